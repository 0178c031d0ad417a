// Builds dist/ from src/: dist/index.js, one ES module with openapi-fetch and eventsource-parser
// bundled in (so it loads as it is in a browser or in Node), and the type declarations (tsc).
// `npm run build` writes dist/, which is committed; `node scripts/build.mjs DIR` writes DIR
// instead (test/drift.test.mjs compares that with dist/).
import { build } from 'esbuild';
import { execFileSync } from 'node:child_process';
import { copyFileSync, mkdirSync } from 'node:fs';
import { join, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';

const root = fileURLToPath(new URL('..', import.meta.url));

/** Builds the package into `out`. */
export async function buildInto(out) {
  out = resolve(out);
  mkdirSync(out, { recursive: true });
  await build({
    absWorkingDir: root,
    entryPoints: ['src/index.ts'],
    bundle: true,
    format: 'esm',
    platform: 'neutral',
    target: ['es2022'],
    legalComments: 'eof',
    outfile: join(out, 'index.js'),
    logLevel: 'warning',
  });
  execFileSync(process.execPath, [join(root, 'node_modules/typescript/bin/tsc'), '-p', root, '--outDir', out], { stdio: 'inherit' });
  // tsc does not copy declaration files it reads; the generated types are one.
  copyFileSync(join(root, 'src/schema.d.ts'), join(out, 'schema.d.ts'));
}

if (process.argv[1] === fileURLToPath(import.meta.url)) {
  await buildInto(process.argv[2] ?? 'dist');
}
