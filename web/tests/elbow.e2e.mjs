// The gesture experiment's panel in headless Debian Chromium, driven by playwright-core.
//
//   PAVLOV_BIN=… SKELETON_TO=127.0.0.1:PORT node web/tests/elbow.e2e.mjs <dashboard URL> <screenshot.png>
//
// The server runs config/interaction.toml with its skeleton port at SKELETON_TO and nobody sending. The page
// must show the elbow chart, the skeleton status "none" and, after a second, the no-skeleton warning. Then
// this script starts the simulated operator (`pavlov human --to SKELETON_TO`): the status turns "tracked",
// the warning goes, both elbow angles and their averages fill the chart, and the debounced command count
// rises with the operator's commands (never above the raw stimulus onsets in the tick stream). Saves a
// screenshot, prints a JSON summary, exits non-zero on any failure.

import { spawn } from 'node:child_process';

import { harness, launch, openDashboard, patient } from './browser.mjs';

const { screenshot, url, fail, until } = harness('elbow.e2e');
const bin = process.env.PAVLOV_BIN;
const to = process.env.SKELETON_TO;
if (!bin || !to) fail('PAVLOV_BIN and SKELETON_TO must be set');
const browser = await launch(fail);
const summary = {};
let human = null;
try {
  const { page, problems, ticks } = await openDashboard(browser, url);

  // No skeleton yet: the chart is there, the status says none, and after a second the banner warns.
  await page.waitForSelector('#elbow-card:not([hidden])', { timeout: patient(15000) });
  if ((await page.locator('#chart-elbow .uplot').count()) !== 1) fail('no elbow chart');
  await page.waitForFunction(() => document.getElementById('now-skeleton').textContent === 'none', null, { timeout: patient(5000) });
  await page.waitForSelector('#skeleton-banner:not([hidden])', { timeout: patient(5000) });
  const warning = await page.locator('#skeleton-banner').textContent();
  if (!warning.includes('No skeleton')) fail(`banner says "${warning}"`);
  summary.warned_without_skeleton = true;
  await page.screenshot({ path: screenshot.replace(/\.png$/, '-none.png'), fullPage: true });

  // The operator starts: tracked, no warning, angles in the chart.
  human = spawn(bin, ['human', '--to', to, '--seed', '3'], { stdio: ['ignore', 'ignore', 'pipe'] });
  human.on('exit', (code) => { if (code !== null && code !== 0) fail(`pavlov human exited with ${code}`); });
  await page.waitForFunction(() => document.getElementById('now-skeleton').textContent === 'tracked', null, { timeout: patient(10000) });
  await page.waitForFunction(() => document.getElementById('skeleton-banner').hidden, null, { timeout: patient(5000) });
  await page.waitForFunction(() => {
    const d = window.pavlov.elbow.data();
    if (!d) return false;
    const seen = (k) => d[k].filter((v) => v !== null).length;
    return seen(1) > 20 && seen(2) > 20 && seen(3) > 20 && seen(4) > 20;
  }, null, { timeout: patient(10000) });
  summary.elbow_points = await page.evaluate(() => window.pavlov.elbow.data().slice(1).map((c) => c.filter((v) => v !== null).length));

  // Commands: the page's debounced count rises, and never exceeds the raw rising edges of the stimulus.
  const count = async () => Number((await page.locator('#i-commands').textContent()).split(' ')[0].replace(/,/g, '')) || 0;
  const start = Date.now();
  while ((await count()) < 2) {
    if (Date.now() - start > 45000) fail('fewer than 2 commands counted in 45 s of gestures');
    await page.waitForTimeout(250);
  }
  let edges = 0;
  for (let k = 1; k < ticks.length; k++) if (ticks[k].stimulus && !ticks[k - 1].stimulus) edges += 1;
  const debounced = await count();
  if (debounced > edges) fail(`${debounced} debounced commands but only ${edges} stimulus onsets`);
  summary.commands = { debounced, raw_stimulus_onsets: edges };
  // Let a command show in the chart, then take the picture.
  await until('a tick with the left elbow below 90°', () => ticks.slice(-100).some((t) => t.elbow && t.elbow.left !== null && t.elbow.left < 90), 20000);
  await page.waitForTimeout(1500);
  await page.screenshot({ path: screenshot, fullPage: true });
  if (problems.length) fail(problems.join('; '));
  summary.ok = true;
  console.log(JSON.stringify(summary));
} catch (e) {
  fail(e && e.stack ? e.stack : String(e));
} finally {
  if (human) human.kill('SIGTERM');
  await browser.close();
}
