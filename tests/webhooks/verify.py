"""Verifies webhook deliveries with the Standard Webhooks reference library (PyPI standardwebhooks),
not with choreo's own code: tests/api/webhooks.rs writes what its receiver got and runs this.

Usage: verify.py SECRET DELIVERIES.json
DELIVERIES.json: [{"headers": {"webhook-id": ..., ...}, "body": "<the raw body>"}, ...]
Prints one JSON line per delivery: the payload the library verified and parsed. A tampered copy
of each delivery must be refused, or this exits non-zero.
"""
import json
import sys

from standardwebhooks.webhooks import Webhook, WebhookVerificationError

secret, path = sys.argv[1], sys.argv[2]
hook = Webhook(secret)
with open(path, encoding="utf-8") as f:
    deliveries = json.load(f)
for delivery in deliveries:
    payload = hook.verify(delivery["body"], delivery["headers"])
    print(json.dumps(payload))
    try:
        hook.verify(delivery["body"] + " ", delivery["headers"])
    except WebhookVerificationError:
        pass
    else:
        sys.exit("a tampered body verified")
