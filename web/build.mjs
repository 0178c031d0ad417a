// Builds web/dist from web/src: the page's script (esbuild bundles three.js from node_modules and
// the TypeScript client from ../clients/typescript/src, minified, licences kept at the end), the
// stylesheet and the page; and choreo-player.js, the <choreo-player> element for any page (the same
// three.js and player, one classic script). `npm ci && npm run build` in web/;
// src/api/web.rs compiles web/dist into the choreo binary, so commit web/dist after a build.
// `node build.mjs DIR` builds into DIR instead (tests/web.rs compares that with web/dist).
import { build } from 'esbuild';
import { copyFileSync, mkdirSync } from 'node:fs';
import { join } from 'node:path';

const out = process.argv[2] ?? 'dist';
mkdirSync(out, { recursive: true });
const bundle = (entry, file) => build({
  entryPoints: [entry],
  bundle: true,
  minify: true,
  format: 'iife',
  target: ['chrome110', 'firefox110', 'safari16'],
  legalComments: 'eof',
  outfile: join(out, file),
  logLevel: 'info',
});
await bundle('src/main.js', 'app.js');
await bundle('src/element.js', 'choreo-player.js');
copyFileSync('src/app.css', join(out, 'app.css'));
copyFileSync('src/index.html', join(out, 'index.html'));
