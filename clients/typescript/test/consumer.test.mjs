// The package as a project that installs it sees it: `npm pack` makes the tarball (so only the
// files package.json ships are there), it is unpacked into a scratch project's node_modules, and
// real tsc compiles that project with moduleResolution nodenext and with bundler, checking the
// client's declarations too (no skipLibCheck). A declaration that does not resolve in either mode
// turns every type of the client into an error or, under skipLibCheck, into `any`; so the project
// also holds a misspelt request field, which must be the one error tsc reports.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { execFileSync, spawnSync } from 'node:child_process';
import { mkdirSync, mkdtempSync, readFileSync, rmSync, symlinkSync, writeFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { fileURLToPath } from 'node:url';

const root = fileURLToPath(new URL('..', import.meta.url));
const tsc = join(root, 'node_modules/typescript/bin/tsc');
const manifest = JSON.parse(readFileSync(join(root, 'package.json'), 'utf8'));

// What a newcomer writes: each line that uses the client is typed from the package.
const GOOD = `import { ApiError, Choreo, type CreateJob, type Job } from '@choreo/client';

const choreo = new Choreo({ baseUrl: 'http://127.0.0.1:8080', apiKey: 'ck_example' });

export async function dance(songId: string): Promise<Job> {
  const request: CreateJob = { song_id: songId, model: 'dance-revolution', seed: 7 };
  const job = await choreo.createJob(request);
  // @ts-expect-error a status is a string union, not a number (unused if the types were \`any\`)
  const wrong: number = job.status;
  void wrong;
  return choreo.wait(job.id, { onUpdate: (j) => console.log(j.status, j.progress) });
}

export function describe(e: unknown): string {
  if (e instanceof ApiError) return \`\${e.status} \${e.code ?? ''} \${e.detail} \${e.problem?.title ?? ''}\`;
  return String(e);
}
`;

// The same call with \`seed\` misspelt: tsc must refuse it.
const TYPO = `import { Choreo } from '@choreo/client';

const choreo = new Choreo({ baseUrl: 'http://127.0.0.1:8080' });
export const job = choreo.createJob({ song_id: 'a-song', model: 'dance-revolution', seeed: 7 });
`;

const MODES = {
  nodenext: { module: 'NodeNext', moduleResolution: 'NodeNext' },
  bundler: { module: 'ESNext', moduleResolution: 'Bundler' },
};

let project;

before(() => {
  project = mkdtempSync(join(tmpdir(), 'choreo-consumer-'));
  const packed = join(project, 'packed');
  mkdirSync(packed);
  const [{ filename }] = JSON.parse(execFileSync('npm', ['pack', '--json', '--pack-destination', packed], { cwd: root, encoding: 'utf8' }));
  const installed = join(project, 'node_modules', ...manifest.name.split('/'));
  mkdirSync(installed, { recursive: true });
  execFileSync('tar', ['-xzf', join(packed, filename), '-C', installed, '--strip-components=1']);
  // The package's dependencies, as npm install would place them (the client's own copies).
  for (const dependency of Object.keys(manifest.dependencies ?? {})) {
    const link = join(project, 'node_modules', ...dependency.split('/'));
    mkdirSync(join(link, '..'), { recursive: true });
    symlinkSync(join(root, 'node_modules', dependency), link, 'dir');
  }
  writeFileSync(join(project, 'package.json'), JSON.stringify({ name: 'consumer', private: true, type: 'module' }));
  writeFileSync(join(project, 'good.ts'), GOOD);
  writeFileSync(join(project, 'typo.ts'), TYPO);
  for (const [mode, resolution] of Object.entries(MODES)) {
    const compilerOptions = { target: 'ES2022', lib: ['ES2022', 'DOM'], strict: true, noEmit: true, skipLibCheck: false, types: [], ...resolution };
    writeFileSync(join(project, `tsconfig.${mode}.json`), JSON.stringify({ compilerOptions, files: ['good.ts', 'typo.ts'] }, null, 2));
  }
});

after(() => rmSync(project, { recursive: true, force: true }));

for (const mode of Object.keys(MODES)) {
  test(`a project with moduleResolution ${mode} type-checks against the packed client`, () => {
    const run = spawnSync(process.execPath, [tsc, '-p', `tsconfig.${mode}.json`, '--pretty', 'false'], { cwd: project, encoding: 'utf8' });
    const output = run.stdout + run.stderr;
    const errors = output.split('\n').filter((line) => / error TS\d+:/.test(line));
    assert.equal(errors.length, 1, `tsc (${mode}) should report only the misspelt field, and reported:\n${output}`);
    assert.match(errors[0], /^typo\.ts\(4,\d+\): error TS(2353|2561): .*'seeed'/, `the misspelt field (${mode}):\n${output}`);
    assert.notEqual(run.status, 0);
  });
}

test('the packed client loads in Node through its exports', () => {
  const script = `import { ApiError, Choreo } from '${manifest.name}'; console.log(typeof Choreo, typeof ApiError);`;
  const out = execFileSync(process.execPath, ['--input-type=module', '-e', script], { cwd: project, encoding: 'utf8' });
  assert.equal(out.trim(), 'function function');
});
