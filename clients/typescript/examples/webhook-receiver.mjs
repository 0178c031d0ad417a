// A webhook receiver for choreo's job deliveries (README: "Integrating choreo in five minutes").
// choreo POSTs the finished job, as GET /v1/jobs/{id} returns it, signed the Standard Webhooks
// way (headers webhook-id, webhook-timestamp, webhook-signature: HMAC-SHA256 over
// "id.timestamp.body" with the server's `webhook_secret`); the `standardwebhooks` package checks
// the signature and the timestamp's age before the body is trusted.
//
//   npm install standardwebhooks
//   CHOREO_WEBHOOK_SECRET=whsec_… node webhook-receiver.mjs      # listens on :9000
import { createServer } from 'node:http';
import { Webhook } from 'standardwebhooks';

/** An HTTP server that verifies each delivery and hands the job to `onJob`. */
export function receiver(secret, onJob) {
  const webhook = new Webhook(secret); // takes the whsec_… form as it is
  return createServer(async (req, res) => {
    const chunks = [];
    for await (const chunk of req) chunks.push(chunk);
    const body = Buffer.concat(chunks).toString('utf8'); // verify the bytes as sent, not a re-encoding
    let job;
    try {
      job = webhook.verify(body, req.headers);
    } catch {
      res.writeHead(401).end(); // a wrong or stale signature: not from choreo
      return;
    }
    // webhook-id is the same on every retry of one delivery: skip ids already handled.
    await onJob(job, req.headers['webhook-id']);
    res.writeHead(204).end(); // any 2xx ends choreo's retries
  });
}

if (process.argv[1] === new URL(import.meta.url).pathname) {
  receiver(process.env.CHOREO_WEBHOOK_SECRET, (job) => {
    console.log(`job ${job.id} ${job.status}`, job.links?.motion_glb ?? job.error ?? '');
  }).listen(Number(process.env.PORT ?? 9000));
}
