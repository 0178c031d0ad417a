// A job's events, pushed by the server: `GET /v1/jobs/{id}/events` (text/event-stream).
//
// Read with fetch streaming, not EventSource, because EventSource cannot send the
// `Authorization: Bearer` header. Each event carries `id: <seq>`; when the connection drops
// before the `done` event, the stream is opened again with `Last-Event-ID: <last seq>` and the
// server replays what was missed, so a reader sees every event once and in order.
import { createParser, type EventSourceMessage } from 'eventsource-parser';
import { ApiError } from './errors.js';
import type { components } from './schema.js';

export type Job = components['schemas']['JobView'];
export type Status = components['schemas']['Status'];

/** `event: status`: the job moved from one status to another. */
export interface StatusEvent {
  seq: number;
  job_id: string;
  from: Status | null;
  to: Status;
  attempt: number;
  error: string | null;
  at: string;
}

/** `event: progress`: the job reached a stage, or moved within one. */
export interface ProgressEvent {
  seq: number;
  job_id: string;
  stage: string;
  /** 0..1 */
  progress: number;
  at: string;
}

/** One event of a job's stream; `done` carries the job as `GET /v1/jobs/{id}` returns it, and is last. */
export type JobEvent =
  | { type: 'status'; id: string | undefined; data: StatusEvent }
  | { type: 'progress'; id: string | undefined; data: ProgressEvent }
  | { type: 'done'; id: string | undefined; data: Job };

export interface EventStreamOptions {
  /** Resume after this event id (the `seq` of the last event seen). */
  lastEventId?: string;
  signal?: AbortSignal;
  /** Wait before reconnecting after a dropped connection, ms (the server's `retry:` overrides it). */
  retryMs?: number;
  /** Consecutive failed reconnections before giving up. */
  maxRetries?: number;
}

export interface EventStreamRequest {
  url: string;
  headers: Record<string, string>;
  fetch: typeof fetch;
}

const sleep = (ms: number, signal?: AbortSignal) =>
  new Promise<void>((resolve, reject) => {
    const timer = setTimeout(resolve, ms);
    signal?.addEventListener('abort', () => {
      clearTimeout(timer);
      reject(signal.reason);
    }, { once: true });
  });

function toEvent(message: EventSourceMessage): JobEvent | null {
  const type = message.event;
  if (type !== 'status' && type !== 'progress' && type !== 'done') return null; // a newer server's kind
  return { type, id: message.id, data: JSON.parse(message.data) } as JobEvent;
}

/**
 * The job's events in order, until `done` (then the iterator ends). Reconnects with
 * `Last-Event-ID` when the stream drops; an HTTP error answer (401, 404) is thrown as ApiError
 * at once, since asking again would get the same answer. After `maxRetries` failures in a row it
 * throws: an ApiError (`network-error`) when the server no longer answers at all.
 */
export async function* jobEvents(request: EventStreamRequest, options: EventStreamOptions = {}): AsyncGenerator<JobEvent> {
  let lastEventId = options.lastEventId;
  let retryMs = options.retryMs ?? 1000;
  const maxRetries = options.maxRetries ?? 10;
  let failures = 0;
  for (;;) {
    const headers: Record<string, string> = { ...request.headers, Accept: 'text/event-stream' };
    if (lastEventId !== undefined) headers['Last-Event-ID'] = lastEventId;
    let response: Response | null = null;
    let unanswered: unknown = null;
    try {
      response = await request.fetch(request.url, { headers, signal: options.signal, cache: 'no-store' });
    } catch (e) {
      if (options.signal?.aborted) throw e;
      unanswered = e; // a network error: try again below
    }
    if (response && !response.ok) throw await ApiError.from(response);
    if (response?.body) {
      const pending: JobEvent[] = [];
      const parser = createParser({
        onEvent: (message) => {
          const event = toEvent(message);
          if (event) pending.push(event);
        },
        onRetry: (ms) => { retryMs = ms; },
      });
      const reader = response.body.pipeThrough(new TextDecoderStream()).getReader();
      try {
        for (;;) {
          const { done, value } = await reader.read();
          if (done) break;
          parser.feed(value);
          for (const event of pending.splice(0)) {
            if (event.id !== undefined) lastEventId = event.id;
            failures = 0;
            yield event;
            if (event.type === 'done') return;
          }
        }
      } catch (e) {
        if (options.signal?.aborted) throw e;
        // The connection dropped mid-stream: resume below from the last event seen.
      } finally {
        // Also when the reader stops early (break, return): the connection is closed, not left open.
        await reader.cancel().catch(() => {});
      }
    }
    failures += 1;
    if (failures > maxRetries) {
      // The server stopped answering (it went down): say so as every other call does.
      if (unanswered !== null) throw unanswered instanceof ApiError ? unanswered : ApiError.network(request.url, unanswered);
      throw new Error(`the event stream of ${request.url} dropped ${failures} times`);
    }
    await sleep(retryMs, options.signal);
  }
}
