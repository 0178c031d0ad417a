import type { components } from './schema.js';
export type Problem = components['schemas']['Problem'];
/** An HTTP error answer, with the problem+json fields when the server sent them. */
export declare class ApiError extends Error {
    readonly status: number;
    readonly code: string | undefined;
    readonly problem: Partial<Problem> | null;
    readonly url: string;
    constructor(status: number, problem: Partial<Problem> | null, url: string);
    /** The error for a response that is not ok, reading its problem+json body when it has one. */
    static from(response: Response): Promise<ApiError>;
}
