// Browser tests of the dashboard (web/src/) served by a real drillbif-server: headless Chromium
// loads the page, submits jobs from its forms and checks the plots, an optimum map's plot and
// query panel, the job list's live progress, cancel, the errors a missing token or a bad field
// gives, and that the kinds and submit routes come from the server's /openapi.json.
//
//   DRILLBIF_SERVER_BINARY=build/server/drillbif-server DRILLBIF_WEB_MODULES=build/web \
//     node web/test/dashboard.test.mjs
//
// Registered with CTest as dashboard_browser_test (web/CMakeLists.txt). The jobs are small
// (the trace box omega in [0.05, 0.2], a in [0.27, 0.32] takes well under a second; the optimum
// map of 5 cells a few seconds).
import assert from 'node:assert/strict';
import {after, before, test} from 'node:test';

import {chartContents, launchBrowser, openDashboard, Server, submitForm, TOKEN} from './harness.mjs';

// How long a small job may take from submit to plot on a loaded 2-core machine: the jobs take
// at most a few seconds alone (the optimum map's 5 cells the longest, 2 to 4 s), so 30 s only
// bounds a hang.
const JOB_TIMEOUT_MS = 30000;

let server;
let browser;
let session;  // the page with the token, shared by the tests in order
let traceName;  // the trace the form submitted

before(async () => {
  server = await Server.start();
  browser = await launchBrowser();
  session = await openDashboard(browser, server.url, TOKEN);
});

after(async () => {
  await browser?.close();
  await server?.stop();
});

// The operation the form submitted last (the status line names its id's first 8 digits; the
// page sets it to "submitting..." when the submit starts, so an earlier submit's line is never
// read).
async function submittedOperation(page) {
  await page.waitForFunction(
      () => /submitted [0-9a-f]{8}/.test(document.querySelector('#form-status').textContent),
      {timeout: JOB_TIMEOUT_MS});
  const prefix = (await page.$eval('#form-status', (e) => e.textContent)).split(' ').at(-1);
  const {operations} = await server.call('/v1/operations?page_size=1000');
  const found = operations.filter((o) => o.name.startsWith(`operations/${prefix}`));
  assert.equal(found.length, 1, `one operation starts with ${prefix}`);
  return found[0].name;
}

async function waitForPlot(page, kind) {
  await page.waitForFunction((k) => {
    const plot = document.querySelector('#plot');
    return plot.dataset.kind === k && Number(plot.dataset.series) > 0;
  }, {timeout: JOB_TIMEOUT_MS}, kind);
  return chartContents(page);
}

test('the page and its files are served with the CSP, without a token', async () => {
  const {response, page} = session;
  assert.equal(response.status(), 200);
  assert.match(response.headers()['content-type'], /^text\/html/);
  assert.match(response.headers()['content-security-policy'], /default-src 'self'/);
  assert.equal(await page.title(), 'drillbif dashboard');
  // Chart.js came from the server (the page has no other source) and defined its global.
  assert.equal(await page.evaluate(() => typeof globalThis.Chart), 'function');
  const library = await fetch(`${server.url}/vendor/chart.umd.min.js`);
  assert.equal(library.status, 200);
  assert.match(library.headers.get('content-type'), /^text\/javascript/);
});

test('with the token the job list loads without an error', async () => {
  const {page, problems} = session;
  assert.equal(await page.$eval('#api-error', (e) => e.hidden), true);
  assert.deepEqual(problems, []);
});

test('a trace submitted from the form completes and its curves are plotted', async () => {
  const {page} = session;
  await submitForm(page, 'trace');
  const name = await submittedOperation(page);
  traceName = name;
  const chart = await waitForPlot(page, 'trace');
  const {trace} = await server.call(`/v1/${name}:result`);
  assert.ok(trace.curves.length > 0, 'the small box has curves');
  // One polyline per curve, then the codimension-2 markers when there are any.
  const codim2 = trace.codim2Points?.length ?? 0;
  assert.equal(chart.datasets.length, trace.curves.length + (codim2 > 0 ? 1 : 0));
  trace.curves.forEach((curve, i) => {
    assert.equal(chart.datasets[i].points, curve.points.length, `curve ${i}`);
    assert.equal(chart.datasets[i].drawn, curve.points.length, `curve ${i} laid out`);
  });
  if (codim2 > 0) assert.equal(chart.datasets.at(-1).points, codim2);
  assert.ok(chart.width > 0 && chart.height > 0);
});

