import type { components } from './schema.js';
export type Problem = components['schemas']['Problem'];
/** The `code` of an ApiError for a request that got no HTTP answer. */
export declare const NETWORK_ERROR = "network-error";
/** An HTTP error answer, or no answer at all (`status` 0, `code` 'network-error'). */
export declare class ApiError extends Error {
    /** The HTTP status; 0 when no answer came. */
    readonly status: number;
    /** The problem's stable kebab-case name, to match on (`not-found`, `network-error`…);
     * undefined for an answer that was not problem+json. */
    readonly code: string | undefined;
    /** What went wrong and what to fix, for people: the problem's `detail`, else its title or the
     * HTTP status. */
    readonly detail: string;
    /** The problem+json body as the server sent it; null when it sent none. */
    readonly problem: Partial<Problem> | null;
    /** The URL that was requested. */
    readonly url: string;
    /** `options` set `code` and `detail` where no problem body carries them (see `network`). */
    constructor(status: number, problem: Partial<Problem> | null, url: string, options?: {
        code?: string;
        detail?: string;
        cause?: unknown;
    });
    /** The error for a response that is not ok, reading its problem+json body when it has one. */
    static from(response: Response): Promise<ApiError>;
    /** The error for a fetch of `url` that rejected with `cause` before any answer came. */
    static network(url: string, cause: unknown): ApiError;
}
