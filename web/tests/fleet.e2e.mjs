// The fleet page in headless Debian Chromium driven by playwright-core.
//
//   FLEET_TOKEN=<alpha's token> node web/tests/fleet.e2e.mjs <fleet URL> <screenshot.png>
//
// Run by tests/e2e/fleet.rs against a `pavlov fleet` that sees two robots on Zenoh: `alpha` (commands on,
// already switched to manual mode by the test) and `beta` (commands off), plus a hostile status published
// for a robot `mallory` whose dashboard URL is `javascript:…`. The page must list the robots with their
// live ticks and modes, link each real robot's dashboard and never a javascript: URL, send a command with
// the typed token that changes alpha's mode in the table, and show the refusal of a wrong token (alpha's
// e-stop stays off). Saves a screenshot, prints a JSON summary, exits non-zero on any failure.

import { harness, launch, patient } from './browser.mjs';

const { screenshot, url, fail } = harness('fleet.e2e');
const token = process.env.FLEET_TOKEN;
if (!token) fail('FLEET_TOKEN (alpha\'s token) is not set');
const browser = await launch(fail);
const summary = {};
try {
  const page = await browser.newPage({ viewport: { width: 1400, height: 520 } });
  const problems = [];
  page.on('pageerror', (e) => problems.push(`page error: ${e.message}`));
  // The refused command's 403 is logged by Chromium as a failed resource; it is the answer this test
  // expects (checked below), not a problem of the page.
  page.on('console', (m) => {
    if (m.type() !== 'error') return;
    if (/status of 403/.test(m.text()) && m.location().url.includes('/api/command/')) return;
    problems.push(`console error: ${m.text()} (${m.location().url})`);
  });
  await page.goto(url, { waitUntil: 'load' });

  // One row per robot: [robot, mode, e-stop, link, health, tick, …, dashboard].
  const rows = () => page.$$eval('#robots tr', (trs) => trs.map((tr) =>
    Array.from(tr.children).map((td) => td.textContent)));
  const rowOf = async (name) => (await rows()).find((r) => r[0] === name);
  const waitRow = async (what, name, ok) => {
    const end = Date.now() + 20000;
    let r;
    while (Date.now() < end) {
      r = await rowOf(name);
      if (r && ok(r)) return r;
      await page.waitForTimeout(200);
    }
    fail(`timed out waiting for ${what}: ${JSON.stringify(r)}`);
  };
  const alpha0 = await waitRow('alpha in manual mode, ticking', 'alpha', (r) => r[1] === 'manual' && Number(r[5]) > 0);
  const beta0 = await waitRow('beta in Pavlovian mode, ticking', 'beta', (r) => r[1] === 'pavlovian' && Number(r[5]) > 0);
  const mallory0 = await waitRow('mallory\'s hostile status', 'mallory', () => true);
  // Presence from liveliness tokens: the robots are alive; mallory never declared one.
  if (!alpha0[10].startsWith('alive')) fail(`alpha not shown alive: ${alpha0[10]}`);
  if (!mallory0[10].startsWith('unknown')) fail(`mallory not shown unknown: ${mallory0[10]}`);
  // The tick column moves: the table is live.
  await page.waitForTimeout(1500);
  const alpha1 = await rowOf('alpha');
  if (!(Number(alpha1[5]) > Number(alpha0[5]))) fail(`alpha's tick did not move: ${alpha0[5]} → ${alpha1[5]}`);
  summary.ticks = { alpha: [Number(alpha0[5]), Number(alpha1[5])], beta: Number(beta0[5]) };

  // Dashboard links: http(s) for the real robots, none at all for mallory.
  const links = await page.$$eval('#robots tr', (trs) => trs.map((tr) => {
    const a = tr.querySelector('a');
    return [tr.children[0].textContent, a ? a.getAttribute('href') : null];
  }));
  for (const [name, href] of links) {
    if (name === 'mallory') {
      if (href !== null) fail(`mallory's row links ${href}`);
    } else if (!/^http:\/\/127\.0\.0\.1:\d+\/?$/.test(href || '')) {
      fail(`${name}'s dashboard link is ${href}`);
    }
  }
  const anyScript = await page.$$eval('a', (as) => as.some((a) => /^\s*javascript:/i.test(a.getAttribute('href') || '')));
  if (anyScript) fail('the page links a javascript: URL');
  summary.links = Object.fromEntries(links);

  // A command with alpha's token: alpha becomes reactive, in its answer and in the table.
  await page.selectOption('#robot', 'alpha');
  await page.selectOption('#cmd', '{"cmd":"set_mode","mode":"reactive"}');
  await page.fill('#token', token);
  await page.click('#command button');
  await page.waitForFunction(() => document.getElementById('answer').textContent.length > 0, null, { timeout: patient(15000) });
  const applied = await page.locator('#answer').textContent();
  if (!applied.startsWith('200 ') || !applied.includes('"reactive"')) fail(`the command's answer: ${applied}`);
  await waitRow('alpha reactive in the table', 'alpha', (r) => r[1] === 'reactive');
  summary.applied = applied;

  // A wrong token: refused with 403, shown; alpha's e-stop stays off.
  await page.evaluate(() => { document.getElementById('answer').textContent = ''; });
  await page.selectOption('#cmd', '{"cmd":"estop"}');
  await page.fill('#token', 'not-the-token');
  await page.click('#command button');
  await page.waitForFunction(() => document.getElementById('answer').textContent.length > 0, null, { timeout: patient(15000) });
  const refused = await page.locator('#answer').textContent();
  if (!refused.startsWith('403 ') || !refused.includes('the token is wrong')) fail(`the wrong token's answer: ${refused}`);
  await page.waitForTimeout(600);
  const alpha2 = await rowOf('alpha');
  if (alpha2[2] !== 'off') fail(`alpha's e-stop shows ${alpha2[2]} after a refused e-stop`);
  summary.refused = refused;

  await page.screenshot({ path: screenshot, fullPage: true });
  if (problems.length) fail(problems.join('; '));
  summary.ok = true;
  console.log(JSON.stringify(summary));
} finally {
  await browser.close();
}