test('a continuation submitted from the form is plotted with its stability and special points',
    async () => {
      const {page} = session;
      await submitForm(page, 'continue');
      const name = await submittedOperation(page);
      const chart = await waitForPlot(page, 'continue');
      const result = (await server.call(`/v1/${name}:result`)).continue;
      const branch = chart.datasets.filter((d) => d.label.startsWith('branch,'));
      const specials = chart.datasets.filter((d) => d.label === 'branch: special points');
      // Runs of equal stability share their end points: one more point per run after the first.
      const drawn = branch.reduce((n, d) => n + d.points, 0) - (branch.length - 1);
      assert.equal(drawn, result.points.length);
      assert.ok(branch.every((d) => d.drawn === d.points));
      // Unstable runs are dashed, stable ones solid.
      for (const d of branch) assert.equal(d.dashed, d.label.endsWith('unstable'), d.label);
      const unstable = result.points.some((p) => !p.stable);
      assert.equal(branch.some((d) => d.dashed), unstable);
      assert.equal(specials.length, 1);
      assert.equal(specials[0].points, result.specialPoints.length);
      assert.ok(result.specialPoints.length > 0, 'the default box has special points to mark');
    });

test('an optimum of the traced box is drawn with its margin over the trace\'s curves',
    async () => {
      const {page} = session;
      // The optimum form's box is the trace form's: the trace submitted above gives the curves.
      await submitForm(page, 'optimum');
      const name = await submittedOperation(page);
      const chart = await waitForPlot(page, 'optimum');
      const {optimum} = await server.call(`/v1/${name}:result`);
      assert.equal(optimum.status, 'COMPLETED');
      const marker = chart.datasets.find((d) => d.label === 'optimum');
      assert.equal(marker.points, 1);
      assert.deepEqual(marker.first, {x: optimum.params.omega, y: optimum.params.a});
      assert.equal(chart.datasets.find((d) => d.label === 'margin').points, 5);  // closed
      const curves = chart.datasets.filter((d) => /^(FOLD|PERIOD_DOUBLING|GRAZING)/.test(d.label));
      assert.equal(curves.length, optimum.curves);
    });

// The whole result of `name` (every page of :result), as this test reads it itself.
async function wholeResult(name) {
  let result = null;
  let pageToken = '';
  do {
    const page = await server.call(`/v1/${name}:result?page_size=1${pageToken ?
      `&page_token=${encodeURIComponent(pageToken)}` : ''}`);
    if (result === null) {
      result = page.optimumMap;
    } else {
      result.cells.push(...page.optimumMap.cells);
    }
    pageToken = page.nextPageToken ?? '';
  } while (pageToken);
  return result;
}

// The map the form submitted and its request, for the query test below.
let mapName;
let mapRequest;

test('an optimum map submitted from the form completes and its plot has one point per cell',
    async () => {
      const {page, requests} = session;
      const started = Date.now();
      await submitForm(page, 'optimum-map');
      mapName = await submittedOperation(page);
      const chart = await waitForPlot(page, 'optimum-map');
      console.log(`# optimum map: ${Date.now() - started} ms from submit to plot`);
      mapRequest = JSON.parse(requests.findLast((r) => r.method === 'POST' &&
        r.path === '/v1/jobs:optimum-map').body).request;
      // Paged one cell at a time: the page must follow next_page_token to get every cell.
      const map = await wholeResult(mapName);
      assert.equal(map.status, 'COMPLETED');
      assert.deepEqual(map.over, ['b']);
      assert.equal(map.cells.length, 5);
      const cells = [...map.cells].sort((p, q) => p.index[0] - q.index[0]);
      const found = cells.filter((c) => c.optimum.status === 'COMPLETED');
      assert.ok(found.length >= 1, 'the small box has an optimum at some b');
      const rop = chart.datasets.find((d) => d.label === 'ROP');
      // One point per cell in b order; a cell without an optimum is a gap (not laid out).
      assert.equal(rop.points, cells.length);
      assert.equal(rop.drawn, found.length);
      const drawnRop = await page.evaluate(() => globalThis.Chart.getChart(
          document.querySelector('#plot canvas')).data.datasets[0].data);
      assert.deepEqual(drawnRop, cells.map((c) => ({x: c.condition[0],
        y: c.optimum.status === 'COMPLETED' ? c.optimum.rop : null})));
      for (const param of ['omega', 'a']) {
        const series = chart.datasets.find((d) => d.label === `${param} at the optimum`);
        assert.equal(series.drawn, found.length, param);
      }
      const missing = chart.datasets.find((d) => d.label === 'optimum not found / failed');
      assert.equal(missing?.points ?? 0, cells.length - found.length);
    });

