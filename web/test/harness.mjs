// What the browser tests (dashboard.test.mjs) and scripts/screenshots.sh share: a drillbif-server
// child process on free ports of 127.0.0.1 with a temporary store and a token, and headless
// Chromium driven by puppeteer-core (npm, installed by the build's `npm ci` in build/web/).
//
// Environment:
//   DRILLBIF_SERVER_BINARY  the drillbif-server executable (required)
//   DRILLBIF_WEB_MODULES    the directory holding node_modules/puppeteer-core (build/web)
//   CHROMIUM                the browser (default /usr/bin/chromium, Debian's package)
import {spawn} from 'node:child_process';
import {createRequire} from 'node:module';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import {setTimeout as sleep} from 'node:timers/promises';

/** The token the test servers require (8 to 512 printable characters: server/tokens.h). */
export const TOKEN = 'dashboard-test-token';

function required(name) {
  const value = process.env[name];
  if (!value) throw new Error(`${name} is not set (tests/web: see web/test/harness.mjs)`);
  return value;
}

/** A drillbif-server process; stop() ends it and removes its directory. */
export class Server {
  static async start({workers = 2, extraFlags = []} = {}) {
    const binary = path.resolve(required('DRILLBIF_SERVER_BINARY'));
    const dir = fs.mkdtempSync(path.join(os.tmpdir(), 'drillbif-dashboard-'));
    const portFile = path.join(dir, 'ports');
    const log = fs.openSync(path.join(dir, 'server.log'), 'a');
    const child = spawn(binary, [
      '--host', '127.0.0.1', '--grpc-port', '0', '--http-port', '0', '--port-file', portFile,
      '--db', path.join(dir, 'jobs.db'), '--token', TOKEN, '--workers', String(workers),
      ...extraFlags,
    ], {stdio: ['ignore', log, log]});
    const server = new Server(child, dir);
    // Serving once the port file is written (ports: gRPC, then HTTP).
    for (let i = 0; i < 200; ++i) {
      if (child.exitCode !== null) break;
      if (fs.existsSync(portFile)) {
        const [, http] = fs.readFileSync(portFile, 'utf8').trim().split('\n');
        server.url = `http://127.0.0.1:${http}`;
        return server;
      }
      await sleep(50);
    }
    await server.stop();
    throw new Error(`drillbif-server did not start: ${server.log()}`);
  }

  constructor(child, dir) {
    this.child = child;
    this.dir = dir;
    this.url = '';
  }

  log() {
    try {
      return fs.readFileSync(path.join(this.dir, 'server.log'), 'utf8');
    } catch {
      return '';
    }
  }

  /** Calls the API with the token: the parsed JSON answer. */
  async call(route, {method = 'GET', body} = {}) {
    const response = await fetch(this.url + route, {
      method,
      headers: {Authorization: `Bearer ${TOKEN}`, 'Content-Type': 'application/json'},
      body: body === undefined ? undefined : JSON.stringify(body),
    });
    const answer = await response.json();
    if (!response.ok) throw new Error(`${route}: ${response.status} ${JSON.stringify(answer)}`);
    return answer;
  }

  /** SIGTERM, then SIGKILL after 10 s; removes the directory. */
  async stop() {
    if (this.child.exitCode === null && this.child.signalCode === null) {
      const exited = new Promise((resolve) => this.child.once('exit', resolve));
      this.child.kill('SIGTERM');
      const timer = setTimeout(() => this.child.kill('SIGKILL'), 10000);
      await exited;
      clearTimeout(timer);
    }
    fs.rmSync(this.dir, {recursive: true, force: true});
  }
}

/** Headless Chromium (puppeteer-core); root needs --no-sandbox. */
export async function launchBrowser() {
  const require = createRequire(path.resolve(required('DRILLBIF_WEB_MODULES'), 'package.json'));
  const puppeteer = require('puppeteer-core');
  const executablePath = process.env.CHROMIUM || '/usr/bin/chromium';
  if (!fs.existsSync(executablePath)) {
    throw new Error(`${executablePath}: no Chromium (the Debian package chromium: scripts/setup.sh)`);
  }
  return puppeteer.launch({
    executablePath,
    headless: true,  // Chromium's new headless mode (--headless=new)
    args: ['--no-sandbox', '--disable-gpu', '--disable-dev-shm-usage'],
    defaultViewport: {width: 1400, height: 1000},
  });
}

