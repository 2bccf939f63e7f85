// A full disk on the dashboard, in headless Debian Chromium driven by playwright-core.
//
//   FILL_DIR=<the server's folder, on a small filesystem> node web/tests/storage.e2e.mjs <dashboard URL> <screenshot.png>
//
// The server records into FILL_DIR (`pavlov serve --record`, its working folder on a 2 MiB tmpfs). The page
// must show the recording on; then this script fills the filesystem (a filler file, all the room but 16 kB)
// and the recording badge must turn to "stopped" with the OS's reason under it. A click on Save weights
// must show why the checkpoint was not written. Once the filler is gone, a click on Start must bring the
// badge back on and clear the notice. Saves a screenshot of the failure, prints a JSON summary, exits
// non-zero on any failure.

import { closeSync, ftruncateSync, fstatSync, openSync, unlinkSync, writeSync } from 'node:fs';
import { join } from 'node:path';

import { harness, launch, openDashboard, patient } from './browser.mjs';

const { screenshot, url, fail, until } = harness('storage.e2e');
const dir = process.env.FILL_DIR;
if (!dir) fail('FILL_DIR is not set');
const filler = join(dir, 'filler');

/** Fills the filesystem of `dir` but `room` bytes. */
function fill(room) {
  const fd = openSync(filler, 'w');
  const block = Buffer.alloc(64 * 1024, 0xa5);
  try {
    for (;;) writeSync(fd, block);
  } catch (e) {
    if (e.code !== 'ENOSPC') fail(`filling: ${e.message}`);
  }
  ftruncateSync(fd, Math.max(0, fstatSync(fd).size - room));
  closeSync(fd);
}

const browser = await launch(fail);
const summary = {};
try {
  const { page, problems, acks } = await openDashboard(browser, url);
  const text = (id) => page.locator(`#${id}`).textContent();
  const visible = (id) => page.locator(`#${id}`).isVisible();

  await page.waitForFunction(() => document.getElementById('rec-state').textContent === 'on', null, { timeout: patient(60000) });
  fill(16 * 1024);

  // The recording stops, and the page says why.
  await page.waitForFunction(() => document.getElementById('rec-state').textContent === 'stopped', null, { timeout: patient(120000) });
  if (!(await visible('rec-error'))) fail('the reason is not shown');
  const reason = await text('rec-error');
  if (!reason.includes('No space left on device')) fail(`the reason shown is "${reason}"`);
  if (await visible('rec-download')) fail('the download link still offers the stopped recording');
  summary.recording = reason;

  // A save the disk has no room for: the page says why.
  await page.click('#save-weights');
  await page.waitForSelector('#weights-error:not([hidden])', { timeout: patient(60000) });
  const weights = await text('weights-error');
  if (!weights.includes('No space left on device')) fail(`the checkpoint failure shown is "${weights}"`);
  summary.checkpoint = weights;
  await page.screenshot({ path: screenshot, fullPage: true });

  // With room again, Start records: the badge is on and the notice gone.
  unlinkSync(filler);
  const at = acks.length;
  await page.click('#rec-start');
  await until('the start_recording ack', () => acks.slice(at).some((a) => a.type === 'ack' && a.cmd === 'start_recording'), 60000);
  await page.waitForFunction(() => document.getElementById('rec-state').textContent === 'on', null, { timeout: patient(60000) });
  if (await visible('rec-error')) fail('the failure is still shown while recording again');
  summary.resumed = true;
  if (problems.length) fail(problems.join('; '));
  summary.ok = true;
  console.log(JSON.stringify(summary));
} catch (e) {
  fail(e && e.stack ? e.stack : String(e));
} finally {
  await browser.close();
}