test('a query between two cells shows the verified answer QueryOptimum gives and marks it',
    async () => {
      const {page, requests} = session;
      assert.ok(mapName, 'the map test ran first');
      // Halfway between the cells at b = 0.145 and 0.15 (the panel's own default is between
      // the first two): the answer is interpolated from neighbours, not a cell's own.
      const b = 0.1475;
      await page.$eval('#map-query-value-0', (input, v) => {
        input.value = v;
        input.dispatchEvent(new Event('input'));
      }, String(b));
      assert.equal(Number(await page.$eval('#map-query-slider-0', (e) => e.value)), b);
      await page.click('#map-query-button');
      await page.waitForSelector('#map-answer-rop', {timeout: JOB_TIMEOUT_MS});
      // The same query made here: the map's optimum request with b set.
      const optimum = structuredClone(mapRequest.optimum);
      optimum.trace.params.b = b;
      const sent = JSON.parse(requests.findLast((r) => r.method === 'POST' &&
        r.path === '/v1/optimum:query').body);
      assert.deepEqual(sent, {request: optimum});
      const answer = await server.call('/v1/optimum:query', {method: 'POST',
        body: {request: optimum}});
      assert.equal(answer.operation, mapName);
      assert.equal(answer.fromMap.verified, true, answer.fromMap.verification);
      const text = async (id) => page.$eval(`#${id}`, (e) => e.textContent);
      assert.equal(await text('map-answer-verified'), 'yes');
      assert.equal(await text('map-answer-verification'), answer.fromMap.verification);
      assert.equal(await text('map-answer-rop'), answer.optimum.rop.toPrecision(6));
      assert.match(await text('map-answer-params'),
          new RegExp(`omega = ${answer.optimum.params.omega.toPrecision(6)}.*` +
          `a = ${answer.optimum.params.a.toPrecision(6)}|a = ${answer.optimum.params.a
              .toPrecision(6)}.*omega = ${answer.optimum.params.omega.toPrecision(6)}`));
      const cellsText = await text('map-answer-cells');
      assert.equal(cellsText.split('; ').length, answer.fromMap.cells.length);
      for (const cell of answer.fromMap.cells) assert.ok(cellsText.includes(`[${cell.index[0]}]`));
      const chart = await chartContents(page);
      const marker = chart.datasets.find((d) => d.label === 'query (ROP)');
      assert.deepEqual(marker.first, {x: b, y: answer.optimum.rop});
      assert.equal(marker.drawn, 1);
    });

test('a map opened in another tab can be queried: its result repeats its optimum request',
    async () => {
      assert.ok(mapName, 'the map test ran first');
      const map = await wholeResult(mapName);
      assert.deepEqual(map.optimum.margin, mapRequest.optimum.margin);
      assert.deepEqual(map.optimum.trace.min, mapRequest.optimum.trace.min);
      const other = await openDashboard(browser, server.url, TOKEN);
      try {
        const row = `#jobs-body tr[data-name="${mapName}"]`;
        await other.page.waitForSelector(`${row} .plot-button`, {timeout: JOB_TIMEOUT_MS});
        await other.page.click(`${row} .plot-button`);
        await other.page.waitForSelector('#map-query-button', {timeout: JOB_TIMEOUT_MS});
        await other.page.click('#map-query-button');
        await other.page.waitForSelector('#map-answer-rop', {timeout: JOB_TIMEOUT_MS});
        assert.equal(await other.page.$eval('#map-answer-verified', (e) => e.textContent), 'yes');
      } finally {
        await other.context.close();
      }
    });

