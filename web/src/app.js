// The dashboard: token, submit forms, the job list with live progress, and the plot of a
// finished job's result, with a query panel on an optimum map. Everything goes through the REST
// API (api.js), whose routes and kinds come from the server's /openapi.json at load.
import * as api from './api.js';
import {readForm, renderForm} from './forms.js';
import * as plots from './plots.js';

const $ = (id) => document.getElementById(id);
const FINAL = new Set(['SUCCEEDED', 'FAILED', 'CANCELLED']);
const REQUESTS_KEY = 'drillbif.requests';
// Watch streams open at once, besides the one of the job submitted last. Each holds one of the
// browser's 6 connections to the server (HTTP/1.1), and the page's calls need the others.
const MAX_WATCHES = 3;
// How often the list reloads while it has running or queued jobs no stream follows.
const REFRESH_MS = 5000;

// The requests this tab submitted, by operation name ({kind, request}): the result messages do
// not repeat them, and the plots want the parameters' names and the box.
const requests = JSON.parse(sessionStorage.getItem(REQUESTS_KEY) ?? '{}');
const jobs = new Map();  // operation name -> {operation, row, watch: AbortController}
let kind = 'trace';
let description = null;  // api.ApiDescription: the kinds and routes, once /openapi.json loaded
let shown = null;  // the operation whose result is on display
let pendingPlot = null;  // the operation submitted last: plotted when it succeeds

function showApiError(error) {
  const box = $('api-error');
  if (error) {
    box.textContent = error instanceof api.ApiError ? error.describe() : String(error);
    box.hidden = false;
  } else {
    box.hidden = true;
  }
}

