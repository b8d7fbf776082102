// Headless-Chromium test (tests/test_web.py): load the built site from a local server, check it runs
// without console errors, take screenshots at simulated 0 s and 5 s, press a number key and read the
// command the page shows; measure load time and frame rate.
//   node browser.mjs --url http://127.0.0.1:PORT/ --out DIR [--chromium /usr/bin/chromium] [--key 2]
//     [--query '?quality=high'] [--viewport 1280x720]
// Writes DIR/result.json, DIR/page_0s.png, DIR/page_5s.png.
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { pathToFileURL } from 'node:url';
import { WEB, args } from './common.mjs';

const a = args();
const out = a.out;
fs.mkdirSync(out, { recursive: true });
const { chromium } = await import(pathToFileURL(path.join(WEB, 'node_modules/playwright-core/index.mjs')).href);
const userDataDir = fs.mkdtempSync(path.join(os.tmpdir(), 'charctl-chromium-'));
const flags = [
  '--headless',
  '--no-sandbox',
  '--disable-gpu',
  '--disable-quic',
  '--no-first-run',
  '--disable-background-networking',
  '--disable-component-update',
  '--disable-sync',
];
const result = { console: [], errors: [], requests: [] };
const t0 = Date.now();
const context = await chromium.launchPersistentContext(userDataDir, {
  executablePath: a.chromium || '/usr/bin/chromium',
  headless: true,
  args: flags,
  viewport: { width: Number((a.viewport || '1024x640').split('x')[0]), height: Number((a.viewport || '1024x640').split('x')[1]) },
});
const wait = (ms) => new Promise((r) => setTimeout(r, ms));
try {
  const page = context.pages()[0] || (await context.newPage());
  page.on('console', (m) => {
    result.console.push(`${m.type()}: ${m.text()}`);
    if (m.type() === 'error') result.errors.push(m.text());
  });
  page.on('pageerror', (e) => result.errors.push(`pageerror: ${e.message}`));
  page.on('request', (r) => result.requests.push(r.url()));
  page.on('requestfailed', (r) => result.errors.push(`request failed: ${r.url()} ${r.failure()?.errorText}`));
  // the page starts paused (?paused=1): the first screenshot is the start state at 0 s
  const query = a.query ? `${a.query}&paused=1` : '?paused=1';
  const tNav = Date.now();
  await page.goto(a.url + query, { waitUntil: 'load' });
  await page.waitForFunction(() => window.charctlDemo && (window.charctlDemo.ready || window.charctlDemo.error), null, {
    timeout: 90000,
  });
  result.load_wall_ms = Date.now() - tNav;
  result.load_ms = await page.evaluate(() => window.charctlDemo.loadMs);
  result.page_error = await page.evaluate(() => window.charctlDemo.error);
  if (!result.page_error) {
    const status = () => page.evaluate(() => window.charctlDemo.status());
    await page.waitForFunction(() => window.charctlDemo.frames >= 3, null, { timeout: 30000 });
    await wait(500);
    result.status_0 = await status(); // still paused: time 0
    result.command_0 = await page.textContent('#command');
    result.reference_0 = await page.textContent('#reference');
    await page.screenshot({ path: path.join(out, 'page_0s.png') });
    // the simulation thread pauses itself at 5 s for the second screenshot (taking one can outlast a
    // second of simulation with software WebGL); Space (the page's pause key) starts and resumes it
    await page.evaluate(() => window.charctlDemo.worker.postMessage({ type: 'pause_at', time: 5.0 }));
    await page.keyboard.press(' ');
    const tRun = Date.now();
    await page.waitForFunction(() => !window.charctlDemo.status().paused, null, { timeout: 30000, polling: 20 });
    await page.waitForFunction(() => window.charctlDemo.status().paused, null, { timeout: 120000, polling: 20 });
    result.run_wall_s = (Date.now() - tRun) / 1000;
    await wait(300);
    result.status_5 = await status();
    await page.screenshot({ path: path.join(out, 'page_5s.png') });
    await page.keyboard.press(' ');
    await page.waitForFunction(() => !window.charctlDemo.status().paused, null, { timeout: 30000, polling: 20 });
    // frame rate and real-time factor over 3 s of wall time
    const probe = () => page.evaluate(() => [window.charctlDemo.frames, window.charctlDemo.status().time, performance.now()]);
    const f0 = await probe();
    await wait(3000);
    const f1 = await probe();
    result.fps = ((f1[0] - f0[0]) * 1000) / (f1[2] - f0[2]);
    result.real_time_factor = ((f1[1] - f0[1]) * 1000) / (f1[2] - f0[2]);
    const s3 = await status();
    result.step_ms = s3.stepMsMedian;
    result.sim_real_time_factor = s3.simRtf; // measured in the simulation thread over its last 2 s
    result.render_ms = await page.evaluate(() => {
      const s = window.charctlDemo.renderMs.slice().sort((x, y) => x - y);
      return s.length ? s[Math.floor(s.length / 2)] : null;
    });
    // a number key switches the command the page shows
    const key = a.key || '2';
    await page.keyboard.press(key);
    await page.waitForFunction((k) => {
      const d = window.charctlDemo;
      const skill = d.meta.skills.find((s) => s.key === k);
      return document.getElementById('command').textContent === skill.name;
    }, key, { timeout: 10000 });
    result.command_after_key = await page.textContent('#command');
    result.status_key = await status();
    await wait(2500);
    result.status_after_switch = await status();
    await page.screenshot({ path: path.join(out, 'page_switch.png') });
  }
} catch (e) {
  result.errors.push(`test: ${e.message}`);
} finally {
  result.total_wall_s = (Date.now() - t0) / 1000;
  await context.close();
  fs.rmSync(userDataDir, { recursive: true, force: true });
  fs.writeFileSync(path.join(out, 'result.json'), JSON.stringify(result, null, 1));
}