test('map cells without an optimum are gaps and crosses; two conditions give one square per cell',
    async () => {
      const {page} = session;
      // The map above, drawn again by plots.js with its third cell made NOT_FOUND and its
      // fourth FAILED: what a map of a harder box gives, without computing one.
      const map = await wholeResult(mapName);
      const cells = [...map.cells].sort((p, q) => p.index[0] - q.index[0]);
      cells[2].optimum.status = 'NOT_FOUND';
      cells[3].optimum.status = 'FAILED';
      const draw = (result) => page.evaluate(async (r, request) => {
        const plots = await import('/plots.js');
        plots.plotOptimumMap(document.querySelector('#plot'), r, request, null);
      }, result, mapRequest);
      await draw({...map, cells});
      let chart = await chartContents(page);
      assert.equal(chart.datasets.find((d) => d.label === 'ROP').drawn, 3);
      const missing = chart.datasets.find((d) => d.label === 'optimum not found / failed');
      assert.equal(missing.points, 2);
      assert.equal(missing.drawn, 2);
      assert.equal(missing.first.x, cells[2].condition[0]);
      // Two conditions (b and a made-up second one): a square per found cell, a cross per other.
      const twoD = cells.map((c, k) => ({...c, index: [k % 3, Math.floor(k / 3)],
        condition: [c.condition[0], 0.04 + 0.01 * Math.floor(k / 3)]}));
      await draw({...map, over: ['b', 'xi'], from: [0.14, 0.04], to: [0.16, 0.05], steps: [3, 2],
        cells: twoD});
      chart = await chartContents(page);
      assert.equal(chart.datasets[0].drawn, 3);
      assert.deepEqual(chart.datasets[0].first, {x: twoD[0].condition[0], y: 0.04});
      assert.equal(chart.datasets[1].drawn, 2);
      // The map's own plot again (the tests after this one plot other kinds).
      await draw(map);
    });

test('a simulation\'s trajectory and a sweep\'s samples are plotted', async () => {
  const {page} = session;
  await submitForm(page, 'simulate');
  let name = await submittedOperation(page);
  let chart = await waitForPlot(page, 'simulate');
  const {simulate} = await server.call(`/v1/${name}:result`);
  assert.ok(simulate.trajectory.length > 100);
  assert.deepEqual(chart.datasets.map((d) => d.points),
      [simulate.trajectory.length, simulate.trajectory.length]);

  await submitForm(page, 'sweep');
  name = await submittedOperation(page);
  chart = await waitForPlot(page, 'sweep');
  const {sweep} = await server.call(`/v1/${name}:result`);
  const samples = (points) => points.reduce((n, p) => n + (p.samples?.length ?? 0), 0);
  assert.ok(samples(sweep.up) > 0 && samples(sweep.down) > 0);
  assert.deepEqual(chart.datasets.map((d) => [d.label, d.points, d.drawn]),
      [['up', samples(sweep.up), samples(sweep.up)],
        ['down', samples(sweep.down), samples(sweep.down)]]);
});

test('a field outside its domain shows the server\'s INVALID_ARGUMENT beside the form',
    async () => {
      const {page} = session;
      // max < min: the server names the bounds.
      await submitForm(page, 'continue', {'request.min': 0.5, 'request.max': 0.4});
      await page.waitForFunction(() => !document.querySelector('#form-error').hidden,
          {timeout: JOB_TIMEOUT_MS});
      const text = await page.$eval('#form-error', (e) => e.textContent);
      assert.match(text, /^400 INVALID_ARGUMENT: .*max/);
    });

test('a running job\'s progress follows its watch stream, and Cancel cancels it', async () => {
  const {page} = session;
  // A sweep of 20000 values: minutes alone, so it is running when cancelled.
  await submitForm(page, 'sweep', {'request.steps': 20000, 'request.direction': 'UP'});
  const name = await submittedOperation(page);
  const row = `#jobs-body tr[data-name="${name}"]`;
  // Progress above 0 reaches the row only through the :watch stream (the list is not reloaded).
  await page.waitForFunction((selector) => {
    const progress = document.querySelector(`${selector} progress`);
    return progress && progress.value > 0;
  }, {timeout: JOB_TIMEOUT_MS}, row);
  await page.click(`${row} .cancel-button`);
  await page.waitForFunction((selector) =>
    document.querySelector(selector)?.dataset.state === 'CANCELLED',
  {timeout: JOB_TIMEOUT_MS}, row);
  const operation = await server.call(`/v1/${name}`);
  assert.equal(operation.metadata.state, 'CANCELLED');
});

