// The dashboard as an analysis tool, in headless Debian Chromium driven by playwright-core.
//
//   node web/tests/analysis.e2e.mjs <dashboard URL> <screenshot.png>
//
// Run by tests/e2e/dashboard/browser_analysis.rs, which starts `pavlov serve` a few seconds before, and
// which stops the server when this script prints {"step":"stop-server"} and starts it again on the same
// port at {"step":"restart-server"}. Checks, in order: a page opened mid-run shows the run from its start
// (the server's history); Pause freezes the charts while ticks keep coming in; a drag zooms every chart to
// the same time span and a double-click goes back; the hover readout shows values; the window selector; the
// CSV of the view; a `set_params` sent by another websocket client puts an "α=…" marker on the charts and
// the new α in the Learning card; when the server stops, the page greys out and its E-STOP says it cannot
// send; when it is back, the page is live again with the new run's history. Saves `<screenshot>` (live,
// with markers) and `<screenshot>-disconnected.png`, prints a JSON summary, exits non-zero on any failure.

import { readFileSync } from 'node:fs';

import { harness, launch, openDashboard, patient } from './browser.mjs';

const { screenshot, url, fail, until } = harness('analysis.e2e');
const disconnectedShot = screenshot.replace(/\.png$/, '-disconnected.png');
const browser = await launch(fail);
const summary = {};
const step = (name) => console.log(JSON.stringify({ step: name }));

