import { type Client } from 'openapi-fetch';
import { type EventStreamOptions, type Job, type JobEvent } from './events.js';
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
export declare const TERMINAL: readonly Job['status'][];
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
export declare class Choreo {
    #private;
    /** openapi-fetch's typed client, for any route: `choreo.api.GET('/v1/jobs/{id}', …)`. */
    readonly api: Client<paths>;
    readonly baseUrl: string;
    /** How the last wait() followed its job: 'events' or 'poll'. */
    lastTransport: 'events' | 'poll' | null;
    constructor(options?: ChoreoOptions);
    /** An absolute URL for a path of this server (links in answers are paths). */
    url(path: string): string;
    /** GET any path of this server with the key (a job's `links`, a song's audio): the Response, or ApiError. */
    fetch(path: string, init?: RequestInit): Promise<Response>;
    models(): Promise<ModelInfo[]>;
    song(id: string): Promise<Song>;
    /** GET /v1/songs: this key's songs, newest first; pass a page's `next_cursor` as `cursor` for the next. */
    listSongs(query?: NonNullable<paths['/v1/songs']['get']['parameters']['query']>): Promise<SongPage>;
    job(id: string): Promise<Job>;
    jobs(query?: NonNullable<paths['/v1/jobs']['get']['parameters']['query']>): Promise<JobPage>;
    /** DELETE /v1/jobs/{id}: cancels a queued or running job. */
    cancel(id: string): Promise<Job>;
    /** POST /v1/songs: uploads a song (a File, or a Blob with `filename`); its analysis starts at once. */
    upload(song: Blob, filename?: string): Promise<Song>;
    /** POST /v1/rigs: a skeleton (BVH or glb) in its rest pose, with an optional joint mapping. */
    uploadRig(file: Blob, mapping?: Record<string, string> | null, filename?: string): Promise<Rig>;
    rig(id: string): Promise<Rig>;
    /** GET /v1/rigs: this key's rigs, newest first; pass a page's `next_cursor` as `cursor` for the next. */
    listRigs(query?: NonNullable<paths['/v1/rigs']['get']['parameters']['query']>): Promise<RigPage>;
    /** DELETE /v1/rigs/{id}: deletes the rig and its file (204); an unknown id is an ApiError (404). */
    deleteRig(id: string): Promise<void>;
    /** POST /v1/jobs with an idempotency key (a new one unless given), so a retried call makes one job. */
    createJob(body: CreateJob, idempotencyKey?: string): Promise<Job>;
    /** The job's server-sent events (see jobEvents), with this client's key. */
    events(jobId: string, options?: EventStreamOptions): AsyncGenerator<JobEvent>;
    /**
     * Resolves with the job once it has ended (succeeded, failed or cancelled: check `status`).
     * Follows its server-sent events; on a server without the events route (it answers 404 for a
     * job that GET /v1/jobs/{id} finds) it polls instead.
     */
    wait(jobId: string, options?: WaitOptions): Promise<Job>;
    /** Polls a song until its analysis is done or failed (analysis is a short job without events). */
    waitForSong(id: string, onUpdate?: (song: Song) => void, pollMs?: number): Promise<Song>;
    /** A finished job's file as a Response (`.blob()`, `.arrayBuffer()`, `.json()`); `rig` retargets
     * motion.bvh/glb/vrma to a built-in or uploaded rig. */
    download(jobId: string, file: JobFile, options?: {
        rig?: string;
    }): Promise<Response>;
    /** The song's audio as uploaded. */
    songAudio(songId: string): Promise<Blob>;
}
