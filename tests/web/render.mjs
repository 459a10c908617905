// Renders a page with three.js in headless Chromium (WebGL through SwiftShader) and saves the canvas as PNG.
// Usage: node render.mjs URL OUT.png WIDTH HEIGHT
// The page sets `window.renderDone = true` (or `window.renderError = "..."`) when it has drawn its frame.
// CHROMIUM selects the browser binary (default /usr/bin/chromium).
import { writeFileSync } from "node:fs";
import puppeteer from "puppeteer-core";

const [url, out, width, height] = process.argv.slice(2);
if (!url || !out || !width || !height) {
    console.error("usage: node render.mjs URL OUT.png WIDTH HEIGHT");
    process.exit(2);
}
const browser = await puppeteer.launch({
    executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
    headless: true,
    args: [
        "--no-sandbox", // runs as root in CI
        "--use-angle=swiftshader",
        "--enable-unsafe-swiftshader",
        "--ignore-gpu-blocklist",
    ],
});
try {
    const page = await browser.newPage();
    page.on("console", (m) => console.error(`page: ${m.text()}`));
    page.on("pageerror", (e) => console.error(`page error: ${e.message}`));
    await page.setViewport({ width: Number(width), height: Number(height), deviceScaleFactor: 1 });
    await page.goto(url, { waitUntil: "load" });
    await page.waitForFunction("window.renderDone === true || window.renderError !== undefined", {
        timeout: 60000,
    });
    const error = await page.evaluate("window.renderError");
    if (error !== undefined) {
        throw new Error(`the page failed: ${error}`);
    }
    // The canvas's own pixels (preserveDrawingBuffer), not a screenshot of the window around it.
    const dataUrl = await page.evaluate("document.querySelector('canvas').toDataURL('image/png')");
    writeFileSync(out, Buffer.from(dataUrl.split(",")[1], "base64"));
} finally {
    await browser.close();
}
