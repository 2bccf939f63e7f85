// The robot-trip path of the dashboard in headless Debian Chromium, driven by playwright-core.
//
//   node web/tests/trip.e2e.mjs <dashboard URL> <screenshot.png>
//
// The server runs the simulated Create with trips injected (`--faults trip=…`). The page must show the
// trip banner with its cause while the tick stream says `tripped` and commands a stop, keep it (nothing
// re-arms behind the operator's back), and after a click on Re-arm the server acks `rearm` and the link
// comes back up. Saves a screenshot of the banner, prints a JSON summary, exits non-zero on any failure.

import { harness, launch, openDashboard, patient } from './browser.mjs';

const { screenshot, url, fail, until } = harness('trip.e2e');
const browser = await launch(fail);
const summary = {};
try {
  const { page, problems, ticks, acks } = await openDashboard(browser, url);

  // A trip arrives: the banner shows its cause, the stream says tripped and commands a stop.
  await until('a tick with the link tripped', () => ticks.some((t) => t.link.state === 'tripped'), 60000);
  await page.waitForSelector('#trip-banner:not([hidden])', { timeout: patient(3000) });
  const cause = await page.locator('#trip-cause').textContent();
  const first = ticks.find((t) => t.link.state === 'tripped');
  if (!['wheel drop', 'cliff'].includes(cause)) fail(`trip cause shown as "${cause}"`);
  if (cause !== first.link.trip.replace(/_/g, ' ')) fail(`banner says ${cause}, stream says ${first.link.trip}`);
  summary.cause = cause;

  // It stays tripped for the next 100 ticks (2 s of an idle machine; longer on a busy one, where ticks are
  // skipped): nothing re-enters Safe behind the operator's back.
  const from = ticks.indexOf(first);
  await until('100 ticks after the trip', () => ticks.length - from >= 100, 10000);
  const held = ticks.slice(from);
  // (A busy host may also let the stream go stale meanwhile: `stale`/`link_down` is still a stop, never Safe.)
  const stopped = (t) => t.command.left === 0 && t.command.right === 0;
  const bad = held.find((t) => t.link.state === 'up' || !stopped(t)
    || !['robot_tripped', 'link_down'].includes(t.safety_stop) || !['tripped', 'stale'].includes(t.link.state));
  if (bad) fail(`while tripped: ${JSON.stringify(bad)}`);
  if ((await page.locator('#h-mode').textContent()) !== 'Passive') fail('OI mode not shown as Passive');
  await page.screenshot({ path: screenshot, fullPage: true });

  // Re-arm: acked, and the link comes back up with Safe.
  const at = ticks.length;
  await page.click('#rearm');
  await until('the rearm ack', () => acks.some((a) => a.type === 'ack' && a.cmd === 'rearm'), 5000);
  await until('the link up in Safe after the re-arm', () => ticks.slice(at).some((t) => t.link.state === 'up' && t.link.mode === 2), 5000);
  summary.rearmed = true;
  if (problems.length) fail(problems.join('; '));
  summary.ok = true;
  console.log(JSON.stringify(summary));
} catch (e) {
  fail(e && e.stack ? e.stack : String(e));
} finally {
  await browser.close();
}