/**
 * Records what a page reports: console errors and warnings, uncaught exceptions, failed
 * requests. `messages` is the list, as "type: text".
 */
export function recordProblems(page) {
  const messages = [];
  page.on('console', (message) => {
    if (message.type() === 'error' || message.type() === 'warn') {
      messages.push(`${message.type()}: ${message.text()}`);
    }
  });
  page.on('pageerror', (error) => messages.push(`pageerror: ${error.message}`));
  page.on('requestfailed', (request) => {
    // A stream the page aborts itself (a watch it stops following) is not a failure.
    if (request.failure()?.errorText !== 'net::ERR_ABORTED') {
      messages.push(`requestfailed: ${request.url()} ${request.failure()?.errorText}`);
    }
  });
  return messages;
}

/**
 * Opens the dashboard with `token` in the tab's sessionStorage (none: no token). `requests`
 * lists every request the page made, from the start ({method, path, body}). With `openapi`
 * ({status, body}), the page's GET /openapi.json is answered with it instead of the server's.
 */
export async function openDashboard(browser, url, token, {openapi} = {}) {
  const context = await browser.createBrowserContext();
  const page = await context.newPage();
  const problems = recordProblems(page);
  const requests = [];
  page.on('request', (request) => {
    const {pathname, search} = new URL(request.url());
    requests.push({method: request.method(), path: pathname + search, body: request.postData()});
  });
  if (openapi) {
    await page.setRequestInterception(true);
    page.on('request', (request) => {
      if (new URL(request.url()).pathname === '/openapi.json') {
        request.respond({status: openapi.status, contentType: 'application/json',
          body: openapi.body});
      } else {
        request.continue();
      }
    });
  }
  if (token) {
    await page.evaluateOnNewDocument((t) => sessionStorage.setItem('drillbif.token', t), token);
  }
  const response = await page.goto(`${url}/`, {waitUntil: 'networkidle0'});
  return {context, page, problems, requests, response};
}

/** Submits the form of `kind` with `values` (field path -> value) typed over its defaults. */
export async function submitForm(page, kind, values = {}) {
  await page.click(`#kind-tabs button[data-kind="${kind}"]`);
  for (const [name, value] of Object.entries(values)) {
    await page.$eval(`[name="${name}"]`, (input, v) => {
      input.value = v;
    }, String(value));
  }
  await page.click('#job-submit');
}

/**
 * What the chart on display holds (Chart.getChart on the plot's canvas): per dataset its label,
 * number of points, dash, first point, and how many of its points were laid out at finite pixels
 * inside the chart area and not skipped (what was drawn).
 */
export async function chartContents(page) {
  return page.evaluate(() => {
    const canvas = document.querySelector('#plot canvas');
    const chart = globalThis.Chart.getChart(canvas);
    if (!chart) return null;
    const area = chart.chartArea;
    return {
      kind: document.querySelector('#plot').dataset.kind,
      width: canvas.width,
      height: canvas.height,
      datasets: chart.data.datasets.map((dataset, i) => ({
        label: dataset.label,
        points: dataset.data.length,
        dashed: (dataset.borderDash ?? []).length > 0,
        first: dataset.data[0] ? {x: dataset.data[0].x, y: dataset.data[0].y} : null,
        // A point whose value is null (a gap in its line) is laid out but marked skip.
        drawn: chart.getDatasetMeta(i).data.filter((e) => !e.skip && Number.isFinite(e.x) &&
            Number.isFinite(e.y) && e.x >= area.left - 1 && e.x <= area.right + 1 &&
            e.y >= area.top - 1 && e.y <= area.bottom + 1).length,
      })),
    };
  });
}
