// The public /v1 API, on this origin or another (CORS), with an optional bearer token.
// Every error the API sends is problem+json; ApiError carries its status, code and detail.

/** An HTTP error answer, with the problem+json fields when the server sent them. */
export class ApiError extends Error {
  constructor(status, problem, url) {
    const detail = problem?.detail || problem?.title || `HTTP ${status}`;
    super(`${detail}${problem?.code ? ` (${problem.code})` : ''}`);
    this.status = status;
    this.code = problem?.code;
    this.url = url;
  }
}

export class Api {
  /** base: '' for this origin, or an origin like http://host:8080; token: '' for none. */
  constructor(base = '', token = '') {
    this.base = base.replace(/\/+$/, '');
    this.token = token;
  }

  url(path) {
    return path.startsWith('http') ? path : `${this.base}${path}`;
  }

  headers(extra = {}) {
    return this.token ? { ...extra, Authorization: `Bearer ${this.token}` } : extra;
  }

  async request(path, options = {}) {
    const url = this.url(path);
    const response = await fetch(url, { ...options, headers: this.headers(options.headers) });
    if (!response.ok) {
      let problem = null;
      try { problem = await response.json(); } catch { /* not JSON: the status says enough */ }
      throw new ApiError(response.status, problem, url);
    }
    return response;
  }

  async json(path, options) {
    return (await this.request(path, options)).json();
  }

  async arrayBuffer(path) {
    return (await this.request(path)).arrayBuffer();
  }

  async blob(path) {
    return (await this.request(path)).blob();
  }

  models() { return this.json('/v1/models'); }
  song(id) { return this.json(`/v1/songs/${id}`); }
  job(id) { return this.json(`/v1/jobs/${id}`); }
  jobs(query = 'limit=50') { return this.json(`/v1/jobs?${query}`); }
  cancel(id) { return this.json(`/v1/jobs/${id}`, { method: 'DELETE' }); }

  upload(file) {
    const form = new FormData();
    form.append('file', file, file.name);
    return this.json('/v1/songs', { method: 'POST', body: form });
  }

  /** POST /v1/rigs: a skeleton (BVH or glb) in its rest pose, with an optional mapping object. */
  uploadRig(file, mapping = null) {
    const form = new FormData();
    form.append('file', file, file.name);
    if (mapping) form.append('mapping', JSON.stringify(mapping));
    return this.json('/v1/rigs', { method: 'POST', body: form });
  }

  rig(id) { return this.json(`/v1/rigs/${id}`); }

  /** POST /v1/jobs with an idempotency key, so a retried click makes one job. */
  createJob(body, key = crypto.randomUUID()) {
    return this.json('/v1/jobs', {
      method: 'POST',
      headers: { 'Content-Type': 'application/json', 'Idempotency-Key': key },
      body: JSON.stringify(body),
    });
  }
}

const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));

/** Polls a song until its analysis is done (or failed); calls onUpdate with each view. */
export async function waitForAnalysis(api, id, onUpdate = () => {}) {
  for (;;) {
    const song = await api.song(id);
    onUpdate(song);
    if (song.analysis || ['failed', 'cancelled'].includes(song.analysis_status)) return song;
    await sleep(400);
  }
}

/** Polls a job until it ends; calls onUpdate with each view. */
export async function waitForJob(api, id, onUpdate = () => {}) {
  for (;;) {
    const job = await api.job(id);
    onUpdate(job);
    if (['succeeded', 'failed', 'cancelled'].includes(job.status)) return job;
    await sleep(500);
  }
}