test('with more live jobs than streams the page still answers, and the list catches up',
    async () => {
      const {page} = session;
      // Watch streams open now (each holds one of Chromium's 6 connections to the server).
      const open = new Set();
      const track = (request) => request.url().endsWith(':watch') && open.add(request);
      const untrack = (request) => open.delete(request);
      page.on('request', track);
      page.on('requestfinished', untrack);
      page.on('requestfailed', untrack);
      let mostOpen = 0;
      const sample = setInterval(() => {
        mostOpen = Math.max(mostOpen, open.size);
      }, 20);
      // 8 long sweeps from another client: 2 run (2 workers), 6 queue.
      const sweep = {request: {param: 'b', min: 0, max: 0.2, steps: 100000, samplePeriods: 1}};
      const names = [];
      for (let i = 0; i < 8; ++i) {
        sweep.requestId = `dashboard-live-${i}`;
        names.push((await server.call('/v1/jobs:sweep', {method: 'POST', body: sweep})).name);
      }
      await page.click('#jobs-refresh');
      await page.waitForFunction((n) => n.every((name) =>
        document.querySelector(`#jobs-body tr[data-name="${name}"]`)), {timeout: JOB_TIMEOUT_MS},
      names);
      // Calls still get a connection: the trace's result is fetched and plotted again.
      await page.click(`#jobs-body tr[data-name="${traceName}"] .plot-button`);
      await waitForPlot(page, 'trace');
      for (const name of names) await server.call(`/v1/${name}:cancel`, {method: 'POST', body: {}});
      // Every row reaches its final state: from its stream, or from a stream opened as another
      // ends, or from the list's periodic reload.
      await page.waitForFunction((n) => n.every((name) => document.querySelector(
          `#jobs-body tr[data-name="${name}"]`)?.dataset.state === 'CANCELLED'),
      {timeout: JOB_TIMEOUT_MS}, names);
      clearInterval(sample);
      page.off('request', track);
      page.off('requestfinished', untrack);
      page.off('requestfailed', untrack);
      // At most 3 streams (MAX_WATCHES in app.js); at least one: the running ones are followed.
      console.log(`# at most ${mostOpen} watch streams open at once`);
      assert.ok(mostOpen >= 1 && mostOpen <= 3, `${mostOpen} watch streams at once`);
    });

// The kinds the document lists: its Submit* operations, "SubmitOptimumMap" -> "optimum-map".
async function documentKinds() {
  const document = await (await fetch(`${server.url}/openapi.json`)).json();
  const kinds = new Map();
  for (const [path, item] of Object.entries(document.paths)) {
    const id = item.post?.operationId ?? '';
    if (id.startsWith('Submit')) {
      kinds.set(id.slice(6).replace(/(?<!^)([A-Z])/g, '-$1').toLowerCase(), path);
    }
  }
  return {document, kinds};
}

test('the page read /openapi.json and every submit went to its Submit operation\'s path',
    async () => {
      const {page, requests} = session;
      assert.ok(requests.some((r) => r.method === 'GET' && r.path === '/openapi.json'));
      const {kinds} = await documentKinds();
      assert.ok(kinds.size >= 6, 'simulate, sweep, continue, trace, optimum, optimum-map');
      const tabs = await page.$$eval('#kind-tabs button', (buttons) =>
        buttons.map((b) => b.dataset.kind));
      assert.deepEqual(tabs, [...kinds.keys()]);
      const submits = requests.filter((r) => r.method === 'POST' && r.path.startsWith('/v1/jobs'));
      assert.ok(submits.length >= 6);
      const routes = new Set(kinds.values());
      for (const r of submits) assert.ok(routes.has(r.path), r.path);
    });

