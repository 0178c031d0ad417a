// What a caller catches: an error answer is an ApiError with the problem's status, code and
// detail; a request that gets no answer (the server stopped) is an ApiError too, with status 0,
// the code `network-error` and a message naming the URL; an abort stays an AbortError.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { createServer } from 'node:http';
import { ApiError, Choreo, NETWORK_ERROR } from '../dist/index.js';

const JOB = '0190a0b0-0000-7000-8000-000000000001';

/** A server on a free port that answers with `handler`; resolves with it and its base URL. */
async function serve(handler) {
  const server = createServer(handler);
  await new Promise((resolve) => server.listen(0, '127.0.0.1', resolve));
  return { server, baseUrl: `http://127.0.0.1:${server.address().port}` };
}

/** A base URL where nothing listens: a port that was free a moment ago. */
async function stoppedServer() {
  const { server, baseUrl } = await serve(() => {});
  await new Promise((resolve) => server.close(resolve));
  return baseUrl;
}

const isNetworkError = (url) => (e) => {
  assert.ok(e instanceof ApiError, `an ApiError, not ${e}`);
  assert.equal(e.code, NETWORK_ERROR);
  assert.equal(NETWORK_ERROR, 'network-error');
  assert.equal(e.status, 0);
  assert.equal(e.problem, null);
  assert.equal(e.url, url);
  assert.ok(e.message.includes(url), `the message names the URL: ${e.message}`);
  assert.match(e.message, /ECONNREFUSED/, 'the message keeps the system reason');
  assert.match(e.message, /the server may be down/, 'the message says what to check');
  assert.ok(e.cause instanceof TypeError, 'the cause is the fetch TypeError');
  return true;
};

test('a call to a stopped server is an ApiError network-error that names the URL', async () => {
  const baseUrl = await stoppedServer();
  const choreo = new Choreo({ baseUrl, apiKey: 'k' });
  await assert.rejects(choreo.models(), isNetworkError(`${baseUrl}/v1/models`));
  await assert.rejects(choreo.download(JOB, 'motion.glb'), isNetworkError(`${baseUrl}/v1/jobs/${JOB}/motion.glb`));
});

test('a server that stops during wait() ends it with a network-error', async () => {
  // The job is running; its events stream sends one event, then the server goes away.
  const { server, baseUrl } = await serve((req, res) => {
    if (req.url === `/v1/jobs/${JOB}`) {
      res.writeHead(200, { 'content-type': 'application/json' }).end(JSON.stringify({ id: JOB, status: 'running', progress: 0.1 }));
    } else {
      res.writeHead(200, { 'content-type': 'text/event-stream' });
      res.write(`id: 1\nevent: progress\ndata: ${JSON.stringify({ seq: 1, job_id: JOB, stage: 'generate', progress: 0.5 })}\n\n`);
      server.close();
      setTimeout(() => res.destroy(), 20);
    }
  });
  const choreo = new Choreo({ baseUrl });
  await assert.rejects(choreo.wait(JOB, { retryMs: 10, maxRetries: 2 }), isNetworkError(`${baseUrl}/v1/jobs/${JOB}/events`));
});

test('an error answer exposes status, code and detail, and keeps the problem', async () => {
  const problem = { type: 'about:blank', title: 'Not Found', status: 404, code: 'job-not-found', detail: `no job ${JOB}` };
  const { server, baseUrl } = await serve((req, res) => {
    if (req.url === '/v1/models') res.writeHead(502, { 'content-type': 'text/html' }).end('<h1>Bad Gateway</h1>');
    else res.writeHead(404, { 'content-type': 'application/problem+json' }).end(JSON.stringify(problem));
  });
  try {
    const choreo = new Choreo({ baseUrl });
    await assert.rejects(choreo.job(JOB), (e) => {
      assert.ok(e instanceof ApiError);
      assert.deepEqual([e.status, e.code, e.detail], [404, 'job-not-found', `no job ${JOB}`]);
      assert.deepEqual(e.problem, problem);
      assert.equal(e.message, `no job ${JOB} (job-not-found)`);
      return true;
    });
    // A proxy's HTML error page: no problem, so no code; the detail is the status.
    await assert.rejects(choreo.models(), (e) => e instanceof ApiError && e.status === 502 && e.code === undefined && e.detail === 'HTTP 502' && e.problem === null);
  } finally {
    server.close();
  }
});

test('an aborted event stream is an AbortError, not a network-error', async () => {
  const choreo = new Choreo({ baseUrl: await stoppedServer() });
  const stream = choreo.events(JOB, { signal: AbortSignal.abort() });
  await assert.rejects(stream.next(), (e) => e.name === 'AbortError' && !(e instanceof ApiError));
});