try {
  const { page, problems, ticks } = await openDashboard(browser, url);
  const pavlov = (f, arg) => page.evaluate(f, arg);
  const xRange = (i = 0) => pavlov((k) => {
    const { min, max } = window.pavlov.charts[k].u.scales.x;
    return { min, max };
  }, i);

  // History on connect: the server has been running for seconds; the page shows them all.
  await page.waitForFunction(() => window.pavlov && window.pavlov.historyDone && window.pavlov.ticks >= 20, null, { timeout: patient(20000) });
  const firstLive = ticks[0].seq;
  const earliest = await pavlov(() => window.pavlov.timeline.samples[0].seq);
  if (firstLive < 150) fail(`the page opened only ${firstLive} ticks into the run`);
  if (earliest > 5) fail(`the page's data begins at tick ${earliest}, not at the run's start (first live tick ${firstLive})`);
  await page.waitForFunction(() => window.pavlov.charts[0].u.data[0][0] <= 0.2, null, { timeout: patient(5000) });
  summary.history = { earliest_seq: earliest, first_live_seq: firstLive };

  // Pause: the charts freeze while ticks keep arriving; Resume moves them on.
  await page.click('#pause');
  await page.waitForFunction(() => window.pavlov.view.paused, null, { timeout: patient(2000) });
  await page.waitForTimeout(100);
  const frozen = await pavlov(() => window.pavlov.charts.map((c) => [c.u.data[0].length, c.u.data[0][c.u.data[0].length - 1]]));
  const ticksAtPause = await pavlov(() => window.pavlov.ticks);
  const seqAtPause = await pavlov(() => window.pavlov.timeline.last.seq);
  await page.waitForTimeout(1200);
  const still = await pavlov(() => window.pavlov.charts.map((c) => [c.u.data[0].length, c.u.data[0][c.u.data[0].length - 1]]));
  const ticksLater = await pavlov(() => window.pavlov.ticks);
  const seqLater = await pavlov(() => window.pavlov.timeline.last.seq);
  if (JSON.stringify(frozen) !== JSON.stringify(still)) fail(`the charts moved while paused: ${JSON.stringify(frozen)} → ${JSON.stringify(still)}`);
  if (ticksLater - ticksAtPause < 25 || seqLater - seqAtPause < 25) fail(`ticks did not keep coming while paused: ${ticksAtPause} → ${ticksLater}`);
  if ((await page.locator('#pause').textContent()) !== 'Resume') fail('the pause button does not offer Resume');
  if (!(await page.locator('#view-state').textContent()).startsWith('paused')) fail('the view does not say it is paused');
  await page.click('#pause');
  await page.waitForFunction((t) => {
    const d = window.pavlov.charts[0].u.data[0];
    return !window.pavlov.view.paused && d[d.length - 1] > t + 0.5;
  }, frozen[0][1], { timeout: patient(3000) });
  summary.pause = { ticks_while_paused: ticksLater - ticksAtPause };

  // Drag-to-zoom on the predictions chart: every chart shows the dragged span, and the view pauses.
  const before = await xRange();
  const over = await page.locator('#chart-pred .u-over').boundingBox();
  const y = over.y + over.height / 2;
  await page.mouse.move(over.x + over.width * 0.3, y);
  await page.mouse.down();
  await page.mouse.move(over.x + over.width * 0.5, y, { steps: 8 });
  await page.mouse.move(over.x + over.width * 0.6, y, { steps: 4 });
  await page.mouse.up();
  await page.waitForFunction(() => window.pavlov.view.zoom !== null, null, { timeout: patient(2000) });
  const zoomed = await xRange();
  const width = (r) => r.max - r.min;
  if (!(width(zoomed) < width(before) * 0.45 && width(zoomed) > width(before) * 0.15)) {
    fail(`the zoom did not narrow the x range as dragged: ${JSON.stringify(before)} → ${JSON.stringify(zoomed)}`);
  }
  if (zoomed.min < before.min || zoomed.max > before.max) fail(`zoomed outside the window: ${JSON.stringify(zoomed)}`);
  for (let i = 1; i < 4; i++) {
    const r = await xRange(i);
    if (Math.abs(r.min - zoomed.min) > 1e-6 || Math.abs(r.max - zoomed.max) > 1e-6) fail(`chart ${i} is not zoomed with the others`);
  }
  if (!(await pavlov(() => window.pavlov.view.paused))) fail('zooming did not pause the view');
  if (await page.locator('#zoom-reset').isHidden()) fail('no Reset zoom button while zoomed');
  // Hover readout: the legend shows the values under the cursor.
  await page.mouse.move(over.x + over.width * 0.5, over.y + over.height * 0.5);
  await page.waitForTimeout(150);
  const readout = await page.locator('#chart-pred .u-legend .u-value').allTextContents();
  if (!readout[0].endsWith(' s') || readout.slice(1).some((v) => v === '—' || v === '')) fail(`no hover readout: ${JSON.stringify(readout)}`);
  summary.zoom = { before, zoomed, readout };
  // Double-click: back to the whole window, and live again.
  await page.mouse.dblclick(over.x + over.width * 0.5, y);
  await page.waitForFunction(() => window.pavlov.view.zoom === null && !window.pavlov.view.paused, null, { timeout: patient(2000) });
  await page.waitForTimeout(200);
  const back = await xRange();
  if (Math.abs(width(back) - 30) > 0.01) fail(`after the double-click the window is ${width(back)} s, not 30 s`);

  // The window selector, and the CSV of what is on screen.
  await page.click('.window[data-seconds="10"]');
  await page.waitForTimeout(200);
  const ten = await xRange();
  if (Math.abs(width(ten) - 10) > 0.01) fail(`the 10 s window shows ${width(ten)} s`);
  const [download] = await Promise.all([page.waitForEvent('download', { timeout: patient(5000) }), page.click('#csv')]);
  const csv = readFileSync(await download.path(), 'utf8').trimEnd().split('\n');
  if (!csv[0].startsWith('seq,t_s,mode,stall,stall_threshold,')) fail(`CSV header: ${csv[0]}`);
  if (csv.length < 300 || csv.length > 520) fail(`CSV of a 10 s view has ${csv.length - 1} rows`);
  summary.csv = { rows: csv.length - 1, file: download.suggestedFilename() };

  // A set_params from another client: an "α=0.01" marker appears on the charts, the Learning card shows it.
  const ack = await pavlov(() => new Promise((resolve, reject) => {
    const ws = new WebSocket(`ws://${window.location.host}/ws`, ['pavlov.v1']);
    ws.onopen = () => ws.send(JSON.stringify({ cmd: 'set_params', id: 1, alpha: 0.01 }));
    ws.onmessage = (m) => {
      const v = JSON.parse(m.data);
      // Events carry an id of their own: only an ack or an error answers the command.
      if (v.id === 1 && (v.type === 'ack' || v.type === 'error')) { ws.close(); resolve(v); }
    };
    ws.onerror = () => reject(new Error('the second client could not connect'));
  }));
  if (ack.type !== 'ack') fail(`set_params was not acked: ${JSON.stringify(ack)}`);
  await page.waitForFunction(() => window.pavlov.charts[0].drawnMarkers.includes('α=0.01'), null, { timeout: patient(5000) });
  const everyChart = await pavlov(() => window.pavlov.charts.every((c) => c.drawnMarkers.includes('α=0.01')));
  if (!everyChart) fail('the marker is not on every chart');
  await page.waitForFunction(() => document.getElementById('inforce-body').textContent.includes('0.01'), null, { timeout: patient(3000) });
  await page.click('#mode-reactive');
  await page.waitForFunction(() => window.pavlov.charts[0].drawnMarkers.includes('mode→reactive'), null, { timeout: patient(5000) });
  summary.markers = await pavlov(() => window.pavlov.charts[0].drawnMarkers);
  await page.click('.window[data-seconds="30"]');
  await page.waitForTimeout(1500);
  await page.screenshot({ path: screenshot, fullPage: true });

  // The server stops: the page greys out, says so, and its E-STOP says it cannot send. (From here on the
  // browser reports each failed reconnection attempt on its console: those are expected.)
  if (problems.length) fail(problems.join('; '));
  step('stop-server');
  await page.waitForFunction(() => document.body.classList.contains('disconnected'), null, { timeout: patient(15000) });
  const grey = await pavlov(() => ({
    estop_disabled: document.getElementById('estop').disabled,
    estop_text: document.getElementById('estop').textContent,
    banner: !document.getElementById('disconnect-banner').hidden,
    banner_text: document.getElementById('disconnect-banner').textContent.replace(/\s+/g, ' ').trim(),
    charts_filter: getComputedStyle(document.getElementById('charts')).filter,
    card_filter: getComputedStyle(document.querySelector('.side > .card')).filter,
    conn: document.getElementById('conn').dataset.state,
    live: window.pavlov.live,
  }));
  if (!grey.estop_disabled || !grey.estop_text.includes('cannot send')) fail(`the E-STOP still looks usable: ${JSON.stringify(grey)}`);
  if (!grey.banner || !grey.banner_text.includes('cannot reach the robot')) fail(`no disconnected banner: ${JSON.stringify(grey)}`);
  if (!grey.charts_filter.includes('grayscale') || !grey.card_filter.includes('grayscale')) fail(`panels not greyed: ${JSON.stringify(grey)}`);
  if (grey.conn !== 'down' || grey.live) fail(`the connection does not say down: ${JSON.stringify(grey)}`);
  summary.disconnected = grey;
  await page.waitForTimeout(300);
  await page.screenshot({ path: disconnectedShot, fullPage: true });

  // The server is back (a new run on the same port): the page reconnects by itself, live, with its history.
  const oldRun = await pavlov(() => window.pavlov.run);
  step('restart-server');
  await page.waitForFunction((old) => window.pavlov.live && window.pavlov.run !== old && window.pavlov.historyDone
    && !document.body.classList.contains('disconnected') && !document.getElementById('estop').disabled, oldRun, { timeout: patient(30000) });
  const after = await pavlov(() => ({ first: window.pavlov.timeline.samples[0].seq, events: window.pavlov.timeline.events.length }));
  if (after.first > 5) fail(`after reconnecting the data begins at tick ${after.first}`);
  summary.reconnected = after;

  const unexpected = problems.filter((p) => !/WebSocket connection to .* failed/.test(p));
  if (unexpected.length) fail(unexpected.join('; '));
  summary.ok = true;
  console.log(JSON.stringify(summary));
} catch (e) {
  fail(e && e.stack ? e.stack : String(e));
} finally {
  await browser.close();
}
