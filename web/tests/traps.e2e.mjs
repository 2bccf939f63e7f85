// The dashboard without traps (issue 25), in headless Debian Chromium driven by playwright-core.
//
//   TOKEN=… node web/tests/traps.e2e.mjs <dashboard URL> <screenshot.png>
//
// Run by tests/e2e/dashboard/browser_traps.rs against `pavlov serve` with the gesture experiment
// (config/interaction.toml, a simulated operator streaming a skeleton) and a token, opened once the run
// has gone on for a while. As the operator (the page opened with `#token=`): every stacked chart's plot
// area starts at the same left edge (within 1 px); for every window of the selector, the strip charts,
// the elbow chart and the learning view's two charts all show that window, and the elbow chart and the
// learning view hold data from before the page connected (the server's history); after a burst of
// operator commands, at the 5- and 10-minute windows, no two marker labels overlap (their bounding boxes)
// and each says what it means on hover; the legend names every marker kind; the first-run note shows,
// and once dismissed stays dismissed after a reload. As a watcher (no token): E-STOP, Re-arm and Release
// are disabled and say they need the operator's token, and no banner says "you". Screenshots:
// `<screenshot>` (operator), `<screenshot>-watcher.png`, `<screenshot>-5min.png`. Prints a JSON summary,
// exits non-zero on any failure. Every wait is for a condition; the deadlines are failure timeouts only.

import { harness, launch, openDashboard, patient } from './browser.mjs';

const { screenshot, url, fail, until } = harness('traps.e2e');
const token = process.env.TOKEN;
if (!token) fail('TOKEN must be set');
const shot = (suffix) => screenshot.replace(/\.png$/, `-${suffix}.png`);
const browser = await launch(fail);
const summary = {};
const STACKED = ['chart-pred', 'chart-events', 'chart-current', 'chart-wheels', 'chart-elbow', 'chart-learn-return', 'chart-learn-td'];

/** Whether two boxes `{x, y, width, height}` share any area. */
const overlap = (a, b) => a.x < b.x + b.width && b.x < a.x + a.width && a.y < b.y + b.height && b.y < a.y + a.height;

