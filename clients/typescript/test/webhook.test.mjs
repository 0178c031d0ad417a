// The webhook receiver of docs/integrating.md (examples/webhook-receiver.mjs) accepts a delivery signed the
// Standard Webhooks way and refuses a tampered or unsigned one. The signature is made here from
// the scheme itself (HMAC-SHA256 of "id.timestamp.body" with the secret's bytes, base64, "v1,"),
// independently of the standardwebhooks package the receiver uses; tests/api/webhooks.rs checks
// choreo's own deliveries.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { createHmac, randomBytes } from 'node:crypto';
import { receiver } from '../examples/webhook-receiver.mjs';

const key = randomBytes(32);
const SECRET = `whsec_${key.toString('base64')}`;

function sign(id, timestamp, body) {
  return `v1,${createHmac('sha256', key).update(`${id}.${timestamp}.${body}`).digest('base64')}`;
}

test('the receiver verifies a signed delivery and refuses a tampered one', async () => {
  const jobs = [];
  const server = receiver(SECRET, (job, id) => { jobs.push([job, id]); });
  await new Promise((resolve) => server.listen(0, '127.0.0.1', resolve));
  const url = `http://127.0.0.1:${server.address().port}/`;
  try {
    const body = JSON.stringify({ id: '0190a0b0-0000-7000-8000-000000000001', status: 'succeeded', progress: 1 });
    const timestamp = String(Math.floor(Date.now() / 1000));
    const headers = { 'content-type': 'application/json', 'webhook-id': 'msg_1', 'webhook-timestamp': timestamp, 'webhook-signature': sign('msg_1', timestamp, body) };
    assert.equal((await fetch(url, { method: 'POST', headers, body })).status, 204);
    assert.deepEqual(jobs, [[JSON.parse(body), 'msg_1']]);
    const tampered = body.replace('succeeded', 'failed');
    assert.equal((await fetch(url, { method: 'POST', headers, body: tampered })).status, 401);
    const old = String(Math.floor(Date.now() / 1000) - 3600);
    assert.equal((await fetch(url, { method: 'POST', headers: { ...headers, 'webhook-timestamp': old, 'webhook-signature': sign('msg_1', old, body) }, body })).status, 401, 'an hour-old delivery is a replay');
    assert.equal((await fetch(url, { method: 'POST', body })).status, 401, 'unsigned');
    assert.equal(jobs.length, 1);
  } finally {
    server.close();
  }
});
