// Builds web/dist from web/src: one script (esbuild bundles three.js from node_modules, minified,
// licences kept at the end), the stylesheet and the page. `npm ci && npm run build` in web/;
// src/api/web.rs compiles web/dist into the choreo binary, so commit web/dist after a build.
// `node build.mjs DIR` builds into DIR instead (tests/web.rs compares that with web/dist).
import { build } from 'esbuild';
import { copyFileSync, mkdirSync } from 'node:fs';
import { join } from 'node:path';

const out = process.argv[2] ?? 'dist';
mkdirSync(out, { recursive: true });
await build({
  entryPoints: ['src/main.js'],
  bundle: true,
  minify: true,
  format: 'iife',
  target: ['chrome110', 'firefox110', 'safari16'],
  legalComments: 'eof',
  outfile: join(out, 'app.js'),
  logLevel: 'info',
});
copyFileSync('src/app.css', join(out, 'app.css'));
copyFileSync('src/index.html', join(out, 'index.html'));