try {
  // ---------------------------------------------------------------- the operator
  const op = await openDashboard(browser, `${url}#token=${token}`);
  const { page } = op;
  const pavlov = (f, arg) => page.evaluate(f, arg);
  await page.waitForFunction(() => window.pavlov && window.pavlov.historyDone && window.pavlov.canCommand
    && window.pavlov.ticks >= 25, null, { timeout: patient(30000) });
  await page.waitForSelector('#elbow-card:not([hidden]) #chart-elbow .uplot', { timeout: patient(15000) });
  await until('a live tick', () => op.ticks.length > 0, 15000);
  const firstLive = op.ticks[0].t;
  summary.first_live_t = firstLive;

  // The first-run note is there on a first visit.
  if (await page.locator('#first-run').isHidden()) fail('no first-run note on a first visit');

  // One left edge: every stacked chart's plot area starts at the same x.
  const edges = await pavlov((ids) => ids.map((id) => {
    const over = document.querySelector(`#${id} .u-over`);
    return over ? [id, over.getBoundingClientRect().left] : [id, null];
  }), STACKED);
  summary.left_edges = Object.fromEntries(edges);
  const lefts = edges.map(([, x]) => x);
  if (lefts.some((x) => x === null)) fail(`a stacked chart is missing: ${JSON.stringify(edges)}`);
  if (Math.max(...lefts) - Math.min(...lefts) > 1) fail(`plot areas start at different x: ${JSON.stringify(edges)}`);

  // One window: every chart (the elbow chart and the learning view included) shows the window selected.
  const spans = () => pavlov(() => {
    const p = window.pavlov;
    const all = [...p.charts.map((c) => [c.el.id, c.u]), ['chart-learn-return', p.learning.charts.ret], ['chart-learn-td', p.learning.charts.td]];
    return { charts: all.map(([id, u]) => [id, u.scales.x.min, u.scales.x.max]) };
  });
  summary.windows = {};
  for (const seconds of [10, 60, 300, 600, 30]) {
    await page.click(`.window[data-seconds="${seconds}"]`);
    await page.waitForFunction((s) => {
      const p = window.pavlov;
      const us = [...p.charts.map((c) => c.u), p.learning.charts.ret, p.learning.charts.td];
      const maxes = us.map((u) => u.scales.x.max);
      // Live, so the window moves on: the charts may be a redraw apart (≤ 1 s at the widest window).
      return us.every((u) => Math.abs(u.scales.x.max - u.scales.x.min - s) < 1e-6)
        && Math.max(...maxes) - Math.min(...maxes) <= 1.5;
    }, seconds, { timeout: patient(15000) });
    summary.windows[seconds] = (await spans()).charts.map(([id, min, max]) => [id, Number(min.toFixed(2)), Number(max.toFixed(2))]);
  }

  // Filled from the server's history: the elbow chart and the learning view hold data from well before
  // the page connected (the run had gone on for a while before it was opened).
  await page.click('.window[data-seconds="300"]');
  await page.waitForFunction((t0) => {
    const p = window.pavlov;
    const before = (d, k) => d[0].some((x, i) => x < t0 - 5 && d[k][i] != null);
    const elbow = p.elbow.data();
    return elbow && before(elbow, 1) && before(p.learning.charts.ret.data, 1)
      && before(p.learning.charts.ret.data, 2) && before(p.learning.charts.td.data, 1);
  }, firstLive, { timeout: patient(20000) }).catch(async () => {
    const d = await pavlov(() => ({
      elbow: window.pavlov.elbow.data() && window.pavlov.elbow.data()[0].slice(0, 3),
      learn: window.pavlov.learning.charts.ret.data[0].slice(0, 3),
    }));
    fail(`the elbow chart or the learning view has nothing from before ${firstLive} s: ${JSON.stringify(d)}`);
  });
  summary.history_filled = await pavlov((t0) => {
    const p = window.pavlov;
    const count = (d, k) => d[0].filter((x, i) => x < t0 && d[k][i] != null).length;
    return {
      elbow_left: count(p.elbow.data(), 1), value: count(p.learning.charts.ret.data, 1),
      return: count(p.learning.charts.ret.data, 2), td: count(p.learning.charts.td.data, 1),
    };
  }, firstLive);

  // Many markers close together: a burst of operator commands (modes, requests, learning parameters).
  const burst = [];
  // 30 commands: within the connection's burst of 40 messages (PROTOCOL.md, the rate limit).
  for (let i = 0; i < 10; i += 1) {
    burst.push({ cmd: 'set_mode', mode: i % 2 ? 'pavlovian' : 'reactive' });
    burst.push({ cmd: 'human_request', duration_ms: 100 });
    burst.push({ cmd: 'set_params', prediction: 'command', alpha: 0.01 + (i % 4) * 0.001 });
  }
  const acked = op.acks.length;
  await pavlov((cmds) => cmds.forEach((c, i) => window.pavlov.ws.send(JSON.stringify({ ...c, id: 50000 + i }))), burst);
  await until('the answers to the burst', () => op.acks.length - acked >= burst.length, 20000);
  const refused = op.acks.slice(acked).filter((a) => a.type === 'error');
  if (refused.length) fail(`commands of the burst refused: ${JSON.stringify(refused.slice(0, 3))}`);
  await page.click('.window[data-seconds="600"]');
  await page.waitForFunction((n) => window.pavlov.charts[0].drawnMarkers.length >= n, burst.length, { timeout: patient(15000) });

  // No two labels overlap, at the 10- and the 5-minute window; each has hover text saying what it means.
  summary.labels = {};
  for (const seconds of [600, 300]) {
    await page.click(`.window[data-seconds="${seconds}"]`);
    await page.waitForFunction((s) => {
      const u = window.pavlov.charts[0].u;
      return Math.abs(u.scales.x.max - u.scales.x.min - s) < 1e-6 && document.querySelectorAll('#chart-pred .marker-label').length > 0;
    }, seconds, { timeout: patient(15000) });
    const labels = await pavlov(() => [...document.querySelectorAll('.marker-label')].map((el) => {
      const r = el.getBoundingClientRect();
      const plot = el.closest('.u-over').getBoundingClientRect();
      return {
        text: el.textContent, title: el.title, kind: el.dataset.kind,
        box: { x: r.x, y: r.y, width: r.width, height: r.height },
        inside: r.left >= plot.left - 0.5 && r.right <= plot.right + 0.5 && r.top >= plot.top - 0.5,
      };
    }));
    for (let i = 0; i < labels.length; i += 1) {
      for (let j = i + 1; j < labels.length; j += 1) {
        if (overlap(labels[i].box, labels[j].box)) fail(`labels overlap at ${seconds} s: ${JSON.stringify([labels[i], labels[j]])}`);
      }
    }
    const outside = labels.find((l) => !l.inside);
    if (outside) fail(`a label leaves its chart: ${JSON.stringify(outside)}`);
    const bare = labels.find((l) => l.title.length < 40 || !l.title.startsWith(l.text));
    if (bare) fail(`a label without hover text: ${JSON.stringify(bare)}`);
    const hidden = await pavlov(() => window.pavlov.charts[0].hiddenLabels);
    const more = await page.locator('#markers-more').isVisible();
    if (hidden > 0 && !more) fail(`${hidden} labels left out without a word`);
    summary.labels[seconds] = {
      shown: labels.length, texts: labels.map((l) => l.text), left_out: hidden, markers: await pavlov(() => window.pavlov.charts[0].drawnMarkers.length),
    };
    if (seconds === 300) await page.screenshot({ path: shot('5min'), fullPage: true });
  }

  // The legend: every kind, with its meaning and usual cause on hover.
  const legend = await pavlov(() => [...document.querySelectorAll('#marker-legend .marker-key')].map((k) => ({
    kind: k.dataset.kind, text: k.textContent, title: k.title, visible: k.getBoundingClientRect().width > 0,
  })));
  summary.legend = legend.map((k) => k.text);
  const kinds = legend.map((k) => k.kind);
  for (const k of ['stall', 'link', 'estop', 'control', 'learning', 'storage']) {
    if (!kinds.includes(k)) fail(`the legend lacks ${k}: ${JSON.stringify(legend)}`);
  }
  if (!legend.every((k) => k.visible && k.title.length > 40)) fail(`a legend entry is hidden or unexplained: ${JSON.stringify(legend)}`);
  for (const k of ['stall', 'link']) {
    if (!/host load/.test(legend.find((x) => x.kind === k).title)) fail(`the ${k} entry does not name host load`);
  }

  // The operator's own buttons are live; the trip banner speaks to the operator.
  const opButtons = await pavlov(() => ({
    estop: document.getElementById('estop').disabled, rearm: document.getElementById('rearm').disabled,
    trip: document.getElementById('trip-banner').textContent.replace(/\s+/g, ' ').trim(),
  }));
  if (opButtons.estop || opButtons.rearm) fail(`the operator's E-STOP or Re-arm is disabled: ${JSON.stringify(opButtons)}`);
  await page.click('.window[data-seconds="30"]');
  await page.waitForFunction(() => Math.abs(window.pavlov.charts[0].u.scales.x.max - window.pavlov.charts[0].u.scales.x.min - 30) < 1e-6, null, { timeout: patient(15000) });
  await page.screenshot({ path: screenshot, fullPage: true });

  // The first-run note goes when dismissed, and stays gone on the next visit.
  await page.click('#first-run-close');
  if (!(await page.locator('#first-run').isHidden())) fail('the first-run note did not go');
  await page.reload({ waitUntil: 'load' });
  await page.waitForFunction(() => window.pavlov && window.pavlov.ticks > 0, null, { timeout: patient(20000) });
  if (!(await page.locator('#first-run').isHidden())) fail('the first-run note came back after a reload');
  summary.first_run_note_remembered = true;
  if (op.problems.length) fail(op.problems.join('; '));

  // ---------------------------------------------------------------- a watcher
  const w = await openDashboard(browser, url);
  await w.page.waitForFunction(() => window.pavlov && window.pavlov.historyDone && window.pavlov.ticks >= 10
    && window.pavlov.hello && !window.pavlov.hello.can_command, null, { timeout: patient(30000) });
  const watcher = await w.page.evaluate(() => {
    const b = (id) => {
      const el = document.getElementById(id);
      return { disabled: el.disabled, text: el.textContent.replace(/\s+/g, ' ').trim(), title: el.title };
    };
    const banners = ['trip-banner', 'estop-banner', 'watch-banner'].map((id) => document.getElementById(id).textContent.replace(/\s+/g, ' ').trim());
    return {
      estop: b('estop'), rearm: b('rearm'), release: b('release'), mode: b('mode-reactive'), banners,
    };
  });
  summary.watcher = watcher;
  for (const name of ['estop', 'rearm', 'release', 'mode']) {
    if (!watcher[name].disabled) fail(`a watcher's ${name} button is not disabled: ${JSON.stringify(watcher[name])}`);
  }
  for (const name of ['estop', 'rearm']) {
    const b = watcher[name];
    if (!`${b.text} ${b.title}`.includes("needs the operator's token")) fail(`a watcher's ${name} does not say why: ${JSON.stringify(b)}`);
  }
  const you = watcher.banners.find((t) => /\byou\b/i.test(t));
  if (you) fail(`a banner tells a watcher "you": ${you}`);
  if (!/when the operator re-arms/.test(watcher.banners[0])) fail(`the trip banner: ${watcher.banners[0]}`);
  await w.page.screenshot({ path: shot('watcher'), fullPage: true });
  if (w.problems.length) fail(w.problems.join('; '));
  summary.ok = true;
  console.log(JSON.stringify(summary));
} catch (e) {
  fail(e && e.stack ? e.stack : String(e));
} finally {
  await browser.close();
}