function shortName(name) {
  return name.replace(/^operations\//, '').slice(0, 8);
}

function metadataOf(operation) {
  return operation.metadata ?? {};
}

// --- Jobs ----------------------------------------------------------------------------------------

function renderRow(job) {
  const {operation} = job;
  const meta = metadataOf(operation);
  const state = meta.state ?? 'QUEUED';
  const row = job.row ?? document.createElement('tr');
  job.row = row;
  row.dataset.name = operation.name;
  row.dataset.state = state;
  row.classList.toggle('selected', operation.name === shown);
  const progress = document.createElement('progress');
  progress.max = 1;
  progress.value = meta.progress ?? 0;
  const progressCell = document.createElement('td');
  progressCell.append(progress, ` ${Math.round((meta.progress ?? 0) * 100)}%`);
  if (meta.currentValue !== undefined) progressCell.append(` at ${meta.currentValue.toPrecision(4)}`);
  const stateCell = document.createElement('td');
  stateCell.className = `state state-${state}`;
  stateCell.textContent = state + (meta.cacheHit ? ' (cached)' : '');
  if (operation.error) stateCell.title = operation.error.message ?? '';
  const actions = document.createElement('td');
  if (state === 'SUCCEEDED') {
    const plot = document.createElement('button');
    plot.textContent = 'Plot';
    plot.className = 'plot-button';
    plot.addEventListener('click', () => showResult(operation.name));
    actions.append(plot);
  }
  if (!FINAL.has(state)) {
    const cancel = document.createElement('button');
    cancel.textContent = 'Cancel';
    cancel.className = 'cancel-button';
    cancel.addEventListener('click', () => cancelJob(operation.name));
    actions.append(cancel);
  }
  if (state === 'FAILED' && operation.error) {
    const why = document.createElement('span');
    why.className = 'error';
    why.textContent = ` ${operation.error.message ?? ''}`;
    actions.append(why);
  }
  const cell = (text, className = '') => {
    const td = document.createElement('td');
    td.textContent = text;
    td.className = className;
    return td;
  };
  const created = meta.createTime ? new Date(meta.createTime).toLocaleTimeString() : '';
  row.replaceChildren(cell(shortName(operation.name), 'name'),
      cell((meta.kind ?? '').toLowerCase(), 'kind'), stateCell, progressCell, cell(created),
      actions);
  return row;
}

// Shows the job list newest first.
function renderJobs() {
  const rows = [...jobs.values()].reverse().map(renderRow);
  $('jobs-body').replaceChildren(...rows);
}

// Follows a running job's :watch stream, updating its row until it is final.
function follow(job) {
  if (job.watch || FINAL.has(metadataOf(job.operation).state)) return;
  const controller = new AbortController();
  job.watch = controller;
  const name = job.operation.name;
  api.watch(name, (meta) => {
    job.operation = {...job.operation, metadata: meta};
    renderRow(job);
  }, controller.signal).then(async () => {
    if (controller.signal.aborted) return;
    // Final. A failed or cancelled operation holds the error the metadata does not (a
    // succeeded one its whole result, which is not needed here: :result pages it).
    if (metadataOf(job.operation).state !== 'SUCCEEDED') {
      job.operation = await api.call(`/v1/${name}`);
    }
    renderRow(job);
    if (pendingPlot === name && metadataOf(job.operation).state === 'SUCCEEDED') {
      pendingPlot = null;
      await showResult(name);
    }
  }).catch((error) => {
    if (!controller.signal.aborted) showApiError(error);
  }).finally(() => {
    if (job.watch === controller) job.watch = null;
    if (!controller.signal.aborted) followSome();
  });
}

// Follows the live jobs, the running and newest first, up to MAX_WATCHES streams; the others
// are updated by reloading the list every REFRESH_MS while they last. A stream counts until its
// follow() ends, also after its job turned final (its last message came, the stream may not have
// closed yet).
let refreshTimer = null;
function followSome() {
  const state = (job) => metadataOf(job.operation).state;
  const live = [...jobs.values()].reverse().filter((job) => !FINAL.has(state(job)));
  live.sort((p, q) => (state(q) === 'RUNNING') - (state(p) === 'RUNNING'));
  let open = [...jobs.values()].filter((job) => job.watch).length;
  for (const job of live) {
    if (job.watch || open >= MAX_WATCHES) continue;
    follow(job);
    ++open;
  }
  const unfollowed = live.some((job) => !job.watch);
  if (unfollowed && refreshTimer === null) {
    refreshTimer = setTimeout(() => {
      refreshTimer = null;
      refreshJobs();
    }, REFRESH_MS);
  }
}

/** Reloads the job list (every page) and follows the running jobs. */
async function refreshJobs() {
  try {
    const {operations, truncated} = await api.listOperations();
    showApiError(null);
    for (const operation of operations) {
      const job = jobs.get(operation.name) ?? {};
      job.operation = operation;
      jobs.set(operation.name, job);
    }
    renderJobs();
    followSome();
    $('jobs-note').textContent = truncated ? 'Only the oldest jobs are listed.' : '';
  } catch (error) {
    showApiError(error);
  }
}

async function cancelJob(name) {
  try {
    await api.call(`/v1/${name}:cancel`, {method: 'POST', body: {}});
  } catch (error) {
    showApiError(error);
  }
}

// --- Results -------------------------------------------------------------------------------------

// The TraceResult of a finished trace this tab submitted with the same trace request as an
// optimum (the curves of its box; a stability region asked for too does not change them), or
// null.
async function traceOfBox(traceRequest) {
  const curvesOf = (request) => JSON.stringify({...request, region: undefined});
  const wanted = curvesOf(traceRequest);
  for (const [name, {kind: k, request}] of Object.entries(requests)) {
    if (k !== 'trace' || curvesOf(request) !== wanted) continue;
    const job = jobs.get(name);
    if (metadataOf(job?.operation ?? {}).state !== 'SUCCEEDED') continue;
    return (await api.getResult(name)).result;
  }
  return null;
}

function summaryOf(kind, result) {
  const parts = [`status ${result.status ?? '?'}`];
  if (result.message) parts.push(result.message);
  // A trace's and an optimum's messages already say what they found; a continuation's says
  // how its directions ended.
  if (kind === 'continue') {
    parts.push(`${(result.points ?? []).length} points, ` +
      `${(result.specialPoints ?? []).length} special points`);
  } else if (kind === 'trace' && !result.message) {
    parts.push(`${(result.curves ?? []).length} curves, ` +
      `${(result.codim2Points ?? []).length} codimension-2 points`);
  } else if (kind === 'optimum' && !result.message && result.params) {
    parts.push(`ROP ${Number(result.rop ?? 0).toPrecision(5)} at ${JSON.stringify(result.params)}`);
  } else if (kind === 'optimumMap' && !result.message) {
    // int64 counters are JSON strings.
    parts.push(`${(result.cells ?? []).length} cells over ${(result.over ?? []).join(', ')}: ` +
      `${Number(result.cellsFound ?? 0)} found, ${Number(result.cellsNotFound ?? 0)} not found, ` +
      `${Number(result.cellsFailed ?? 0)} failed`);
  }
  if (result.wallSeconds !== undefined) parts.push(`${result.wallSeconds.toFixed(2)} s`);
  return parts.join(' · ');
}

/** Fetches the result of `name` and plots it. */
async function showResult(name) {
  shown = name;
  for (const job of jobs.values()) job.row?.classList.toggle('selected', job.operation.name === name);
  $('result-name').textContent = shortName(name);
  $('result-summary').textContent = 'loading...';
  $('result-controls').replaceChildren();
  $('result-panel').replaceChildren();
  const container = $('plot');
  plots.clearPlot(container);
  try {
    const {kind: resultKind, result} = await api.getResult(name);
    if (shown !== name) return;
    // A map's result repeats its optimum request: a map submitted anywhere can be queried.
    const request = requests[name]?.request ??
        (resultKind === 'optimumMap' && result.optimum ? {optimum: result.optimum} : undefined);
    $('result-summary').textContent = summaryOf(resultKind, result);
    switch (resultKind) {
      case 'continue': {
        const select = document.createElement('select');
        select.id = 'measure';
        for (const [value, text] of Object.entries(plots.CONTINUE_MEASURES)) {
          select.add(new Option(text, value));
        }
        select.addEventListener('change',
            () => plots.plotContinue(container, result, request, select.value));
        $('result-controls').append('Measure: ', select);
        plots.plotContinue(container, result, request, select.value);
        break;
      }
      case 'trace':
        plots.plotTrace(container, result, request);
        break;
      case 'optimum':
        plots.plotOptimum(container, result, request,
            request ? await traceOfBox(request.trace) : null);
        break;
      case 'simulate':
        plots.plotSimulate(container, result);
        break;
      case 'sweep':
        plots.plotSweep(container, result, request);
        break;
      case 'optimumMap':
        plots.plotOptimumMap(container, result, request, null);
        showMapQuery(name, result, request);
        break;
    }
    showApiError(null);
  } catch (error) {
    $('result-summary').textContent = '';
    showApiError(error);
  }
}

// --- Optimum map queries -------------------------------------------------------------------------

// The optimum request of a map (OptimumMapRequest.optimum) at condition values `values` (one per
// condition of `over`): what QueryOptimum answers from the map.
function optimumAt(optimum, over, values) {
  const params = {...(optimum.trace?.params ?? {})};
  over.forEach((condition, i) => {
    params[condition] = values[i];
  });
  return {...optimum, trace: {...(optimum.trace ?? {}), params}};
}

// A condition value as a person reads it: 0.145, not 0.14500000000000002.
function short(value) {
  return String(Number(Number(value).toPrecision(10)));
}

// The rows of the answer table of a QueryOptimumResponse at condition values `values`.
function answerRows(answer, over, values) {
  const rows = [];
  const {optimum = {}, fromMap} = answer;
  const row = (label, text, id) => {
    const tr = document.createElement('tr');
    const th = document.createElement('th');
    th.textContent = label;
    const td = document.createElement('td');
    td.textContent = text;
    if (id) td.id = id;
    tr.append(th, td);
    rows.push(tr);
  };
  row('asked', over.map((c, i) => `${c} = ${short(values[i])}`).join(', '), 'map-answer-asked');
  row('status', optimum.status ?? '(none)', 'map-answer-status');
  if (fromMap) {
    row('verified', fromMap.verified ? 'yes' : 'no', 'map-answer-verified');
    row('verification', fromMap.verification ?? '', 'map-answer-verification');
    row('interpolated', fromMap.interpolated ? 'yes' : 'no (the nearest cell)');
  } else {
    row('from map', 'no (a stored or computed optimum)', 'map-answer-verified');
  }
  row('ROP', Number(optimum.rop ?? 0).toPrecision(6), 'map-answer-rop');
  const params = optimum.params ?? {};
  row('params', Object.entries(params).map(([k, v]) => `${k} = ${Number(v).toPrecision(6)}`)
      .join(', '), 'map-answer-params');
  if (optimum.margin) row('margin', optimum.margin.map((m) => m.toPrecision(4)).join(', '));
  if (optimum.signature) row('signature', optimum.signature);
  if (fromMap) {
    row('cells used', (fromMap.cells ?? []).map((c) =>
      `[${(c.index ?? []).join(', ')}] at ${(c.condition ?? []).map(short).join(', ')} (weight ` +
      `${Number(c.weight ?? 0).toFixed(3)})`).join('; '), 'map-answer-cells');
    row('largest multiplier', Number(fromMap.maxMultiplier ?? 0).toPrecision(4));
  }
  return rows;
}

/**
 * The query panel of the map `name` on display: a value of each condition within [from, to]
 * (slider and number kept together), Query -> POST QueryOptimum with the map's optimum request
 * at those values; the answer is listed and marked on the map's plot.
 */
function showMapQuery(name, result, request) {
  const controls = $('result-panel');
  const over = result.over ?? [];
  const panel = document.createElement('div');
  panel.id = 'map-query';
  if (!request?.optimum) {
    panel.textContent = 'Query: this map\'s result does not say its optimum request (box, ' +
      'margin, grid).';
    controls.append(panel);
    return;
  }
  const inputs = over.map((condition, i) => {
    const from = result.from[i];
    const to = result.to[i];
    const steps = result.steps[i];
    // Halfway between the first two cells: an answer interpolated between neighbours (rounded:
    // 0.1425, not 0.14250000000000002).
    const start = Number((from + 0.5 * (to - from) / (steps - 1)).toPrecision(6));
    const slider = document.createElement('input');
    slider.type = 'range';
    slider.min = String(from);
    slider.max = String(to);
    slider.step = String((to - from) / 1000);
    slider.value = String(start);
    slider.id = `map-query-slider-${i}`;
    const number = document.createElement('input');
    number.type = 'number';
    number.min = String(from);
    number.max = String(to);
    number.step = 'any';
    number.value = String(start);
    number.id = `map-query-value-${i}`;
    slider.addEventListener('input', () => {
      number.value = slider.value;
    });
    number.addEventListener('input', () => {
      slider.value = number.value;
    });
    const label = document.createElement('label');
    label.htmlFor = number.id;
    label.textContent = `${condition} in [${from}, ${to}]`;
    const row = document.createElement('div');
    row.className = 'query-condition';
    row.append(label, slider, number);
    return {row, number};
  });
  const button = document.createElement('button');
  button.type = 'button';
  button.id = 'map-query-button';
  button.textContent = 'Query';
  const status = document.createElement('span');
  status.id = 'map-query-status';
  status.className = 'status';
  const answer = document.createElement('table');
  answer.id = 'map-answer';
  answer.className = 'answer';
  button.addEventListener('click', async () => {
    const values = inputs.map(({number}) => Number(number.value));
    status.textContent = ' querying...';
    answer.replaceChildren();
    try {
      const response = await api.call(description.route('QueryOptimum'), {method: 'POST',
        body: {request: optimumAt(request.optimum, over, values)}});
      if (shown !== name) return;
      status.textContent = '';
      answer.replaceChildren(...answerRows(response, over, values));
      plots.plotOptimumMap($('plot'), result, request, {values, answer: response});
    } catch (error) {
      status.textContent = ` ${error instanceof api.ApiError ? error.describe() : String(error)}`;
    }
  });
  const heading = document.createElement('h3');
  heading.textContent = 'Query the map';
  panel.append(heading, ...inputs.map(({row}) => row), button, status, answer);
  controls.append(panel);
}

// --- Submit --------------------------------------------------------------------------------------

function selectKind(next) {
  kind = next;
  for (const button of $('kind-tabs').children) {
    button.setAttribute('aria-selected', String(button.dataset.kind === kind));
  }
  $('form-error').hidden = true;
  $('form-status').textContent = '';
  try {
    renderForm(kind, $('job-fields'), description);
    $('job-submit').disabled = false;
  } catch (e) {
    $('job-fields').replaceChildren();
    $('job-submit').disabled = true;
    $('form-error').textContent = String(e.message ?? e);
    $('form-error').hidden = false;
  }
}

async function submit(event) {
  event.preventDefault();
  const error = $('form-error');
  error.hidden = true;
  $('form-status').textContent = 'submitting...';
  try {
    const body = readForm(kind, $('job-fields'));
    const operation = await api.call(description.kinds.get(kind).route, {method: 'POST', body});
    requests[operation.name] = {kind, request: body.request};
    sessionStorage.setItem(REQUESTS_KEY, JSON.stringify(requests));
    $('form-status').textContent = `submitted ${shortName(operation.name)}`;
    pendingPlot = operation.name;
    const job = jobs.get(operation.name) ?? {};
    job.operation = operation;
    jobs.set(operation.name, job);
    renderJobs();
    if (metadataOf(operation).state === 'SUCCEEDED') {
      pendingPlot = null;
      await showResult(operation.name);
    } else {
      // Followed whatever the other streams: its plot appears when it succeeds.
      follow(job);
    }
  } catch (e) {
    // INVALID_ARGUMENT names the field at fault: shown next to the form.
    error.textContent = e instanceof api.ApiError ? e.describe() : String(e);
    error.hidden = false;
    $('form-status').textContent = '';
  }
}

// --- Start ---------------------------------------------------------------------------------------

async function start() {
  $('token').value = api.token();
  $('job-submit').disabled = true;
  plots.clearPlot($('plot'));
  try {
    description = await api.loadDescription();
  } catch (error) {
    // No made-up routes: without the document the page cannot submit.
    showApiError(error);
    $('form-error').textContent = 'The API description (/openapi.json) did not load: ' +
      'nothing can be submitted. Reload the page when the server answers.';
    $('form-error').hidden = false;
    return;
  }
  for (const name of description.kinds.keys()) {
    const button = document.createElement('button');
    button.type = 'button';
    button.role = 'tab';
    button.dataset.kind = name;
    button.textContent = name;
    button.addEventListener('click', () => selectKind(name));
    $('kind-tabs').append(button);
  }
  selectKind(description.kinds.has(kind) ? kind : description.kinds.keys().next().value);
  $('job-form').addEventListener('submit', submit);
  $('jobs-refresh').addEventListener('click', refreshJobs);
  $('token-form').addEventListener('submit', (event) => {
    event.preventDefault();
    api.setToken($('token').value.trim());
    for (const job of jobs.values()) {
      job.watch?.abort();
      job.watch = null;
    }
    refreshJobs();
  });
  refreshJobs();
}

start();
