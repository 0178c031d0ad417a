// node_modules/openapi-fetch/dist/index.mjs
var PATH_PARAM_RE = /\{[^{}]+\}/g;
var supportsRequestInitExt = () => {
  return typeof process === "object" && Number.parseInt(process?.versions?.node?.substring(0, 2)) >= 18 && process.versions.undici;
};
function randomID() {
  return Math.random().toString(36).slice(2, 11);
}
function createClient(clientOptions) {
  let {
    baseUrl = "",
    Request: CustomRequest = globalThis.Request,
    fetch: baseFetch = globalThis.fetch,
    querySerializer: globalQuerySerializer,
    bodySerializer: globalBodySerializer,
    pathSerializer: globalPathSerializer,
    headers: baseHeaders,
    requestInitExt = void 0,
    ...baseOptions
  } = { ...clientOptions };
  requestInitExt = supportsRequestInitExt() ? requestInitExt : void 0;
  baseUrl = removeTrailingSlash(baseUrl);
  const globalMiddlewares = [];
  async function coreFetch(schemaPath, fetchOptions) {
    const {
      baseUrl: localBaseUrl,
      fetch = baseFetch,
      Request = CustomRequest,
      headers,
      params = {},
      parseAs = "json",
      querySerializer: requestQuerySerializer,
      bodySerializer = globalBodySerializer ?? defaultBodySerializer,
      pathSerializer: requestPathSerializer,
      body,
      middleware: requestMiddlewares = [],
      ...init
    } = fetchOptions || {};
    let finalBaseUrl = baseUrl;
    if (localBaseUrl) {
      finalBaseUrl = removeTrailingSlash(localBaseUrl) ?? baseUrl;
    }
    let querySerializer = typeof globalQuerySerializer === "function" ? globalQuerySerializer : createQuerySerializer(globalQuerySerializer);
    if (requestQuerySerializer) {
      querySerializer = typeof requestQuerySerializer === "function" ? requestQuerySerializer : createQuerySerializer({
        ...typeof globalQuerySerializer === "object" ? globalQuerySerializer : {},
        ...requestQuerySerializer
      });
    }
    const pathSerializer = requestPathSerializer || globalPathSerializer || defaultPathSerializer;
    const serializedBody = body === void 0 ? void 0 : bodySerializer(
      body,
      // Note: we declare mergeHeaders() both here and below because it’s a bit of a chicken-or-egg situation:
      // bodySerializer() needs all headers so we aren’t dropping ones set by the user, however,
      // the result of this ALSO sets the lowest-priority content-type header. So we re-merge below,
      // setting the content-type at the very beginning to be overwritten.
      // Lastly, based on the way headers work, it’s not a simple “present-or-not” check becauase null intentionally un-sets headers.
      mergeHeaders(baseHeaders, headers, params.header)
    );
    const finalHeaders = mergeHeaders(
      // with no body, we should not to set Content-Type
      serializedBody === void 0 || // if serialized body is FormData; browser will correctly set Content-Type & boundary expression
      serializedBody instanceof FormData ? {} : {
        "Content-Type": "application/json"
      },
      baseHeaders,
      headers,
      params.header
    );
    const finalMiddlewares = [...globalMiddlewares, ...requestMiddlewares];
    const requestInit = {
      redirect: "follow",
      ...baseOptions,
      ...init,
      body: serializedBody,
      headers: finalHeaders
    };
    let id;
    let options;
    let request = new Request(
      createFinalURL(schemaPath, { baseUrl: finalBaseUrl, params, querySerializer, pathSerializer }),
      requestInit
    );
    let response;
    for (const key in init) {
      if (!(key in request)) {
        request[key] = init[key];
      }
    }
    if (finalMiddlewares.length) {
      id = randomID();
      options = Object.freeze({
        baseUrl: finalBaseUrl,
        fetch,
        parseAs,
        querySerializer,
        bodySerializer,
        pathSerializer
      });
      for (const m of finalMiddlewares) {
        if (m && typeof m === "object" && typeof m.onRequest === "function") {
          const result = await m.onRequest({
            request,
            schemaPath,
            params,
            options,
            id
          });
          if (result) {
            if (result instanceof Request) {
              request = result;
            } else if (result instanceof Response) {
              response = result;
              break;
            } else {
              throw new Error("onRequest: must return new Request() or Response() when modifying the request");
            }
          }
        }
      }
    }
    if (!response) {
      try {
        response = await fetch(request, requestInitExt);
      } catch (error2) {
        let errorAfterMiddleware = error2;
        if (finalMiddlewares.length) {
          for (let i = finalMiddlewares.length - 1; i >= 0; i--) {
            const m = finalMiddlewares[i];
            if (m && typeof m === "object" && typeof m.onError === "function") {
              const result = await m.onError({
                request,
                error: errorAfterMiddleware,
                schemaPath,
                params,
                options,
                id
              });
              if (result) {
                if (result instanceof Response) {
                  errorAfterMiddleware = void 0;
                  response = result;
                  break;
                }
                if (result instanceof Error) {
                  errorAfterMiddleware = result;
                  continue;
                }
                throw new Error("onError: must return new Response() or instance of Error");
              }
            }
          }
        }
        if (errorAfterMiddleware) {
          throw errorAfterMiddleware;
        }
      }
      if (finalMiddlewares.length) {
        for (let i = finalMiddlewares.length - 1; i >= 0; i--) {
          const m = finalMiddlewares[i];
          if (m && typeof m === "object" && typeof m.onResponse === "function") {
            const result = await m.onResponse({
              request,
              response,
              schemaPath,
              params,
              options,
              id
            });
            if (result) {
              if (!(result instanceof Response)) {
                throw new Error("onResponse: must return new Response() when modifying the response");
              }
              response = result;
            }
          }
        }
      }
    }
    const contentLength = response.headers.get("Content-Length");
    if (response.status === 204 || request.method === "HEAD" || contentLength === "0" && !response.headers.get("Transfer-Encoding")?.includes("chunked")) {
      return response.ok ? { data: void 0, response } : { error: void 0, response };
    }
    if (response.ok) {
      const getResponseData = async () => {
        if (parseAs === "stream") {
          return response.body;
        }
        if (parseAs === "json" && !contentLength) {
          const raw = await response.text();
          return raw ? JSON.parse(raw) : void 0;
        }
        return await response[parseAs]();
      };
      return { data: await getResponseData(), response };
    }
    let error = await response.text();
    try {
      error = JSON.parse(error);
    } catch {
    }
    return { error, response };
  }
  return {
    request(method, url, init) {
      return coreFetch(url, { ...init, method: method.toUpperCase() });
    },
    /** Call a GET endpoint */
    GET(url, init) {
      return coreFetch(url, { ...init, method: "GET" });
    },
    /** Call a PUT endpoint */
    PUT(url, init) {
      return coreFetch(url, { ...init, method: "PUT" });
    },
    /** Call a POST endpoint */
    POST(url, init) {
      return coreFetch(url, { ...init, method: "POST" });
    },
    /** Call a DELETE endpoint */
    DELETE(url, init) {
      return coreFetch(url, { ...init, method: "DELETE" });
    },
    /** Call a OPTIONS endpoint */
    OPTIONS(url, init) {
      return coreFetch(url, { ...init, method: "OPTIONS" });
    },
    /** Call a HEAD endpoint */
    HEAD(url, init) {
      return coreFetch(url, { ...init, method: "HEAD" });
    },
    /** Call a PATCH endpoint */
    PATCH(url, init) {
      return coreFetch(url, { ...init, method: "PATCH" });
    },
    /** Call a TRACE endpoint */
    TRACE(url, init) {
      return coreFetch(url, { ...init, method: "TRACE" });
    },
    /** Register middleware */
    use(...middleware) {
      for (const m of middleware) {
        if (!m) {
          continue;
        }
        if (typeof m !== "object" || !("onRequest" in m || "onResponse" in m || "onError" in m)) {
          throw new Error("Middleware must be an object with one of `onRequest()`, `onResponse() or `onError()`");
        }
        globalMiddlewares.push(m);
      }
    },
    /** Unregister middleware */
    eject(...middleware) {
      for (const m of middleware) {
        const i = globalMiddlewares.indexOf(m);
        if (i !== -1) {
          globalMiddlewares.splice(i, 1);
        }
      }
    }
  };
}
function serializePrimitiveParam(name, value, options) {
  if (value === void 0 || value === null) {
    return "";
  }
  if (typeof value === "object") {
    throw new Error(
      "Deeply-nested arrays/objects aren\u2019t supported. Provide your own `querySerializer()` to handle these."
    );
  }
  return `${name}=${options?.allowReserved === true ? value : encodeURIComponent(value)}`;
}
function serializeObjectParam(name, value, options) {
  if (!value || typeof value !== "object") {
    return "";
  }
  const values = [];
  const joiner = {
    simple: ",",
    label: ".",
    matrix: ";"
  }[options.style] || "&";
  if (options.style !== "deepObject" && options.explode === false) {
    for (const k in value) {
      values.push(k, options.allowReserved === true ? value[k] : encodeURIComponent(value[k]));
    }
    const final2 = values.join(",");
    switch (options.style) {
      case "form": {
        return `${name}=${final2}`;
      }
      case "label": {
        return `.${final2}`;
      }
      case "matrix": {
        return `;${name}=${final2}`;
      }
      default: {
        return final2;
      }
    }
  }
  for (const k in value) {
    const finalName = options.style === "deepObject" ? `${name}[${k}]` : k;
    values.push(serializePrimitiveParam(finalName, value[k], options));
  }
  const final = values.join(joiner);
  return options.style === "label" || options.style === "matrix" ? `${joiner}${final}` : final;
}
function serializeArrayParam(name, value, options) {
  if (!Array.isArray(value)) {
    return "";
  }
  if (options.explode === false) {
    const joiner2 = { form: ",", spaceDelimited: "%20", pipeDelimited: "|" }[options.style] || ",";
    const final = (options.allowReserved === true ? value : value.map((v) => encodeURIComponent(v))).join(joiner2);
    switch (options.style) {
      case "simple": {
        return final;
      }
      case "label": {
        return `.${final}`;
      }
      case "matrix": {
        return `;${name}=${final}`;
      }
      // case "spaceDelimited":
      // case "pipeDelimited":
      default: {
        return `${name}=${final}`;
      }
    }
  }
  const joiner = { simple: ",", label: ".", matrix: ";" }[options.style] || "&";
  const values = [];
  for (const v of value) {
    if (options.style === "simple" || options.style === "label") {
      values.push(options.allowReserved === true ? v : encodeURIComponent(v));
    } else {
      values.push(serializePrimitiveParam(name, v, options));
    }
  }
  return options.style === "label" || options.style === "matrix" ? `${joiner}${values.join(joiner)}` : values.join(joiner);
}
function createQuerySerializer(options) {
  return function querySerializer(queryParams) {
    const search = [];
    if (queryParams && typeof queryParams === "object") {
      for (const name in queryParams) {
        const value = queryParams[name];
        if (value === void 0 || value === null) {
          continue;
        }
        if (Array.isArray(value)) {
          if (value.length === 0) {
            continue;
          }
          search.push(
            serializeArrayParam(name, value, {
              style: "form",
              explode: true,
              ...options?.array,
              allowReserved: options?.allowReserved || false
            })
          );
          continue;
        }
        if (typeof value === "object") {
          search.push(
            serializeObjectParam(name, value, {
              style: "deepObject",
              explode: true,
              ...options?.object,
              allowReserved: options?.allowReserved || false
            })
          );
          continue;
        }
        search.push(serializePrimitiveParam(name, value, options));
      }
    }
    return search.join("&");
  };
}
function defaultPathSerializer(pathname, pathParams) {
  let nextURL = pathname;
  for (const match of pathname.match(PATH_PARAM_RE) ?? []) {
    let name = match.substring(1, match.length - 1);
    let explode = false;
    let style = "simple";
    if (name.endsWith("*")) {
      explode = true;
      name = name.substring(0, name.length - 1);
    }
    if (name.startsWith(".")) {
      style = "label";
      name = name.substring(1);
    } else if (name.startsWith(";")) {
      style = "matrix";
      name = name.substring(1);
    }
    if (!pathParams || pathParams[name] === void 0 || pathParams[name] === null) {
      continue;
    }
    const value = pathParams[name];
    if (Array.isArray(value)) {
      nextURL = nextURL.replace(match, serializeArrayParam(name, value, { style, explode }));
      continue;
    }
    if (typeof value === "object") {
      nextURL = nextURL.replace(match, serializeObjectParam(name, value, { style, explode }));
      continue;
    }
    if (style === "matrix") {
      nextURL = nextURL.replace(match, `;${serializePrimitiveParam(name, value)}`);
      continue;
    }
    nextURL = nextURL.replace(match, style === "label" ? `.${encodeURIComponent(value)}` : encodeURIComponent(value));
  }
  return nextURL;
}
function defaultBodySerializer(body, headers) {
  if (body instanceof FormData) {
    return body;
  }
  if (headers) {
    const contentType = headers.get instanceof Function ? headers.get("Content-Type") ?? headers.get("content-type") : headers["Content-Type"] ?? headers["content-type"];
    if (contentType === "application/x-www-form-urlencoded") {
      return new URLSearchParams(body).toString();
    }
  }
  return JSON.stringify(body);
}
function createFinalURL(pathname, options) {
  let finalURL = `${options.baseUrl}${pathname}`;
  if (options.params?.path) {
    finalURL = options.pathSerializer(finalURL, options.params.path);
  }
  let search = options.querySerializer(options.params.query ?? {});
  if (search.startsWith("?")) {
    search = search.substring(1);
  }
  if (search) {
    finalURL += `?${search}`;
  }
  return finalURL;
}
function mergeHeaders(...allHeaders) {
  const finalHeaders = new Headers();
  for (const h of allHeaders) {
    if (!h || typeof h !== "object") {
      continue;
    }
    const iterator = h instanceof Headers ? h.entries() : Object.entries(h);
    for (const [k, v] of iterator) {
      if (v === null) {
        finalHeaders.delete(k);
      } else if (Array.isArray(v)) {
        for (const v2 of v) {
          finalHeaders.append(k, v2);
        }
      } else if (v !== void 0) {
        finalHeaders.set(k, v);
      }
    }
  }
  return finalHeaders;
}
function removeTrailingSlash(url) {
  if (url.endsWith("/")) {
    return url.substring(0, url.length - 1);
  }
  return url;
}

