// choreo's TypeScript client: the request and answer types are generated from
// openapi/openapi.json (src/schema.d.ts, by openapi-typescript) and every call goes through
// openapi-fetch's typed client; this file adds what a generator cannot know: the bearer key, a
// multipart upload, waiting for a job (its server-sent events, or polling on a server without
// them) and downloads of its files.
//
//   const choreo = new Choreo({ baseUrl: 'http://127.0.0.1:8080', apiKey: 'ck_…' });
//   const song = await choreo.upload(file);
//   const job = await choreo.createJob({ song_id: song.id, model: 'dance-revolution' });
//   const done = await choreo.wait(job.id, { onUpdate: (j) => console.log(j.status, j.progress) });
//   const glb = await choreo.download(done.id, 'motion.glb');
import createClient, { type Client } from 'openapi-fetch';
import { ApiError } from './errors.js';
import { jobEvents, type EventStreamOptions, type Job, type JobEvent } from './events.js';
import type { components, paths } from './schema.js';

export { ApiError, NETWORK_ERROR, type Problem } from './errors.js';
export { jobEvents, type EventStreamOptions, type Job, type JobEvent, type ProgressEvent, type Status, type StatusEvent } from './events.js';
export type { components, paths } from './schema.js';

type Schemas = components['schemas'];
export type Song = Schemas['SongView'];
export type SongPage = Schemas['SongPage'];
export type CreateJob = Schemas['CreateJob'];
export type JobPage = Schemas['JobPage'];
export type ModelInfo = Schemas['ModelInfo'];
export type Rig = Schemas['RigView'];
export type RigPage = Schemas['RigPage'];

/** The files a finished generate job serves under `/v1/jobs/{id}/`. */
export type JobFile = 'motion.json' | 'motion.glb' | 'motion.bvh' | 'motion.vrma' | 'motion.smpl.npz' | 'report.json' | 'preview.png';

/** Statuses after which a job never changes again. */
export const TERMINAL: readonly Job['status'][] = ['succeeded', 'failed', 'cancelled'];

export interface ChoreoOptions {
  /** The server's origin, e.g. `http://127.0.0.1:8080`; '' for the page's own origin. */
  baseUrl?: string;
  /** An API key's secret (or the server's `auth_token`), sent as `Authorization: Bearer <key>`. */
  apiKey?: string;
  /** A fetch to use instead of the global one. */
  fetch?: typeof fetch;
}

export interface WaitOptions extends EventStreamOptions {
  /** Each event as it arrives (server-sent events only). */
  onEvent?: (event: JobEvent) => void;
  /** The job as it is now, after each change: its status, stage and progress. */
  onUpdate?: (job: Job) => void;
  /** 'events' (server-sent events), 'poll' (GET the job every `pollMs`), or 'auto' (default):
   * events, or polling on a server that has no events route. */
  transport?: 'auto' | 'events' | 'poll';
  pollMs?: number;
}

const sleep = (ms: number) => new Promise((resolve) => setTimeout(resolve, ms));

/** A random UUID v4. crypto.randomUUID exists only in secure contexts (https, localhost), and a
 * page on http://host:8080 is not one; getRandomValues works everywhere. */
function randomUuid(): string {
  const b = crypto.getRandomValues(new Uint8Array(16));
  b[6] = (b[6] & 0x0f) | 0x40;
  b[8] = (b[8] & 0x3f) | 0x80;
  const h = Array.from(b, (x) => x.toString(16).padStart(2, '0')).join('');
  return `${h.slice(0, 8)}-${h.slice(8, 12)}-${h.slice(12, 16)}-${h.slice(16, 20)}-${h.slice(20)}`;
}

/** `fetch`, but a request that gets no answer rejects with an ApiError (`network-error`) naming
 * its URL. The fetch standard rejects such a request with a TypeError and nothing else does, so
 * an abort (an AbortError) and a custom fetch's own errors pass through unchanged. */
function answering(fetch: typeof globalThis.fetch): typeof globalThis.fetch {
  return async (input, init) => {
    try {
      return await fetch(input, init);
    } catch (e) {
      if (!(e instanceof TypeError)) throw e;
      throw ApiError.network(typeof input === 'string' ? input : input instanceof URL ? input.href : input.url, e);
    }
  };
}

export class Choreo {
  /** openapi-fetch's typed client, for any route: `choreo.api.GET('/v1/jobs/{id}', …)`. */
  readonly api: Client<paths>;
  readonly baseUrl: string;
  readonly #headers: Record<string, string>;
  readonly #fetch: typeof fetch;
  /** How the last wait() followed its job: 'events' or 'poll'. */
  lastTransport: 'events' | 'poll' | null = null;

