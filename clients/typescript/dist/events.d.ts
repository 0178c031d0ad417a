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
export type JobEvent = {
    type: 'status';
    id: string | undefined;
    data: StatusEvent;
} | {
    type: 'progress';
    id: string | undefined;
    data: ProgressEvent;
} | {
    type: 'done';
    id: string | undefined;
    data: Job;
};
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
/**
 * The job's events in order, until `done` (then the iterator ends). Reconnects with
 * `Last-Event-ID` when the stream drops; an HTTP error answer (401, 404) is thrown as ApiError
 * at once, since asking again would get the same answer. After `maxRetries` failures in a row it
 * throws: an ApiError (`network-error`) when the server no longer answers at all.
 */
export declare function jobEvents(request: EventStreamRequest, options?: EventStreamOptions): AsyncGenerator<JobEvent>;
