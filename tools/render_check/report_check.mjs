#!/usr/bin/env node
// Opens a terratiles OUTDIR/report.html in headless Debian chromium and checks that it is
// self-contained and sound: no request leaves the page (every request but the file itself and
// data: URIs counts, whatever its scheme), no console error or page error, at least one
// inline <svg> plot per plot in the page, two map images per map in report.json, each of them
// decoded by the browser. Writes a full-page screenshot.
//
//   node tools/render_check/report_check.mjs OUTDIR --screenshot FILE [--chromium PATH]
//
// Exit 0 when sound, 1 with the reasons on stderr, 2 on bad usage or a missing browser.
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { pathToFileURL } from 'node:url';

const args = process.argv.slice(2);
let outDir = null;
let screenshot = null;
let chromiumPath = process.env.CHROMIUM || '/usr/bin/chromium';
for (let i = 0; i < args.length; i++) {
  if (args[i] === '--screenshot') screenshot = args[++i];
  else if (args[i] === '--chromium') chromiumPath = args[++i];
  else if (!outDir) outDir = args[i];
  else {
    process.stderr.write(`report_check: unexpected argument ${args[i]}\n`);
    process.exit(2);
  }
}
if (!outDir || !screenshot) {
  process.stderr.write('usage: report_check.mjs OUTDIR --screenshot FILE [--chromium PATH]\n');
  process.exit(2);
}
const htmlFile = path.resolve(outDir, 'report.html');
const report = JSON.parse(fs.readFileSync(path.resolve(outDir, 'report.json'), 'utf8'));
if (!fs.existsSync(chromiumPath)) {
  process.stderr.write(`report_check: browser not found at ${chromiumPath} (apt-get install -y chromium)\n`);
  process.exit(2);
}
const { chromium } = await import('playwright-core');
const userDataDir = fs.mkdtempSync(path.join(os.tmpdir(), 'tt-report-check-'));
const reasons = [];
const pageUrl = pathToFileURL(htmlFile).href;
let context;
try {
  context = await chromium.launchPersistentContext(userDataDir, {
    executablePath: chromiumPath,
    headless: true,
    chromiumSandbox: false,
    args: ['--headless', '--no-sandbox', '--disable-background-networking', '--disable-component-update',
           '--disable-dev-shm-usage', '--no-first-run'],
    viewport: { width: 1280, height: 900 },
    deviceScaleFactor: 1,
  });
  const page = context.pages()[0] || (await context.newPage());
  page.on('request', (request) => {
    const url = request.url();
    if (url !== pageUrl && !url.startsWith('data:')) reasons.push(`request to ${url}`);
  });
  page.on('console', (message) => {
    if (message.type() === 'error') reasons.push(`console error: ${message.text()}`);
  });
  page.on('pageerror', (error) => reasons.push(`page error: ${error.message}`));
  await page.goto(pageUrl, { waitUntil: 'load' });
  const facts = await page.evaluate(() => ({
    svgs: document.querySelectorAll('svg').length,
    images: [...document.images].map((image) => ({ src: image.src.slice(0, 22), ok: image.complete && image.naturalWidth > 0 })),
    title: document.title,
  }));
  const mapCount = (report.maps || []).length;
  if (facts.svgs < 3) reasons.push(`${facts.svgs} inline svg elements; expected the plots (at least 3)`);
  const mapImages = facts.images.filter((image) => image.src.startsWith('data:image/png'));
  if (mapImages.length !== 2 * mapCount) {
    reasons.push(`${mapImages.length} map images; report.json has ${mapCount} maps (2 images each)`);
  }
  const broken = facts.images.filter((image) => !image.ok);
  if (broken.length) reasons.push(`${broken.length} images the browser could not decode`);
  await page.screenshot({ path: screenshot, fullPage: true });
  process.stdout.write(`report_check: ${facts.title}: ${facts.svgs} svg, ${mapImages.length} map images, screenshot ${screenshot}\n`);
} catch (error) {
  reasons.push(`check aborted: ${error.message}`);
} finally {
  if (context) await context.close().catch(() => {});
  fs.rmSync(userDataDir, { recursive: true, force: true });
}
if (reasons.length) {
  process.stderr.write(`report_check: FAILED\n${reasons.map((r) => `  ${r}`).join('\n')}\n`);
  process.exit(1);
}
