// What the browser scripts (dashboard.e2e.mjs, trip.e2e.mjs) share: their arguments, failing loudly,
// waiting for a condition, and launching Debian's Chromium through playwright-core. Never downloads a
// browser: Chromium comes from apt (`apt-get install chromium`); set CHROMIUM to use another binary.

import { existsSync } from 'node:fs';
import { chromium } from 'playwright-core';

const ARGS = [
  '--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
  '--disable-background-networking', '--disable-component-update', '--disable-sync',
];

/** A script's harness: `fail` exits non-zero with the script's name, `until` polls a predicate. */
export function harness(name) {
  function fail(message) {
    console.error(`${name}: FAIL: ${message}`);
    process.exit(1);
  }
  async function until(what, predicate, timeoutMs) {
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
