// The dashboard as a watcher sees it, in headless Debian Chromium driven by playwright-core.
//
//   node web/tests/watcher.e2e.mjs <dashboard URL> <screenshot.png>
//
// The server runs with a token; the page is opened without one, so its websocket is watch-only and its
// `hello` carries only the watcher's view of the configuration (web/PROTOCOL.md, "What a watcher sees").
// The page must still say which robot and tick period it shows, draw every chart from live ticks, show
// the watch-only banner, and a disabled E-STOP that says it needs the operator's token; an e-stop sent anyway
// is refused by the server (the tick stream shows nothing latched). Saves a screenshot, prints a JSON summary, exits non-zero on any failure.

import { harness, launch, openDashboard, patient } from './browser.mjs';

const { screenshot, url, fail, until } = harness('watcher.e2e');
const browser = await launch(fail);
const summary = {};
try {
  const { page, problems, ticks, acks } = await openDashboard(browser, url);

  await page.waitForFunction(() => window.pavlov && window.pavlov.ticks >= 60, null, { timeout: patient(20000) });
  await page.waitForSelector('#watch-banner:not([hidden])', { timeout: patient(3000) });
  const name = await page.locator('#robot-name').textContent();
  if (!name.includes('create1') || !name.includes('20 ms ticks')) fail(`robot shown as "${name}"`);
  summary.robot_name = name;
  const stallsLabel = await page.locator('#c-stalls-label').textContent();
  if (stallsLabel !== 'Stall events') fail(`stall counter labelled "${stallsLabel}"`);
  // The four strip charts, and the learning view's two (value vs return, δ).
  const charts = await page.locator('.chart-card:not(.learn-card):not(.horde-card) .uplot').count();
  if (charts !== 4) fail(`expected 4 strip charts, found ${charts}`);
  const learningCharts = await page.locator('#learn-card .uplot').count();
  if (learningCharts !== 2) fail(`expected the learning view's 2 charts, found ${learningCharts}`);
  const before = await page.evaluate(() => window.pavlov.charts.map((c) => c.u.data[0].length));
  await page.waitForTimeout(600);
  const after = await page.evaluate(() => window.pavlov.charts.map((c) => c.u.data[0].length));
  if (!after.every((n, i) => n > before[i])) fail(`charts did not update: ${before} → ${after}`);
  summary.chart_points = after;
  const conn = await page.locator('#conn').textContent();
  if (!conn.includes('watch-only')) fail(`connection shown as "${conn}"`);

  // A watcher's E-STOP is disabled and says why; an e-stop sent anyway (by the page's own socket) is refused
  // by the server, and nothing is latched.
  const estop = await page.evaluate(() => ({
    disabled: document.getElementById('estop').disabled, text: document.getElementById('estop').textContent,
  }));
  if (!estop.disabled || !estop.text.includes("needs the operator's token")) fail(`a watcher's E-STOP: ${JSON.stringify(estop)}`);
  const from = ticks.length;
  await page.evaluate(() => window.pavlov.ws.send(JSON.stringify({ cmd: 'estop', id: 9999 })));
  await until('the refusal of the e-stop', () => acks.some((a) => a.type === 'error' && a.code === 'unauthorized'), 5000);
  await page.waitForTimeout(300);
  if (ticks.slice(from).some((t) => t.estop)) fail('a watcher latched the e-stop');
  summary.estop_refused = true;
  await page.screenshot({ path: screenshot, fullPage: true });
  if (problems.length) fail(problems.join('; '));
  summary.ok = true;
  console.log(JSON.stringify(summary));
} catch (e) {
  fail(e && e.stack ? e.stack : String(e));
} finally {
  await browser.close();
}