// src/errors.ts
var NETWORK_ERROR = "network-error";
var ApiError = class _ApiError extends Error {
  /** The HTTP status; 0 when no answer came. */
  status;
  /** The problem's stable kebab-case name, to match on (`not-found`, `network-error`…);
   * undefined for an answer that was not problem+json. */
  code;
  /** What went wrong and what to fix, for people: the problem's `detail`, else its title or the
   * HTTP status. */
  detail;
  /** The problem+json body as the server sent it; null when it sent none. */
  problem;
  /** The URL that was requested. */
  url;
  /** `options` set `code` and `detail` where no problem body carries them (see `network`). */
  constructor(status, problem, url, options = {}) {
    const detail = options.detail ?? (problem?.detail || problem?.title || `HTTP ${status}`);
    const code = options.code ?? problem?.code;
    super(`${detail}${code ? ` (${code})` : ""}`, "cause" in options ? { cause: options.cause } : void 0);
    this.name = "ApiError";
    this.status = status;
    this.code = code;
    this.detail = detail;
    this.problem = problem;
    this.url = url;
  }
  /** The error for a response that is not ok, reading its problem+json body when it has one. */
  static async from(response) {
    let problem = null;
    try {
      problem = await response.json();
    } catch {
    }
    return new _ApiError(response.status, problem, response.url);
  }
  /** The error for a fetch of `url` that rejected with `cause` before any answer came. */
  static network(url, cause) {
    const detail = `no answer from ${url} (${reason(cause)}): the server may be down or the address wrong; in a browser, a cross-origin request the server does not allow (CORS) fails the same way`;
    return new _ApiError(0, null, url, { code: NETWORK_ERROR, detail, cause });
  }
};
function reason(error) {
  const outer = error instanceof Error ? error.message : String(error);
  const inner = error instanceof Error ? error.cause : void 0;
  const detail = inner?.message || inner?.code;
  return detail ? `${outer}: ${detail}` : outer;
}