test('the submit route is the document\'s: a trace goes where /openapi.json says', async () => {
  // The server's document with SubmitTrace moved to a path the server does not serve: the page
  // posts there (and shows the 404), so the route cannot be built in.
  const {document} = await documentKinds();
  document.paths['/v1/jobs:trace-moved'] = document.paths['/v1/jobs:trace'];
  delete document.paths['/v1/jobs:trace'];
  const {page, requests, context} = await openDashboard(browser, server.url, TOKEN,
      {openapi: {status: 200, body: JSON.stringify(document)}});
  await submitForm(page, 'trace');
  await page.waitForFunction(() => !document.querySelector('#form-error').hidden,
      {timeout: JOB_TIMEOUT_MS});
  assert.match(await page.$eval('#form-error', (e) => e.textContent), /^404 NOT_FOUND/);
  const posts = requests.filter((r) => r.method === 'POST').map((r) => r.path);
  assert.deepEqual(posts, ['/v1/jobs:trace-moved']);
  await context.close();
});

test('a kind the page has no form for is submitted from a JSON box to the document\'s route',
    async () => {
      // SubmitTrace renamed: a kind "trace-by-hand" the page does not know, at /v1/jobs:trace.
      const {document} = await documentKinds();
      document.paths['/v1/jobs:trace'].post.operationId = 'SubmitTraceByHand';
      const {page, requests, context} = await openDashboard(browser, server.url, TOKEN,
          {openapi: {status: 200, body: JSON.stringify(document)}});
      const tabs = await page.$$eval('#kind-tabs button', (b) => b.map((e) => e.dataset.kind));
      assert.ok(tabs.includes('trace-by-hand') && !tabs.includes('trace'), tabs.join(' '));
      const request = {params: {a: 0.3, b: 0.15, omega: 0.1}, traceParams: ['omega', 'a'],
        min: [0.05, 0.27], max: [0.2, 0.32]};
      await submitForm(page, 'trace-by-hand', {request: JSON.stringify(request)});
      const name = await submittedOperation(page);
      assert.deepEqual(JSON.parse(requests.findLast((r) => r.method === 'POST').body),
          {request});
      assert.equal((await server.call(`/v1/${name}`)).metadata.kind, 'TRACE');
      await context.close();
    });

test('when /openapi.json fails the page says so and offers no form', async () => {
  const {page, problems, context} = await openDashboard(browser, server.url, TOKEN,
      {openapi: {status: 503, body: '{"code": "UNAVAILABLE", "message": "shutting down"}'}});
  await page.waitForFunction(() => !document.querySelector('#api-error').hidden,
      {timeout: JOB_TIMEOUT_MS});
  assert.equal(await page.$eval('#api-error', (e) => e.textContent),
      '503 UNAVAILABLE: /openapi.json: shutting down');
  assert.equal(await page.$$eval('#kind-tabs button', (b) => b.length), 0);
  assert.equal(await page.$eval('#job-submit', (e) => e.disabled), true);
  assert.match(await page.$eval('#form-error', (e) => e.textContent), /openapi\.json/);
  // Chromium logs the refused document as a failed resource; nothing else may appear.
  assert.deepEqual(problems.filter((p) => !/status of 503/.test(p)), []);
  await context.close();
});

test('the session with the token logged no console error or warning', () => {
  // Chromium logs the refused submit of the invalid field as a failed resource (400): that one,
  // and nothing else.
  const refused = session.problems.filter((p) => /status of 400 \(Bad Request\)/.test(p));
  assert.equal(refused.length, 1);
  assert.deepEqual(session.problems.filter((p) => !refused.includes(p)), []);
});

test('without the token the page shows the 401 message', async () => {
  const {page, problems, context} = await openDashboard(browser, server.url, '');
  await page.waitForFunction(() => !document.querySelector('#api-error').hidden,
      {timeout: JOB_TIMEOUT_MS});
  const text = await page.$eval('#api-error', (e) => e.textContent);
  assert.match(text, /^401 UNAUTHENTICATED: .*token/);
  // Chromium reports each refused call as a failed resource; nothing else may appear.
  const others = problems.filter((p) => !/status of 401/.test(p));
  assert.deepEqual(others, []);
  // Typing the token fixes it.
  await page.type('#token', TOKEN);
  await page.click('#token-form button');
  await page.waitForFunction(() => document.querySelector('#api-error').hidden &&
      document.querySelectorAll('#jobs-body tr').length > 0, {timeout: JOB_TIMEOUT_MS});
  await context.close();
});
