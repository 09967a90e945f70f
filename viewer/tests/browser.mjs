// Shared by the browser tests: headless Debian Chromium, and `talus view DIR --port 0` started
// in its own process group with the URL it prints.

import { spawn } from 'node:child_process';
import { chromium } from 'playwright-core';

const CHROMIUM = process.env.CHROMIUM || '/usr/bin/chromium';

/** A headless Chromium context with a 1400 × 850 viewport, its profile in `profile`. */
export function launchBrowser(profile) {
  return chromium.launchPersistentContext(profile, {
    executablePath: CHROMIUM,
    headless: true,
    viewport: { width: 1400, height: 850 },
    deviceScaleFactor: 1,
    args: [
      '--headless', '--no-sandbox', '--disable-gpu', '--enable-unsafe-swiftshader',
      '--disable-background-networking', '--disable-component-update', '--disable-sync',
      '--no-first-run',
    ],
  });
}

/** Start `talus view DIR --port 0` (binary `talus`, in `cwd`): { child, url } once it listens. */
export async function serveTalus(talus, dir, cwd) {
  const child = spawn(talus, ['view', dir, '--port', '0'], { cwd, detached: true, stdio: ['ignore', 'pipe', 'pipe'] });
  let stderr = '';
  child.stderr.on('data', (d) => { stderr += d; });
  const url = await new Promise((ok, fail) => {
    let out = '';
    const timer = setTimeout(() => fail(new Error(`talus view printed no URL\n${stderr}`)), 60_000);
    child.stdout.on('data', (d) => {
      out += d;
      const m = /http:\/\/[^\s]+/.exec(out);
      if (m) { clearTimeout(timer); ok(m[0]); }
    });
    child.on('exit', (code) => { clearTimeout(timer); fail(new Error(`talus view exited (${code}):\n${stderr}`)); });
  });
  return { child, url };
}

/** Stop a server started by [`serveTalus`] (its whole process group). */
export function stopServer(child) {
  if (!child?.pid) return;
  try { process.kill(-child.pid, 'SIGTERM'); } catch { /* already gone */ }
}

/**
 * Serve the result `dir` with `talus view` and open it in a fresh browser whose profile lives
 * in `tmp`: { server, context, page } once the viewer is ready (or has failed).
 */
export async function openResult(talus, dir, cwd, tmp) {
  const { child, url } = await serveTalus(talus, dir, cwd);
  const context = await launchBrowser(`${tmp}/profile`);
  const page = context.pages()[0] || (await context.newPage());
  await page.goto(url);
  await page.waitForFunction(() => window.__talus && (window.__talus.ready || window.__talus.error), null, { timeout: 120_000 });
  return { server: child, context, page };
}
