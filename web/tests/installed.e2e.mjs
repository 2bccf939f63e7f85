// The dashboard of an installed binary, in headless Debian Chromium driven by playwright-core.
//
//   node web/tests/installed.e2e.mjs <dashboard URL> <screenshot.png>
//
// Run by tests/e2e/dashboard/installed.rs against a copy of `pavlov` started from an empty directory, so
// every file the page loads comes from the binary. Checks that uPlot loaded (no missing-library banner),
// that the four strip charts are uPlot instances that grow with live ticks, and that their canvases have
// drawn pixels; saves a screenshot and prints a JSON summary (see browser.mjs for the browser).

import { harness, launch, openDashboard, patient } from './browser.mjs';

const { screenshot, url, fail } = harness('installed.e2e');
const browser = await launch(fail);
const summary = {};
try {
  const { page, problems, ticks } = await openDashboard(browser, url);
  await page.waitForFunction(() => window.pavlov && window.pavlov.ticks >= 60, null, { timeout: patient(30000) });
  summary.uplot = await page.evaluate(() => typeof window.uPlot === 'function');
  if (!summary.uplot) fail('uPlot did not load');
  if (!(await page.locator('#vendor-banner').isHidden())) fail('the page says its chart library is missing');
  const charts = await page.locator('.chart-card:not(.learn-card):not(.horde-card) .uplot').count();
  if (charts !== 4) fail(`expected 4 strip charts, found ${charts}`);
  const before = await page.evaluate(() => window.pavlov.charts.map((c) => c.u.data[0].length));
  await page.waitForTimeout(600);
  const after = await page.evaluate(() => window.pavlov.charts.map((c) => c.u.data[0].length));
  if (!after.every((n, i) => n > before[i])) fail(`charts did not update: ${before} → ${after}`);
  summary.chart_points = after;
  // Drawn pixels: on each chart's canvas, the pixels that differ from its top-left corner (the background).
  summary.drawn_pixels = await page.evaluate(() => window.pavlov.charts.map((c) => {
    const canvas = c.u.root.querySelector('canvas');
    const { width, height } = canvas;
    const px = canvas.getContext('2d').getImageData(0, 0, width, height).data;
    let drawn = 0;
    for (let i = 4; i < px.length; i += 4) {
      if (px[i] !== px[0] || px[i + 1] !== px[1] || px[i + 2] !== px[2] || px[i + 3] !== px[3]) drawn += 1;
    }
    return drawn;
  }));
  if (!summary.drawn_pixels.every((n) => n > 500)) fail(`a chart has drawn almost nothing: ${summary.drawn_pixels}`);
  summary.ticks_seen = ticks.length;
  await page.screenshot({ path: screenshot, fullPage: true });
  if (problems.length) fail(problems.join('; '));
  summary.ok = true;
  console.log(JSON.stringify(summary));
} catch (e) {
  fail(e && e.stack ? e.stack : String(e));
} finally {
  await browser.close();
}