// node_modules/eventsource-parser/dist/index.js
var ParseError = class extends Error {
  constructor(message, options) {
    super(message), this.name = "ParseError", this.type = options.type, this.field = options.field, this.value = options.value, this.line = options.line;
  }
};
function noop(_arg) {
}
function createParser(callbacks) {
  if (typeof callbacks == "function")
    throw new TypeError(
      "`callbacks` must be an object, got a function instead. Did you mean `{onEvent: fn}`?"
    );
  const { onEvent = noop, onError = noop, onRetry = noop, onComment } = callbacks;
  let incompleteLine = "", isFirstChunk = true, id, data2 = "", eventType = "";
  function feed(newChunk) {
    const chunk = isFirstChunk ? newChunk.replace(/^\xEF\xBB\xBF/, "") : newChunk, [complete, incomplete] = splitLines(`${incompleteLine}${chunk}`);
    for (const line of complete)
      parseLine(line);
    incompleteLine = incomplete, isFirstChunk = false;
  }
  function parseLine(line) {
    if (line === "") {
      dispatchEvent();
      return;
    }
    if (line.startsWith(":")) {
      onComment && onComment(line.slice(line.startsWith(": ") ? 2 : 1));
      return;
    }
    const fieldSeparatorIndex = line.indexOf(":");
    if (fieldSeparatorIndex !== -1) {
      const field = line.slice(0, fieldSeparatorIndex), offset = line[fieldSeparatorIndex + 1] === " " ? 2 : 1, value = line.slice(fieldSeparatorIndex + offset);
      processField(field, value, line);
      return;
    }
    processField(line, "", line);
  }
  function processField(field, value, line) {
    switch (field) {
      case "event":
        eventType = value;
        break;
      case "data":
        data2 = `${data2}${value}
`;
        break;
      case "id":
        id = value.includes("\0") ? void 0 : value;
        break;
      case "retry":
        /^\d+$/.test(value) ? onRetry(parseInt(value, 10)) : onError(
          new ParseError(`Invalid \`retry\` value: "${value}"`, {
            type: "invalid-retry",
            value,
            line
          })
        );
        break;
      default:
        onError(
          new ParseError(
            `Unknown field "${field.length > 20 ? `${field.slice(0, 20)}\u2026` : field}"`,
            { type: "unknown-field", field, value, line }
          )
        );
        break;
    }
  }
  function dispatchEvent() {
    data2.length > 0 && onEvent({
      id,
      event: eventType || void 0,
      // If the data buffer's last character is a U+000A LINE FEED (LF) character,
      // then remove the last character from the data buffer.
      data: data2.endsWith(`
`) ? data2.slice(0, -1) : data2
    }), id = void 0, data2 = "", eventType = "";
  }
  function reset(options = {}) {
    incompleteLine && options.consume && parseLine(incompleteLine), isFirstChunk = true, id = void 0, data2 = "", eventType = "", incompleteLine = "";
  }
  return { feed, reset };
}
function splitLines(chunk) {
  const lines = [];
  let incompleteLine = "", searchIndex = 0;
  for (; searchIndex < chunk.length; ) {
    const crIndex = chunk.indexOf("\r", searchIndex), lfIndex = chunk.indexOf(`
`, searchIndex);
    let lineEnd = -1;
    if (crIndex !== -1 && lfIndex !== -1 ? lineEnd = Math.min(crIndex, lfIndex) : crIndex !== -1 ? crIndex === chunk.length - 1 ? lineEnd = -1 : lineEnd = crIndex : lfIndex !== -1 && (lineEnd = lfIndex), lineEnd === -1) {
      incompleteLine = chunk.slice(searchIndex);
      break;
    } else {
      const line = chunk.slice(searchIndex, lineEnd);
      lines.push(line), searchIndex = lineEnd + 1, chunk[searchIndex - 1] === "\r" && chunk[searchIndex] === `
` && searchIndex++;
    }
  }
  return [lines, incompleteLine];
}

