// End-to-end check of the dashboard in headless Debian Chromium, driven by playwright-core.
//
//   node web/tests/dashboard.e2e.mjs <dashboard URL> <screenshot.png>
//
// Opens the page served by a running `pavlov serve`, checks that live ticks arrive and the charts
// update, switches to manual mode and drives with the arrow keys, presses the E-STOP button, and checks in the tick stream that the server stopped the robot
// (e-stop latched, wheel command 0/0, safety stop "e_stop"). Saves a screenshot, prints a JSON summary
// on stdout, exits non-zero on any failure (see browser.mjs for the browser).

import { harness, launch, openDashboard, patient } from './browser.mjs';

const { screenshot, url, fail, until } = harness('dashboard.e2e');
const browser = await launch(fail);
const summary = {};
try {
  const { page, problems, ticks, acks, sent } = await openDashboard(browser, url);

  // Live ticks arrive and every chart grows.
  await page.waitForFunction(() => window.pavlov && window.pavlov.ticks >= 60, null, { timeout: patient(20000) });
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
  await page.waitForFunction(() => document.getElementById('h-lateness').textContent.includes('µs'), null, { timeout: patient(5000) });
  await page.waitForFunction(() => document.getElementById('conn').dataset.state === 'live', null, { timeout: patient(5000) });
  // The robot link's state and OI mode, from the tick stream.
  await page.waitForFunction(() => document.getElementById('h-mode').textContent === 'Safe', null, { timeout: patient(5000) });
  const linkText = await page.locator('#h-link').textContent();
  if (!linkText.startsWith('up')) fail(`link shown as "${linkText}"`);
  if (!(await page.locator('#trip-banner').isHidden())) fail('the trip banner shows on a healthy link');
  summary.link = { text: linkText, mode: await page.locator('#h-mode').textContent() };
  if (ticks.length === 0) fail('no tick frames observed on the websocket');
  summary.moving_before_estop = ticks.some((t) => t.command.left !== 0 || t.command.right !== 0);

  // The mode switch and teleop by arrow key: in manual mode, holding ↑ drives both wheels forward at the
  // speed slider's 200 mm/s; letting go stops them.
  const tickCount = () => ticks.length;
  let from = tickCount();
  await page.click('#mode-manual');
  await until('ticks in manual mode', () => ticks.slice(from).some((t) => t.mode === 'manual'), 3000);
  await page.waitForSelector('#mode-manual.active', { timeout: patient(3000) });
  from = tickCount();
  await page.keyboard.down('ArrowUp');
  await until('the teleop command in the tick stream', () => ticks.slice(from).some((t) => t.command.left === 200 && t.command.right === 200), 3000);
  await page.waitForTimeout(700); // longer than the 0.5 s teleop expiry: the page must keep refreshing it
  const held = ticks.slice(-10);
  if (!held.every((t) => t.command.left === 200 && t.command.right === 200)) fail(`teleop did not hold: ${JSON.stringify(held.map((t) => t.command))}`);
  from = tickCount();
  await page.keyboard.up('ArrowUp');
  await until('the wheels stopped after the key was released', () => ticks.slice(from).some((t) => t.command.left === 0 && t.command.right === 0), 3000);
  summary.teleop = 'ok';
  from = tickCount();
  await page.click('#mode-pavlovian');
  await until('ticks in pavlovian mode', () => ticks.slice(from).some((t) => t.mode === 'pavlovian'), 3000);
  await until('the default policy driving again', () => ticks.slice(from).some((t) => t.command.left !== 0 || t.command.right !== 0), 5000);

  // E-stop: the button sends the command, the server acks it and the tick stream shows the robot stopped.
  const pressedAt = ticks.length;
  await page.click('#estop');
  await until('the estop command frame', () => sent.some((p) => p.includes('"cmd":"estop"')), 3000);
  await until('the estop ack', () => acks.some((a) => a.type === 'ack' && a.cmd === 'estop'), 5000);
  const stopped = (t) => t.estop && t.command.left === 0 && t.command.right === 0 && t.safety_stop === 'e_stop';
  await until('25 ticks with the robot stopped by the e-stop', () => ticks.slice(pressedAt).filter(stopped).length >= 25, 5000);
  const afterStop = ticks.slice(pressedAt);
  const firstStopped = afterStop.findIndex(stopped);
  const relapsed = afterStop.slice(firstStopped).some((t) => !stopped(t));
  if (relapsed) fail('a tick after the e-stop was not stopped (the latch did not hold)');
  await page.waitForSelector('#estop-banner:not([hidden])', { timeout: patient(3000) });
  summary.ticks_until_stopped = firstStopped;

  // Let the charts show a few seconds after the stop, then take the picture.
  await page.waitForTimeout(1500);
  await page.screenshot({ path: screenshot, fullPage: true });
  summary.ticks_seen = ticks.length;
  summary.page_ticks = await page.evaluate(() => window.pavlov.ticks);
  if (problems.length) fail(problems.join('; '));
  summary.ok = true;
  console.log(JSON.stringify(summary));
} catch (e) {
  fail(e && e.stack ? e.stack : String(e));
} finally {
  await browser.close();
}
