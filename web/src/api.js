// The REST API of drillbif-server (docs/service.md), called with the token of the session.
//
// The token is kept in sessionStorage (gone with the tab) and sent as "Authorization: Bearer"
// on every call. The :watch stream is read with fetch() rather than EventSource, which cannot
// send that header: the token then never appears in a URL or a server log.

const TOKEN_KEY = 'drillbif.token';

/** The token of this tab ('' when none). */
export function token() {
  return sessionStorage.getItem(TOKEN_KEY) ?? '';
}

/** Keeps `value` as the token of this tab (empty: none). */
export function setToken(value) {
  if (value) {
    sessionStorage.setItem(TOKEN_KEY, value);
  } else {
    sessionStorage.removeItem(TOKEN_KEY);
  }
}

/** An API error: the HTTP status and the gateway's JSON error {code, message}. */
export class ApiError extends Error {
  constructor(status, code, message) {
    super(message);
    this.status = status;
    this.code = code;
  }

  /** One line for the user, with a hint for the statuses a token fixes. */
  describe() {
    let text = `${this.status} ${this.code}: ${this.message}`;
    if (this.status === 401) text += ' (enter the server\'s token above)';
    if (this.status === 403) text += ' (this token may not do that)';
    return text;
  }
}

function headers(extra = {}) {
  const out = {...extra};
  const t = token();
  if (t) out.Authorization = `Bearer ${t}`;
  return out;
}

// The ApiError of a failed answer (its JSON body, or its status text when it has none).
async function errorOf(response) {
  const text = await response.text();
  try {
    const body = JSON.parse(text);
    return new ApiError(response.status, body.code ?? 'ERROR', body.message ?? text);
  } catch {
    return new ApiError(response.status, 'ERROR', text || response.statusText);
  }
}

/** Calls `path` ("/v1/..."): the parsed JSON answer, or throws ApiError. */
export async function call(path, {method = 'GET', body} = {}) {
  const init = {method, headers: headers()};
  if (body !== undefined) {
    init.headers['Content-Type'] = 'application/json';
    init.body = JSON.stringify(body);
  }
  let response;
  try {
    response = await fetch(path, init);
  } catch (e) {
    throw new ApiError(0, 'UNAVAILABLE', `the server cannot be reached (${e.message})`);
  }
  if (!response.ok) throw await errorOf(response);
  return response.json();
}

/**
 * Every operation (GET /v1/operations, following next_page_token; oldest first), at most
 * `maxPages` pages of `pageSize`. Returns {operations, truncated}.
 */
export async function listOperations({pageSize = 100, maxPages = 20} = {}) {
  const operations = [];
  let pageToken = '';
  for (let page = 0; page < maxPages; ++page) {
    const query = new URLSearchParams({page_size: String(pageSize)});
    if (pageToken) query.set('page_token', pageToken);
    const answer = await call(`/v1/operations?${query}`);
    operations.push(...(answer.operations ?? []));
    pageToken = answer.nextPageToken ?? '';
    if (!pageToken) return {operations, truncated: false};
  }
  return {operations, truncated: true};
}

// The paged fields of each result (GetResultRequest): their items are split over the pages.
const PAGED = {
  simulate: ['poincare', 'events', 'periodModes', 'trajectory'],
  sweep: ['up', 'down'],
  continue: ['points'],
  trace: ['curves'],
  optimum: [],
};

/**
 * The whole result of a SUCCEEDED operation (GET :result, following next_page_token and
 * merging the pages' items in order). Returns {kind, result}.
 */
export async function getResult(name) {
  let kind = null;
  let result = null;
  let pageToken = '';
  do {
    const query = new URLSearchParams();
    if (pageToken) query.set('page_token', pageToken);
    const page = await call(`/v1/${name}:result?${query}`);
    const pageKind = Object.keys(PAGED).find((k) => k in page);
    if (pageKind === undefined) throw new ApiError(200, 'UNKNOWN', `${name}: result of no known kind`);
    if (result === null) {
      kind = pageKind;
      result = page[kind];
    } else {
      for (const field of PAGED[kind]) {
        if (page[kind][field]) result[field] = (result[field] ?? []).concat(page[kind][field]);
      }
    }
    pageToken = page.nextPageToken ?? '';
  } while (pageToken);
  return {kind, result};
}

/**
 * Follows GET :watch (Server-Sent Events of JobMetadata): calls onMetadata(metadata) for each
 * event until the stream ends (the job reached a final state) or `signal` aborts it. Throws
 * ApiError when the call is refused or the stream ends with an error event.
 */
export async function watch(name, onMetadata, signal) {
  let response;
  try {
    response = await fetch(`/v1/${name}:watch`, {headers: headers(), signal});
  } catch (e) {
    if (signal?.aborted) return;
    throw new ApiError(0, 'UNAVAILABLE', `the server cannot be reached (${e.message})`);
  }
  if (!response.ok) throw await errorOf(response);
  const reader = response.body.pipeThrough(new TextDecoderStream()).getReader();
  let buffer = '';
  try {
    for (;;) {
      const {value, done} = await reader.read();
      if (done) return;
      buffer += value;
      let end;
      while ((end = buffer.indexOf('\n\n')) >= 0) {
        const block = buffer.slice(0, end);
        buffer = buffer.slice(end + 2);
        let event = 'message';
        let data = '';
        for (const line of block.split('\n')) {
          if (line.startsWith('event:')) event = line.slice(6).trim();
          if (line.startsWith('data:')) data += line.slice(5).trim();
        }
        if (event === 'error') {
          const body = JSON.parse(data);
          throw new ApiError(200, body.code ?? 'ERROR', body.message ?? data);
        }
        if (data) onMetadata(JSON.parse(data));
      }
    }
  } catch (e) {
    if (signal?.aborted) return;
    throw e;
  } finally {
    reader.releaseLock();
  }
}
