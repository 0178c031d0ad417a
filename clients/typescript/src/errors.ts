// Every error choreo sends is problem+json (RFC 9457); ApiError carries its status, its stable
// `code` (for matching) and its `detail` (for people).
import type { components } from './schema.js';

export type Problem = components['schemas']['Problem'];

/** An HTTP error answer, with the problem+json fields when the server sent them. */
export class ApiError extends Error {
  readonly status: number;
  readonly code: string | undefined;
  readonly problem: Partial<Problem> | null;
  readonly url: string;

  constructor(status: number, problem: Partial<Problem> | null, url: string) {
    const detail = problem?.detail || problem?.title || `HTTP ${status}`;
    super(`${detail}${problem?.code ? ` (${problem.code})` : ''}`);
    this.name = 'ApiError';
    this.status = status;
    this.code = problem?.code;
    this.problem = problem;
    this.url = url;
  }

  /** The error for a response that is not ok, reading its problem+json body when it has one. */
  static async from(response: Response): Promise<ApiError> {
    let problem: Partial<Problem> | null = null;
    try {
      problem = (await response.json()) as Partial<Problem>;
    } catch {
      // Not JSON: the status says enough.
    }
    return new ApiError(response.status, problem, response.url);
  }
}