// src/events.ts
var sleep = (ms, signal) => new Promise((resolve, reject) => {
  const timer = setTimeout(resolve, ms);
  signal?.addEventListener("abort", () => {
    clearTimeout(timer);
    reject(signal.reason);
  }, { once: true });
});
function toEvent(message) {
  const type = message.event;
  if (type !== "status" && type !== "progress" && type !== "done") return null;
  return { type, id: message.id, data: JSON.parse(message.data) };
}
async function* jobEvents(request, options = {}) {
  let lastEventId = options.lastEventId;
  let retryMs = options.retryMs ?? 1e3;
  const maxRetries = options.maxRetries ?? 10;
  let failures = 0;
  for (; ; ) {
    const headers = { ...request.headers, Accept: "text/event-stream" };
    if (lastEventId !== void 0) headers["Last-Event-ID"] = lastEventId;
    let response = null;
    let unanswered = null;
    try {
      response = await request.fetch(request.url, { headers, signal: options.signal, cache: "no-store" });
    } catch (e) {
      if (options.signal?.aborted) throw e;
      unanswered = e;
    }
    if (response && !response.ok) throw await ApiError.from(response);
    if (response?.body) {
      const pending = [];
      const parser = createParser({
        onEvent: (message) => {
          const event = toEvent(message);
          if (event) pending.push(event);
        },
        onRetry: (ms) => {
          retryMs = ms;
        }
      });
      const reader = response.body.pipeThrough(new TextDecoderStream()).getReader();
      try {
        for (; ; ) {
          const { done, value } = await reader.read();
          if (done) break;
          parser.feed(value);
          for (const event of pending.splice(0)) {
            if (event.id !== void 0) lastEventId = event.id;
            failures = 0;
            yield event;
            if (event.type === "done") return;
          }
        }
      } catch (e) {
        if (options.signal?.aborted) throw e;
      } finally {
        await reader.cancel().catch(() => {
        });
      }
    }
    failures += 1;
    if (failures > maxRetries) {
      if (unanswered !== null) throw unanswered instanceof ApiError ? unanswered : ApiError.network(request.url, unanswered);
      throw new Error(`the event stream of ${request.url} dropped ${failures} times`);
    }
    await sleep(retryMs, options.signal);
  }
}

