// Debian's chromium, headless, with WebGL from SwiftShader (no GPU), as the browser checks
// (render_check.mjs, terrain_check.mjs) drive it through playwright-core.
export const CHROMIUM_ARGS = [
  '--headless',
  '--no-sandbox',
  '--use-angle=swiftshader',
  '--enable-unsafe-swiftshader',
  '--ignore-gpu-blocklist',
  '--disable-background-networking',
  '--disable-component-update',
  '--disable-dev-shm-usage',
  '--no-first-run',
];

// A persistent context in `userDataDir` (a fresh temporary directory) at width x height.
export function launchChromium(chromium, { executablePath, userDataDir, width, height }) {
  return chromium.launchPersistentContext(userDataDir, {
    executablePath,
    headless: true,
    chromiumSandbox: false,
    args: CHROMIUM_ARGS,
    viewport: { width, height },
    deviceScaleFactor: 1,
    timeout: 60000,
  });
}