  constructor(options: ChoreoOptions = {}) {
    this.baseUrl = (options.baseUrl ?? '').replace(/\/+$/, '');
    this.#headers = options.apiKey ? { Authorization: `Bearer ${options.apiKey}` } : {};
    // Looked up at each call, so a fetch replaced later (tests, polyfills) is the one used.
    this.#fetch = answering(options.fetch ?? ((input, init) => globalThis.fetch(input, init)));
    this.api = createClient<paths>({ baseUrl: this.baseUrl, headers: this.#headers, fetch: (request) => this.#fetch(request) });
  }

  /** An absolute URL for a path of this server (links in answers are paths). */
  url(path: string): string {
    return /^https?:/.test(path) ? path : `${this.baseUrl}${path}`;
  }

  /** GET any path of this server with the key (a job's `links`, a song's audio): the Response, or ApiError. */
  async fetch(path: string, init: RequestInit = {}): Promise<Response> {
    const headers = { ...this.#headers, ...(init.headers as Record<string, string> | undefined) };
    const response = await this.#fetch(this.url(path), { ...init, headers });
    if (!response.ok) throw await ApiError.from(response);
    return response;
  }

  models(): Promise<ModelInfo[]> {
    return data(this.api.GET('/v1/models'));
  }

  song(id: string): Promise<Song> {
    return data(this.api.GET('/v1/songs/{id}', { params: { path: { id } } }));
  }

  /** GET /v1/songs: this key's songs, newest first; pass a page's `next_cursor` as `cursor` for the next. */
  listSongs(query: NonNullable<paths['/v1/songs']['get']['parameters']['query']> = { limit: 50 }): Promise<SongPage> {
    return data(this.api.GET('/v1/songs', { params: { query } }));
  }

  job(id: string): Promise<Job> {
    return data(this.api.GET('/v1/jobs/{id}', { params: { path: { id } } }));
  }

  jobs(query: NonNullable<paths['/v1/jobs']['get']['parameters']['query']> = { limit: 50 }): Promise<JobPage> {
    return data(this.api.GET('/v1/jobs', { params: { query } }));
  }

  /** DELETE /v1/jobs/{id}: cancels a queued or running job. */
  cancel(id: string): Promise<Job> {
    return data(this.api.DELETE('/v1/jobs/{id}', { params: { path: { id } } }));
  }

  /** POST /v1/songs: uploads a song (a File, or a Blob with `filename`); its analysis starts at once. */
  upload(song: Blob, filename = (song as File).name || 'song'): Promise<Song> {
    const form = new FormData();
    form.append('file', song, filename);
    return data(this.api.POST('/v1/songs', { body: {} as Schemas['UploadForm'], bodySerializer: () => form }));
  }

  /** POST /v1/rigs: a skeleton (BVH or glb) in its rest pose, with an optional joint mapping. */
  uploadRig(file: Blob, mapping: Record<string, string> | null = null, filename = (file as File).name || 'rig'): Promise<Rig> {
    const form = new FormData();
    form.append('file', file, filename);
    if (mapping) form.append('mapping', JSON.stringify(mapping));
    return data(this.api.POST('/v1/rigs', { body: {} as never, bodySerializer: () => form }));
  }

  rig(id: string): Promise<Rig> {
    return data(this.api.GET('/v1/rigs/{id}', { params: { path: { id } } }));
  }

  /** GET /v1/rigs: this key's rigs, newest first; pass a page's `next_cursor` as `cursor` for the next. */
  listRigs(query: NonNullable<paths['/v1/rigs']['get']['parameters']['query']> = { limit: 50 }): Promise<RigPage> {
    return data(this.api.GET('/v1/rigs', { params: { query } }));
  }

  /** DELETE /v1/rigs/{id}: deletes the rig and its file (204); an unknown id is an ApiError (404). */
  async deleteRig(id: string): Promise<void> {
    const { error, response } = await this.api.DELETE('/v1/rigs/{id}', { params: { path: { id } } });
    if (!response.ok) throw new ApiError(response.status, asProblem(error), response.url);
  }

  /** POST /v1/jobs with an idempotency key (a new one unless given), so a retried call makes one job. */
  createJob(body: CreateJob, idempotencyKey: string = randomUuid()): Promise<Job> {
    return data(this.api.POST('/v1/jobs', { body, params: { header: { 'Idempotency-Key': idempotencyKey } } }));
  }

  /** The job's server-sent events (see jobEvents), with this client's key. */
  events(jobId: string, options: EventStreamOptions = {}): AsyncGenerator<JobEvent> {
    const url = this.url(`/v1/jobs/${encodeURIComponent(jobId)}/events`);
    return jobEvents({ url, headers: this.#headers, fetch: this.#fetch }, options);
  }

  /**
   * Resolves with the job once it has ended (succeeded, failed or cancelled: check `status`).
   * Follows its server-sent events; on a server without the events route (it answers 404 for a
   * job that GET /v1/jobs/{id} finds) it polls instead.
   */
  async wait(jobId: string, options: WaitOptions = {}): Promise<Job> {
    let job = await this.job(jobId);
    if (TERMINAL.includes(job.status)) {
      options.onUpdate?.(job);
      return job;
    }
    if (options.transport !== 'poll') {
      try {
        this.lastTransport = 'events';
        // Without a Last-Event-ID the server replays the job's events from its first, so the view
        // is built from them alone. Laid over the snapshot above, a replayed event older than the
        // snapshot would set its status or progress back (0.1, then 0 again, then 0.1).
        const resuming = options.lastEventId !== undefined;
        let view = resuming ? job : unstarted(job);
        if (resuming) options.onUpdate?.(view);
        for await (const event of this.events(jobId, options)) {
          options.onEvent?.(event);
          view = apply(view, event);
          options.onUpdate?.(view);
          if (event.type === 'done') return view;
        }
        throw new Error(`the events of job ${jobId} ended without a done event`);
      } catch (e) {
        const noRoute = e instanceof ApiError && (e.status === 404 || e.status === 405) && options.transport !== 'events';
        if (!noRoute) throw e;
        job = await this.job(jobId); // still there (a 404 here is the job's own, and is thrown)
      }
    }
    this.lastTransport = 'poll';
    options.onUpdate?.(job);
    while (!TERMINAL.includes(job.status)) {
      await sleep(options.pollMs ?? 500);
      options.signal?.throwIfAborted();
      job = await this.job(jobId);
      options.onUpdate?.(job);
    }
    return job;
  }

  /** Polls a song until its analysis is done or failed (analysis is a short job without events). */
  async waitForSong(id: string, onUpdate: (song: Song) => void = () => {}, pollMs = 400): Promise<Song> {
    for (;;) {
      const song = await this.song(id);
      onUpdate(song);
      if (song.analysis || (song.analysis_status && TERMINAL.includes(song.analysis_status) && song.analysis_status !== 'succeeded')) return song;
      await sleep(pollMs);
    }
  }

  /** A finished job's file as a Response (`.blob()`, `.arrayBuffer()`, `.json()`); `rig` retargets
   * motion.bvh/glb/vrma to a built-in or uploaded rig. */
  download(jobId: string, file: JobFile, options: { rig?: string } = {}): Promise<Response> {
    const query = options.rig ? `?rig=${encodeURIComponent(options.rig)}` : '';
    return this.fetch(`/v1/jobs/${encodeURIComponent(jobId)}/${file}${query}`);
  }

  /** The song's audio as uploaded. */
  songAudio(songId: string): Promise<Blob> {
    return this.fetch(`/v1/songs/${encodeURIComponent(songId)}/audio`).then((r) => r.blob());
  }
}

/** The job as it was registered, before its first event: what a replay from the start is laid over. */
function unstarted(job: Job): Job {
  return { ...job, status: 'queued', stage: null, progress: 0, attempts: 0, error: null, started_at: null, finished_at: null };
}

/** The job view after an event: status events move its status, progress events its stage. */
function apply(job: Job, event: JobEvent): Job {
  switch (event.type) {
    case 'status':
      return { ...job, status: event.data.to, attempts: event.data.attempt ?? job.attempts, error: event.data.error ?? job.error };
    case 'progress':
      return { ...job, stage: event.data.stage as Job['stage'], progress: event.data.progress };
    case 'done':
      return event.data;
  }
}

/** openapi-fetch's `error`: the parsed problem+json, or the body's text when it was not JSON
 * (a proxy's HTML error page), which is no problem. */
function asProblem(error: unknown): ApiError['problem'] {
  return typeof error === 'object' && error !== null ? (error as ApiError['problem']) : null;
}

/** The answer's body, or its problem as ApiError. */
async function data<T>(call: Promise<{ data?: T; error?: unknown; response: Response }>): Promise<T> {
  const { data, error, response } = await call;
  if (!response.ok || data === undefined) {
    throw new ApiError(response.status, asProblem(error), response.url);
  }
  return data;
}