// src/index.ts
var TERMINAL = ["succeeded", "failed", "cancelled"];
var sleep2 = (ms) => new Promise((resolve) => setTimeout(resolve, ms));
function randomUuid() {
  const b = crypto.getRandomValues(new Uint8Array(16));
  b[6] = b[6] & 15 | 64;
  b[8] = b[8] & 63 | 128;
  const h = Array.from(b, (x) => x.toString(16).padStart(2, "0")).join("");
  return `${h.slice(0, 8)}-${h.slice(8, 12)}-${h.slice(12, 16)}-${h.slice(16, 20)}-${h.slice(20)}`;
}
function answering(fetch) {
  return async (input, init) => {
    try {
      return await fetch(input, init);
    } catch (e) {
      if (!(e instanceof TypeError)) throw e;
      throw ApiError.network(typeof input === "string" ? input : input instanceof URL ? input.href : input.url, e);
    }
  };
}
var Choreo = class {
  /** openapi-fetch's typed client, for any route: `choreo.api.GET('/v1/jobs/{id}', …)`. */
  api;
  baseUrl;
  #headers;
  #fetch;
  /** How the last wait() followed its job: 'events' or 'poll'. */
  lastTransport = null;
  constructor(options = {}) {
    this.baseUrl = (options.baseUrl ?? "").replace(/\/+$/, "");
    this.#headers = options.apiKey ? { Authorization: `Bearer ${options.apiKey}` } : {};
    this.#fetch = answering(options.fetch ?? ((input, init) => globalThis.fetch(input, init)));
    this.api = createClient({ baseUrl: this.baseUrl, headers: this.#headers, fetch: (request) => this.#fetch(request) });
  }
  /** An absolute URL for a path of this server (links in answers are paths). */
  url(path) {
    return /^https?:/.test(path) ? path : `${this.baseUrl}${path}`;
  }
  /** GET any path of this server with the key (a job's `links`, a song's audio): the Response, or ApiError. */
  async fetch(path, init = {}) {
    const headers = { ...this.#headers, ...init.headers };
    const response = await this.#fetch(this.url(path), { ...init, headers });
    if (!response.ok) throw await ApiError.from(response);
    return response;
  }
  models() {
    return data(this.api.GET("/v1/models"));
  }
  song(id) {
    return data(this.api.GET("/v1/songs/{id}", { params: { path: { id } } }));
  }
  /** GET /v1/songs: this key's songs, newest first; pass a page's `next_cursor` as `cursor` for the next. */
  listSongs(query = { limit: 50 }) {
    return data(this.api.GET("/v1/songs", { params: { query } }));
  }
  job(id) {
    return data(this.api.GET("/v1/jobs/{id}", { params: { path: { id } } }));
  }
  jobs(query = { limit: 50 }) {
    return data(this.api.GET("/v1/jobs", { params: { query } }));
  }
  /** DELETE /v1/jobs/{id}: cancels a queued or running job. */
  cancel(id) {
    return data(this.api.DELETE("/v1/jobs/{id}", { params: { path: { id } } }));
  }
  /** POST /v1/songs: uploads a song (a File, or a Blob with `filename`); its analysis starts at once. */
  upload(song, filename = song.name || "song") {
    const form = new FormData();
    form.append("file", song, filename);
    return data(this.api.POST("/v1/songs", { body: {}, bodySerializer: () => form }));
  }
  /** POST /v1/rigs: a skeleton (BVH or glb) in its rest pose, with an optional joint mapping. */
  uploadRig(file, mapping = null, filename = file.name || "rig") {
    const form = new FormData();
    form.append("file", file, filename);
    if (mapping) form.append("mapping", JSON.stringify(mapping));
    return data(this.api.POST("/v1/rigs", { body: {}, bodySerializer: () => form }));
  }
  rig(id) {
    return data(this.api.GET("/v1/rigs/{id}", { params: { path: { id } } }));
  }
  /** GET /v1/rigs: this key's rigs, newest first; pass a page's `next_cursor` as `cursor` for the next. */
  listRigs(query = { limit: 50 }) {
    return data(this.api.GET("/v1/rigs", { params: { query } }));
  }
  /** DELETE /v1/rigs/{id}: deletes the rig and its file (204); an unknown id is an ApiError (404). */
  async deleteRig(id) {
    const { error, response } = await this.api.DELETE("/v1/rigs/{id}", { params: { path: { id } } });
    if (!response.ok) throw new ApiError(response.status, asProblem(error), response.url);
  }
  /** POST /v1/jobs with an idempotency key (a new one unless given), so a retried call makes one job. */
  createJob(body, idempotencyKey = randomUuid()) {
    return data(this.api.POST("/v1/jobs", { body, params: { header: { "Idempotency-Key": idempotencyKey } } }));
  }
  /** The job's server-sent events (see jobEvents), with this client's key. */
  events(jobId, options = {}) {
    const url = this.url(`/v1/jobs/${encodeURIComponent(jobId)}/events`);
    return jobEvents({ url, headers: this.#headers, fetch: this.#fetch }, options);
  }
  /**
   * Resolves with the job once it has ended (succeeded, failed or cancelled: check `status`).
   * Follows its server-sent events; on a server without the events route (it answers 404 for a
   * job that GET /v1/jobs/{id} finds) it polls instead.
   */
  async wait(jobId, options = {}) {
    let job = await this.job(jobId);
    if (TERMINAL.includes(job.status)) {
      options.onUpdate?.(job);
      return job;
    }
    if (options.transport !== "poll") {
      try {
        this.lastTransport = "events";
        const resuming = options.lastEventId !== void 0;
        let view = resuming ? job : unstarted(job);
        if (resuming) options.onUpdate?.(view);
        for await (const event of this.events(jobId, options)) {
          options.onEvent?.(event);
          view = apply(view, event);
          options.onUpdate?.(view);
          if (event.type === "done") return view;
        }
        throw new Error(`the events of job ${jobId} ended without a done event`);
      } catch (e) {
        const noRoute = e instanceof ApiError && (e.status === 404 || e.status === 405) && options.transport !== "events";
        if (!noRoute) throw e;
        job = await this.job(jobId);
      }
    }
    this.lastTransport = "poll";
    options.onUpdate?.(job);
    while (!TERMINAL.includes(job.status)) {
      await sleep2(options.pollMs ?? 500);
      options.signal?.throwIfAborted();
      job = await this.job(jobId);
      options.onUpdate?.(job);
    }
    return job;
  }
  /** Polls a song until its analysis is done or failed (analysis is a short job without events). */
  async waitForSong(id, onUpdate = () => {
  }, pollMs = 400) {
    for (; ; ) {
      const song = await this.song(id);
      onUpdate(song);
      if (song.analysis || song.analysis_status && TERMINAL.includes(song.analysis_status) && song.analysis_status !== "succeeded") return song;
      await sleep2(pollMs);
    }
  }
  /** A finished job's file as a Response (`.blob()`, `.arrayBuffer()`, `.json()`); `rig` retargets
   * motion.bvh/glb/vrma to a built-in or uploaded rig. */
  download(jobId, file, options = {}) {
    const query = options.rig ? `?rig=${encodeURIComponent(options.rig)}` : "";
    return this.fetch(`/v1/jobs/${encodeURIComponent(jobId)}/${file}${query}`);
  }
  /** The song's audio as uploaded. */
  songAudio(songId) {
    return this.fetch(`/v1/songs/${encodeURIComponent(songId)}/audio`).then((r) => r.blob());
  }
};
function unstarted(job) {
  return { ...job, status: "queued", stage: null, progress: 0, attempts: 0, error: null, started_at: null, finished_at: null };
}
function apply(job, event) {
  switch (event.type) {
    case "status":
      return { ...job, status: event.data.to, attempts: event.data.attempt ?? job.attempts, error: event.data.error ?? job.error };
    case "progress":
      return { ...job, stage: event.data.stage, progress: event.data.progress };
    case "done":
      return event.data;
  }
}
function asProblem(error) {
  return typeof error === "object" && error !== null ? error : null;
}
async function data(call) {
  const { data: data2, error, response } = await call;
  if (!response.ok || data2 === void 0) {
    throw new ApiError(response.status, asProblem(error), response.url);
  }
  return data2;
}
export {
  ApiError,
  Choreo,
  NETWORK_ERROR,
  TERMINAL,
  jobEvents
};
