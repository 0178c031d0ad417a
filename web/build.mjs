// Builds web/dist from web/src: one script (esbuild bundles three.js from node_modules, minified,
// licences kept at the end), the stylesheet and the page. `npm ci && npm run build` in web/;
// src/api/web.rs compiles web/dist into the choreo binary, so commit web/dist after a build.
import { build } from 'esbuild';
import { copyFileSync, mkdirSync } from 'node:fs';

mkdirSync('dist', { recursive: true });
await build({
  entryPoints: ['src/main.js'],
  bundle: true,
  minify: true,
  format: 'iife',
  target: ['chrome110', 'firefox110', 'safari16'],
  legalComments: 'eof',
  outfile: 'dist/app.js',
  logLevel: 'info',
});
copyFileSync('src/app.css', 'dist/app.css');
copyFileSync('src/index.html', 'dist/index.html');
