// Saves PNGs of the dashboard into docs/figures/dashboard-*.png (scripts/screenshots.sh): a
// server with a token, a few small jobs submitted from the page's forms, each plot captured
// (an optimum map with a query answered from its panel).
import fs from 'node:fs';
import path from 'node:path';
import {fileURLToPath} from 'node:url';

import {launchBrowser, openDashboard, Server, submitForm, TOKEN} from './harness.mjs';

const figures = path.resolve(path.dirname(fileURLToPath(import.meta.url)), '../../docs/figures');

async function plotOf(page, kind, values = {}) {
  await submitForm(page, kind, values);
  await page.waitForFunction((k) => document.querySelector('#plot').dataset.kind === k &&
      Number(document.querySelector('#plot').dataset.series) > 0, {timeout: 120000}, kind);
}

async function save(page, name, selector) {
  const file = path.join(figures, `dashboard-${name}.png`);
  if (selector) {
    await (await page.$(selector)).screenshot({path: file});
  } else {
    await page.screenshot({path: file, fullPage: true});
  }
  console.log(`saved ${path.relative(process.cwd(), file)}`);
}

const server = await Server.start();
const browser = await launchBrowser();
try {
  const {page, problems} = await openDashboard(browser, server.url, TOKEN);
  await plotOf(page, 'trace', {'request.region.grid': '41, 41'});
  await save(page, 'trace', '#result');
  await plotOf(page, 'continue');
  await save(page, 'continue', '#result');
  await plotOf(page, 'optimum');
  await save(page, 'optimum', '#result');
  // An optimum map over b, queried between two cells: the answer listed and starred.
  await plotOf(page, 'optimum-map');
  await page.click('#map-query-button');
  await page.waitForSelector('#map-answer-rop', {timeout: 60000});
  await save(page, 'map', '#result');
  await plotOf(page, 'simulate');
  await save(page, 'simulate', '#result');
  // A sweep left running in the list, then the whole page.
  await submitForm(page, 'sweep', {'request.steps': 20000, 'request.direction': 'UP'});
  await page.waitForFunction(() => [...document.querySelectorAll('#jobs-body tr')]
      .some((row) => row.dataset.state === 'RUNNING' && row.querySelector('progress').value > 0),
  {timeout: 60000});
  await save(page, 'page');
  if (problems.length) console.warn(`page problems: ${problems.join('; ')}`);
} finally {
  await browser.close();
  await server.stop();
}
