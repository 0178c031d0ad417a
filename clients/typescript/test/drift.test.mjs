// The committed client is what the spec and the sources make: src/schema.d.ts is what
// openapi-typescript generates from openapi/openapi.json today, and dist/ is what src/ builds to.
// A change to the API (openapi/openapi.json) without `npm run generate && npm run build` here fails.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { mkdtempSync, readFileSync, readdirSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { fileURLToPath } from 'node:url';
import { generate } from '../scripts/generate.mjs';
import { buildInto } from '../scripts/build.mjs';

const root = fileURLToPath(new URL('..', import.meta.url));

test('src/schema.d.ts is what openapi-typescript generates from openapi/openapi.json', async () => {
  const committed = readFileSync(join(root, 'src/schema.d.ts'), 'utf8');
  const fresh = await generate();
  assert.ok(fresh === committed, 'clients/typescript/src/schema.d.ts drifted from openapi/openapi.json: run `npm run generate && npm run build` in clients/typescript and commit');
});

test('dist/ is what src/ builds to', async () => {
  const out = mkdtempSync(join(tmpdir(), 'choreo-client-'));
  try {
    await buildInto(out);
    const files = readdirSync(out).sort();
    assert.deepEqual(readdirSync(join(root, 'dist')).sort(), files);
    for (const file of files) {
      const same = readFileSync(join(out, file)).equals(readFileSync(join(root, 'dist', file)));
      assert.ok(same, `clients/typescript/dist/${file} differs from what src/ builds to: run \`npm run build\` in clients/typescript and commit`);
    }
  } finally {
    rmSync(out, { recursive: true, force: true });
  }
});
