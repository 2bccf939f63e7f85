// What the browser scripts (dashboard.e2e.mjs, trip.e2e.mjs, watcher.e2e.mjs) share: their arguments, failing loudly,
// waiting for a condition, and launching Debian's Chromium through playwright-core. Never downloads a
// browser: Chromium comes from apt (`apt-get install chromium`); set CHROMIUM to use another binary.

import { existsSync } from 'node:fs';
import { chromium } from 'playwright-core';

const ARGS = [
  '--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
  '--disable-background-networking', '--disable-component-update', '--disable-sync',
];

/**
 * Failure timeouts are stretched this many times: a wait returns as soon as its condition holds, so a generous
 * deadline costs nothing when things work, and a busy machine (the suite runs beside other work) must not turn
 * a slow-but-correct page into a failure. The numbers written in the scripts are what an idle machine needs.
 */
export const PATIENCE = 6;

/** A script's failure timeout for `ms` of an idle machine's patience. */
export function patient(ms) {
  return ms * PATIENCE;
}

/** A script's harness: `fail` exits non-zero with the script's name, `until` polls a predicate. */
export function harness(name) {
  function fail(message) {
    console.error(`${name}: FAIL: ${message}`);
    process.exit(1);
  }
  async function until(what, predicate, idleMs) {
    const timeoutMs = patient(idleMs);
    const end = Date.now() + timeoutMs;
    while (Date.now() < end) {
      if (predicate()) return;
      await new Promise((r) => setTimeout(r, 50));
    }
    fail(`timed out after ${timeoutMs} ms waiting for ${what}`);
  }
  const [url, screenshot] = process.argv.slice(2);
  if (!url || !screenshot) fail(`usage: node ${name}.mjs <dashboard URL> <screenshot.png>`);
  return { url, screenshot, fail, until };
}

/** Launches headless Chromium, failing through `fail` when it is not installed. */
export async function launch(fail) {
  const executablePath = process.env.CHROMIUM || '/usr/bin/chromium';
  if (!existsSync(executablePath)) fail(`no Chromium at ${executablePath}: run \`apt-get install -y chromium\``);
  return chromium.launch({ executablePath, args: ARGS, headless: true });
}

/**
 * Opens the dashboard at `url` in a new page and follows its websocket. Returns the page, the page and
 * console errors seen (`problems`), every tick and every ack/error received (`ticks`, `acks`, as sent
 * by the server), and every frame the page sent (`sent`).
 */
export async function openDashboard(browser, url) {
  const page = await browser.newPage({ viewport: { width: 1440, height: 1050 } });
  const problems = [];
  page.on('pageerror', (e) => problems.push(`page error: ${e.message}`));
  page.on('console', (m) => { if (m.type() === 'error') problems.push(`console error: ${m.text()}`); });
  const ticks = [];
  const acks = [];
  const sent = [];
  const socketOpened = page.waitForEvent('websocket', { timeout: 15000 });
  await page.goto(url, { waitUntil: 'load' });
  const ws = await socketOpened;
  ws.on('framesent', (f) => sent.push(String(f.payload)));
  ws.on('framereceived', (f) => {
    let m;
    try { m = JSON.parse(String(f.payload)); } catch { return; }
    if (m.type === 'tick') ticks.push(m);
    if (m.type === 'ack' || m.type === 'error') acks.push(m);
  });
  return { page, problems, ticks, acks, sent };
}
