// The learning view and the Horde grid, in headless Debian Chromium driven by playwright-core.
//
//   node web/tests/learning.e2e.mjs <dashboard URL> <screenshot.png> [horde|none]
//
// Run by tests/e2e/dashboard/browser_learning.rs against `pavlov serve` with a small `[horde]` (132
// predictions: every observation dimension at three timescales), or with none. Checks: the learning view
// picks the stall prediction, draws its value and, a horizon later, the realised return at the same ticks,
// its TD error and running RMSE, and says the parameters in force (α, λ, θ, τ); with a Horde, the page asked
// for it (`horde_watch`), the grid has one cell a prediction, hovering a cell names it with its value, and a
// click on a cell charts that prediction over time; without one, the view says so and the page never asked.
// Saves `<screenshot>` (the whole page), prints a JSON summary, exits non-zero on any failure.

import { harness, launch, openDashboard, patient } from './browser.mjs';

const { screenshot, url, fail } = harness('learning.e2e');
const expect = process.argv[4] || 'horde';
const browser = await launch(fail);
const summary = { expect };

try {
  const { page, problems, acks, sent } = await openDashboard(browser, url);
  const pavlov = (f, arg) => page.evaluate(f, arg);

  // The learning view: the stall prediction's values and, a horizon (113 ticks, 2.26 s) later, its returns.
  await page.waitForFunction(() => window.pavlov && window.pavlov.learning && window.pavlov.learning.selected === 'stall',
    null, { timeout: patient(20000) });
  // Wait until every count checked below holds (on a busy host the running RMSE, a point every few
  // paired ticks, may lag the values): the wait ends as soon as it does.
  await page.waitForFunction(() => {
    const v = window.pavlov.learning;
    const d = v.charts.ret.data;
    const both = d[0].filter((_, i) => d[1][i] != null && d[2][i] != null).length;
    const td = v.charts.td.data[1].filter((x) => x != null).length;
    const rmse = v.charts.td.data[2].filter((x) => x != null).length;
    return both >= 50 && d[0].length >= 200 && td >= 100 && rmse >= 5;
  }, null, { timeout: patient(40000) });
  const learn = await pavlov(() => {
    const v = window.pavlov.learning;
    const u = v.charts.ret;
    const d = u.data;
    const both = d[0].map((_, i) => (d[1][i] != null && d[2][i] != null ? 1 : 0)).reduce((a, b) => a + b, 0);
    const lastOf = (col) => col.reduce((last, v, i) => (v != null ? i : last), -1);
    const td = v.charts.td.data[1].filter((x) => x != null).length;
    const rmse = v.charts.td.data[2].filter((x) => x != null).length;
    return {
      points: d[0].length,
      both,
      newest_value: lastOf(d[1]),
      newest_return: lastOf(d[2]),
      td,
      rmse,
      info: v.store.info('stall'),
      params: document.getElementById('learn-params').textContent,
      rmse_text: document.getElementById('learn-rmse').textContent,
      horizon_text: document.getElementById('learn-horizon').textContent,
      series: u.series.map((s) => s.label),
    };
  });
  summary.learning = learn;
  if (learn.both < 50) fail(`only ${learn.both} ticks have both a value and a realised return: ${JSON.stringify(learn)}`);
  // The newest values have no return yet: the return trails the value.
  if (!(learn.newest_return < learn.newest_value)) fail(`the return does not trail the value: ${JSON.stringify(learn)}`);
  if (learn.td < 100 || learn.rmse < 5) fail(`too few TD errors or RMSE points: ${JSON.stringify(learn)}`);
  if (!/α 0\.0227/.test(learn.params) || !/λ 0\.5/.test(learn.params) || !/θ 0\.5/.test(learn.params) || !/τ 25/.test(learn.params) || !/learner paper/.test(learn.params)) {
    fail(`the parameters in force are not shown: ${learn.params}`);
  }
  if (learn.rmse_text === '—') fail('no running error shown');
  if (!learn.horizon_text.startsWith('113 ticks')) fail(`horizon: ${learn.horizon_text}`);

  if (expect === 'horde') {
    await page.waitForFunction(() => {
      const h = window.pavlov.horde;
      return h.values && h.values.length === 132 && h.names.every((n) => n) && h.layout && h.messages >= 3;
    }, null, { timeout: patient(20000) });
    if (!sent.some((f) => JSON.parse(f).cmd === 'horde_watch')) fail('the page did not ask for the Horde');
    const watchAck = acks.find((a) => a.cmd === 'horde_watch');
    if (!watchAck || watchAck.type !== 'ack') fail(`horde_watch was not acknowledged: ${JSON.stringify(watchAck)}`);
    const grid = await pavlov(() => {
      const h = window.pavlov.horde;
      const c = document.getElementById('horde-grid');
      return {
        layout: h.layout, css_width: c.getBoundingClientRect().width, none_hidden: document.getElementById('horde-none').hidden,
        names: h.names.slice(0, 3), info: document.getElementById('horde-info').textContent,
      };
    });
    summary.grid = grid;
    if (!grid.none_hidden) fail('the "no Horde" note is shown with a Horde');
    if (grid.layout.cols * grid.layout.rows < 132 || grid.layout.cell < 8) fail(`grid: ${JSON.stringify(grid)}`);
    if (!/132 predictions/.test(grid.info)) fail(`Horde info: ${grid.info}`);
    // Hover, then click cell 40 (its centre): it is charted, and named in the chart's legend.
    await page.locator('#horde-card').scrollIntoViewIfNeeded();
    const box = await page.locator('#horde-grid').boundingBox();
    const { cols, cell } = grid.layout;
    const index = 40;
    const x = box.x + (index % cols) * cell + cell / 2;
    const y = box.y + Math.floor(index / cols) * cell + cell / 2;
    await page.mouse.move(x, y);
    const name = await pavlov((i) => window.pavlov.horde.names[i], index);
    const hover = await page.locator('#horde-hover').textContent();
    if (!hover.startsWith(name)) fail(`hovering cell ${index} shows "${hover}", not ${name}`);
    await page.mouse.click(x, y);
    await page.waitForFunction((i) => {
      const h = window.pavlov.horde;
      return h.series.picked.includes(i) && h.chart.data[0].length >= 4;
    }, index, { timeout: patient(10000) });
    // A second cell too: two series on the chart.
    const x2 = box.x + ((index + 7) % cols) * cell + cell / 2;
    const y2 = box.y + Math.floor((index + 7) / cols) * cell + cell / 2;
    await page.mouse.click(x2, y2);
    await page.waitForTimeout(1500);
    const charted = await pavlov(() => {
      const h = window.pavlov.horde;
      return {
        picked: h.series.picked,
        labels: h.chart.series.slice(1).map((s) => s.label),
        points: h.chart.data[0].length,
        values: h.chart.data[1].filter((v) => v != null).length,
        card_hidden: document.getElementById('horde-chart-card').hidden,
      };
    });
    summary.charted = charted;
    if (charted.card_hidden || charted.labels[0] !== name || charted.labels.length !== 2 || charted.values < 4) {
      fail(`the clicked predictions are not charted: ${JSON.stringify(charted)}`);
    }
    await page.mouse.move(x, y);
  } else {
    await page.waitForTimeout(1000);
    const none = await pavlov(() => ({
      none_hidden: document.getElementById('horde-none').hidden,
      body_hidden: document.getElementById('horde-body').hidden,
      text: document.getElementById('horde-none').textContent,
    }));
    summary.none = none;
    if (none.none_hidden || !none.body_hidden || !/No Horde configured/.test(none.text)) fail(`without a Horde: ${JSON.stringify(none)}`);
    if (sent.some((f) => JSON.parse(f).cmd === 'horde_watch')) fail('the page asked for a Horde the server does not have');
  }

  await page.locator('#learn-card').scrollIntoViewIfNeeded();
  await page.screenshot({ path: screenshot, fullPage: true });
  const errors = acks.filter((a) => a.type === 'error');
  if (errors.length) fail(`error replies: ${JSON.stringify(errors)}`);
  if (problems.length) fail(problems.join('; '));
  summary.ok = true;
  console.log(JSON.stringify(summary));
} catch (e) {
  fail(e && e.stack ? e.stack : String(e));
} finally {
  await browser.close();
}
