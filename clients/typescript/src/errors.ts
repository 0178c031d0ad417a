// Every error choreo sends is problem+json (RFC 9457); ApiError carries its status, its stable
// `code` (for matching) and its `detail` (for people). A request that gets no answer at all is an
// ApiError too, with status 0 and the code `network-error`: fetch reports a server that is down, a
// wrong address, a failed DNS lookup and a browser's CORS refusal alike, as a bare TypeError that
// names neither the URL nor what to check, and one `catch` should handle both kinds.
import type { components } from './schema.js';

export type Problem = components['schemas']['Problem'];

/** The `code` of an ApiError for a request that got no HTTP answer. */
export const NETWORK_ERROR = 'network-error';

/** An HTTP error answer, or no answer at all (`status` 0, `code` 'network-error'). */
export class ApiError extends Error {
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
  constructor(status: number, problem: Partial<Problem> | null, url: string, options: { code?: string; detail?: string; cause?: unknown } = {}) {
    const detail = options.detail ?? (problem?.detail || problem?.title || `HTTP ${status}`);
    const code = options.code ?? problem?.code;
    super(`${detail}${code ? ` (${code})` : ''}`, 'cause' in options ? { cause: options.cause } : undefined);
    this.name = 'ApiError';
    this.status = status;
    this.code = code;
    this.detail = detail;
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

  /** The error for a fetch of `url` that rejected with `cause` before any answer came. */
  static network(url: string, cause: unknown): ApiError {
    const detail = `no answer from ${url} (${reason(cause)}): the server may be down or the address wrong; `
      + 'in a browser, a cross-origin request the server does not allow (CORS) fails the same way';
    return new ApiError(0, null, url, { code: NETWORK_ERROR, detail, cause });
  }
}

/** Node's fetch says only "fetch failed"; the system's reason (ECONNREFUSED, ENOTFOUND) is in its cause. */
function reason(error: unknown): string {
  const outer = error instanceof Error ? error.message : String(error);
  const inner = error instanceof Error ? (error.cause as { message?: string; code?: string } | undefined) : undefined;
  const detail = inner?.message || inner?.code;
  return detail ? `${outer}: ${detail}` : outer;
}
