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

// The paged fields of each result (GetResultRequest's comment: the document describes the
// fields, not which of them are split over the pages). A kind missing here is read whole.
const PAGED = {
  simulate: ['poincare', 'events', 'periodModes', 'trajectory'],
  sweep: ['up', 'down'],
  continue: ['points'],
  trace: ['curves'],
  optimum: [],
  optimumMap: ['cells'],
};
// The fields of a GetResultResponse that are not its result (its oneof holds the result).
const RESULT_ENVELOPE = new Set(['name', 'totalPoints', 'nextPageToken']);

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
    const pageKind = Object.keys(page).find((k) => !RESULT_ENVELOPE.has(k));
    if (pageKind === undefined) throw new ApiError(200, 'UNKNOWN', `${name}: a result of no kind`);
    if (result === null) {
      kind = pageKind;
      result = page[kind];
    } else {
      for (const field of PAGED[kind] ?? []) {
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

/**
 * What the page takes from the server's OpenAPI document (GET /openapi.json, open: no token):
 * the job kinds and their submit routes, the routes of other operations by operationId, and
 * the schemas of request fields (enum values, parameter names).
 */
export class ApiDescription {
  constructor(document) {
    this.document = document;
    // operationId -> {method, path, operation}
    this.operations = new Map();
    for (const [path, item] of Object.entries(document.paths ?? {})) {
      for (const [method, operation] of Object.entries(item)) {
        if (operation?.operationId) {
          this.operations.set(operation.operationId, {method, path, operation});
        }
      }
    }
    // The kinds: every Submit* operation (POST, a path without parameters), named by its
    // operationId ("SubmitOptimumMap" -> "optimum-map"), in the document's order. The route is
    // the operation's path, whatever it is.
    this.kinds = new Map();  // kind -> {route, operationId}
    for (const [operationId, {method, path}] of this.operations) {
      const match = /^Submit([A-Z][A-Za-z0-9]*)$/.exec(operationId);
      if (method === 'post' && match && !path.includes('{')) {
        const kind = match[1].replace(/(?<!^)([A-Z])/g, '-$1').toLowerCase();
        this.kinds.set(kind, {route: path, operationId});
      }
    }
    if (this.kinds.size === 0) throw new Error('/openapi.json: no Submit operation');
  }

  /** The path of the operation `operationId` (a literal path: no path parameter). */
  route(operationId) {
    const found = this.operations.get(operationId);
    if (!found) throw new Error(`/openapi.json: no operation ${operationId}`);
    return found.path;
  }

  // The schema `schema` stands for: $ref followed, a described reference's allOf unwrapped.
  resolve(schema) {
    let node = schema;
    for (let hops = 0; node && hops < 16; ++hops) {
      if (node.$ref) {
        const name = node.$ref.replace(/^#\/components\/schemas\//, '');
        node = this.document.components?.schemas?.[name];
      } else if (node.allOf?.length === 1) {
        node = node.allOf[0];
      } else {
        return node;
      }
    }
    return node ?? null;
  }

  /**
   * The schema of the field at `path` ("request.trace.curveSteps") of the body of the submit
   * operation of `kind` (an array's items for a repeated field), or null when there is none.
   */
  fieldSchema(kind, path) {
    const route = this.kinds.get(kind)?.route;
    const body = this.document.paths?.[route]?.post?.requestBody;
    let node = this.resolve(body?.content?.['application/json']?.schema);
    for (const key of path.split('.')) {
      node = this.resolve(node?.properties?.[key]);
      if (node?.type === 'array') node = this.resolve(node.items);
    }
    return node ?? null;
  }

  /** The values of an enum field, without its *_UNSPECIFIED (unset: the server's default). */
  enumValues(kind, path) {
    return (this.fieldSchema(kind, path)?.enum ?? []).filter((v) => !v.endsWith('_UNSPECIFIED'));
  }

  /** The fields' (JSON) names of the message schema `name` ("drillbif.v1.ModelParams"). */
  fieldsOf(name) {
    return Object.keys(this.document.components?.schemas?.[name]?.properties ?? {});
  }
}

/** Loads /openapi.json: an ApiDescription, or throws ApiError (the page cannot work without). */
export async function loadDescription() {
  let response;
  try {
    response = await fetch('/openapi.json');
  } catch (e) {
    throw new ApiError(0, 'UNAVAILABLE', `/openapi.json cannot be loaded (${e.message})`);
  }
  if (!response.ok) {
    const error = await errorOf(response);
    error.message = `/openapi.json: ${error.message}`;
    throw error;
  }
  try {
    return new ApiDescription(await response.json());
  } catch (e) {
    throw new ApiError(response.status, 'INTERNAL',
        `/openapi.json is not a usable API description (${e.message})`);
  }
}
