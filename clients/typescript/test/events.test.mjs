// The SSE layer against a small fake server that speaks the contract of GET /v1/jobs/{id}/events
// (the real server's stream is tested end to end by tests/web.rs): events in order, a dropped
// connection resumed with Last-Event-ID without loss or repeat, the bearer key sent, and wait()
// polling a server that has no events route.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { createServer } from 'node:http';
import { Choreo } from '../dist/index.js';

const JOB = '0190a0b0-0000-7000-8000-000000000001';
const job = (status, progress, stage = null) => ({
  id: JOB, kind: 'generate', status, progress, stage, attempts: 1, max_attempts: 3, cancel_requested: false, priority: 0,
  created_at: '2026-11-26T00:00:00Z', song_id: JOB, links: { self: `/v1/jobs/${JOB}`, song: `/v1/songs/${JOB}` },
});
/** The job's whole history, as the server would replay it. */
const HISTORY = [
  ['status', { from: null, to: 'queued', attempt: 0, error: null }],
  ['status', { from: 'queued', to: 'running', attempt: 1, error: null }],
  ['progress', { stage: 'decode-audio', progress: 0.1 }],
  ['progress', { stage: 'generate', progress: 0.5 }],
  ['progress', { stage: 'export', progress: 0.9 }],
  ['status', { from: 'running', to: 'succeeded', attempt: 1, error: null }],
].map(([event, data], i) => ({ seq: i + 1, event, data: { seq: i + 1, job_id: JOB, at: '2026-11-26T00:00:00Z', ...data } }));

/** A fake choreo: `events` false answers the events route with 404, as a server without it would. */
async function fakeServer({ events = true, dropAfter = 3, snapshot = job('queued', 0) } = {}) {
  const seen = { eventRequests: [], authorization: new Set(), jobGets: 0 };
  const server = createServer((req, res) => {
    seen.authorization.add(req.headers.authorization);
    if (req.url === `/v1/jobs/${JOB}`) {
      seen.jobGets += 1;
      const view = seen.jobGets < 3 ? job('running', 0.5, 'generate') : job('succeeded', 1, 'done');
      res.writeHead(200, { 'content-type': 'application/json' }).end(JSON.stringify(seen.jobGets === 1 ? snapshot : view));
    } else if (req.url === `/v1/jobs/${JOB}/events` && events) {
      const after = Number(req.headers['last-event-id'] ?? 0);
      seen.eventRequests.push(req.headers['last-event-id'] ?? null);
      res.writeHead(200, { 'content-type': 'text/event-stream', 'cache-control': 'no-cache' });
      res.write('retry: 20\n: keep-alive\n\n');
      const rest = HISTORY.filter((e) => e.seq > after);
      // The first connection drops after `dropAfter` events, mid-way through the next one.
      const first = seen.eventRequests.length === 1;
      const sent = first ? rest.slice(0, dropAfter) : rest;
      for (const e of sent) res.write(`id: ${e.seq}\nevent: ${e.event}\ndata: ${JSON.stringify(e.data)}\n\n`);
      if (first) {
        // Then half an event, never completed (it must not be seen), and the connection drops.
        setTimeout(() => res.write('id: 99\nevent: progress\ndata: {"trunc'), 50);
        setTimeout(() => res.socket.destroy(), 100);
        return;
      }
      res.end(`id: ${HISTORY.length + 1}\nevent: done\ndata: ${JSON.stringify(job('succeeded', 1, 'done'))}\n\n`);
    } else {
      res.writeHead(404, { 'content-type': 'application/problem+json' })
        .end(JSON.stringify({ status: 404, code: 'not-found', title: 'Not Found', detail: 'no such route' }));
    }
  });
  await new Promise((resolve) => server.listen(0, '127.0.0.1', resolve));
  return { server, seen, baseUrl: `http://127.0.0.1:${server.address().port}` };
}

test('wait() follows the events in order and resumes a dropped stream with Last-Event-ID', async () => {
  const { server, seen, baseUrl } = await fakeServer();
  try {
    const choreo = new Choreo({ baseUrl, apiKey: 'secret-key' });
    const events = [];
    const updates = [];
    const done = await choreo.wait(JOB, { onEvent: (e) => events.push(e), onUpdate: (j) => updates.push(`${j.status}:${j.progress}`) });
    assert.equal(done.status, 'succeeded');
    assert.equal(choreo.lastTransport, 'events');
    assert.deepEqual(events.map((e) => Number(e.id)), [1, 2, 3, 4, 5, 6, 7], 'every event once, in order');
    assert.deepEqual(events.map((e) => e.type), ['status', 'status', 'progress', 'progress', 'progress', 'status', 'done']);
    assert.deepEqual(seen.eventRequests, [null, '3'], 'reconnected once, after the last whole event');
    assert.deepEqual([...seen.authorization], ['Bearer secret-key']);
    assert.deepEqual(updates, ['queued:0', 'running:0', 'running:0.1', 'running:0.5', 'running:0.9', 'succeeded:0.9', 'succeeded:1']);
  } finally {
    server.close();
  }
});

test('wait() on a job already under way: the replayed events never set its progress back', async () => {
  // GET /v1/jobs/{id} answers a job at 0.5; the stream then replays its events from the first.
  const { server, baseUrl } = await fakeServer({ snapshot: job('running', 0.5, 'generate'), dropAfter: 99 });
  try {
    const updates = [];
    const done = await new Choreo({ baseUrl }).wait(JOB, { onUpdate: (j) => updates.push([j.status, j.progress]) });
    assert.equal(done.status, 'succeeded');
    const progress = updates.filter(([s]) => s === 'running').map(([, p]) => p);
    assert.deepEqual(progress, [0, 0.1, 0.5, 0.9], `updates: ${JSON.stringify(updates)}`);
    assert.deepEqual(updates[0], ['queued', 0], 'the first view is the first event, not the newer snapshot');
  } finally {
    server.close();
  }
});

test('wait() polls GET /v1/jobs/{id} on a server without the events route', async () => {
  const { server, seen, baseUrl } = await fakeServer({ events: false });
  try {
    const choreo = new Choreo({ baseUrl });
    const done = await choreo.wait(JOB, { pollMs: 10 });
    assert.equal(done.status, 'succeeded');
    assert.equal(choreo.lastTransport, 'poll');
    assert.ok(seen.jobGets >= 3, `polled ${seen.jobGets} times`);
    assert.deepEqual([...seen.authorization], [undefined], 'no key, no header');
  } finally {
    server.close();
  }
});

test('an unknown job is an ApiError with its status and code', async () => {
  const { server, baseUrl } = await fakeServer();
  try {
    const choreo = new Choreo({ baseUrl });
    await assert.rejects(choreo.wait('0190a0b0-0000-7000-8000-0000000000ff'), (e) => e.name === 'ApiError' && e.status === 404 && e.code === 'not-found');
  } finally {
    server.close();
  }
});
