// Drives the browser viewer (`radiosity view SCENE --web DIR`) in headless Chromium (WebGL2 through SwiftShader).
// Usage: node viewer.mjs URL OUT_DIR COLOUR MATERIAL CHANNEL REFLECTANCE
// Loads the page, waits until the solver has converged, saves the canvas as OUT_DIR/viewer-before.png (and the
// whole page as OUT_DIR/viewer-page.png); then changes the controls as a user does, through input events on the
// page's own elements, waiting after each until converged again: light group 0's colour input to COLOUR
// ("#rrggbb"; phase "colour"), the reflectance slider of MATERIAL's channel CHANNEL to REFLECTANCE (phase
// "reflectance"), light group 0's intensity slider to 0 (phase "after"). Saves the canvas of each phase as
// OUT_DIR/viewer-PHASE.png, and prints one JSON object: the console errors, per phase the canvas's size and mean
// 8-bit value per channel, the solver's radiosity, its error against the exact answer, the intensities and
// reflectances it was given, and every frame's budget and units used.
// CHROMIUM selects the browser binary (default /usr/bin/chromium).
import { writeFileSync } from "node:fs";
import { join } from "node:path";
import puppeteer from "puppeteer-core";

const [url, outDir, colour, material, channel, rho] = process.argv.slice(2);
if (!url || !outDir || !colour || !material || !channel || !rho) {
    console.error("usage: node viewer.mjs URL OUT_DIR COLOUR MATERIAL CHANNEL REFLECTANCE");
    process.exit(2);
}
const browser = await puppeteer.launch({
    executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
    headless: true,
    args: ["--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist"],
});
const errors = [];
try {
    const page = await browser.newPage();
    page.on("console", (m) => {
        if (m.type() === "error") {
            errors.push(`console: ${m.text()}`);
        }
    });
    page.on("pageerror", (e) => errors.push(`page error: ${e.message}`));
    page.on("requestfailed", (r) => errors.push(`request failed: ${r.url()}`));
    await page.setViewport({ width: 1000, height: 820, deviceScaleFactor: 1 });
    await page.goto(url, { waitUntil: "load" });

    // Waits until the page has run more than one frame past `frames` and converged (or failed).
    const converged = async (frames) => {
        await page.waitForFunction(
            (f) => window.viewer?.error !== undefined || (window.viewer?.ready && window.viewer.stats.frames > f + 1
                && window.viewer.converged),
            { timeout: 120000, polling: 100 },
            frames,
        );
        const error = await page.evaluate(() => window.viewer.error);
        if (error !== undefined) {
            throw new Error(`the page failed: ${error}`);
        }
    };
    // The canvas's pixels (saved as PNG) and mean 8-bit value per channel, with the page's state, all read in
    // one task: the canvas shows the frame whose radiosity is read back.
    const snapshot = async (name) => {
        const { dataUrl, ...state } = await page.evaluate(() => {
            const c = document.getElementById("view");
            const copy = document.createElement("canvas");
            copy.width = c.width;
            copy.height = c.height;
            const ctx = copy.getContext("2d");
            ctx.drawImage(c, 0, 0);
            const d = ctx.getImageData(0, 0, c.width, c.height).data;
            const sum = [0, 0, 0];
            for (let k = 0; k < d.length; k += 4) {
                sum[0] += d[k];
                sum[1] += d[k + 1];
                sum[2] += d[k + 2];
            }
            return {
                dataUrl: c.toDataURL("image/png"),
                mean: sum.map((s) => s / (d.length / 4)),
                width: c.width,
                height: c.height,
                frames: window.viewer.stats.frames,
                intensity: window.viewer.intensity(0),
                reflectance: Array.from(document.querySelectorAll("input[data-material][data-channel='0']"),
                    (e) => window.viewer.reflectance(Number(e.dataset.material))),
                work: window.viewer.stats.workSinceChange,
                errorVsExact: window.viewer.error_vs_exact,
                radiosity: window.viewer.radiosity(),
            };
        });
        writeFileSync(join(outDir, name), Buffer.from(dataUrl.split(",")[1], "base64"));
        return state;
    };

    await converged(0);
    const before = await snapshot("viewer-before.png");
    await page.screenshot({ path: join(outDir, "viewer-page.png") });
    // Sets an input element's value and fires its input event, as a user's edit does, and returns the frame
    // count read in the same task: the next frame applies the change, so convergence counts only after the frame
    // after that.
    const change = (selector, value) => page.evaluate((s, v) => {
        const input = document.querySelector(s);
        if (!input) {
            throw new Error(`no element ${s}`);
        }
        input.value = v;
        input.dispatchEvent(new Event("input", { bubbles: true }));
        return window.viewer.stats.frames;
    }, selector, value);
    await converged(await change("input[data-group-colour='0']", colour));
    const colourPhase = await snapshot("viewer-colour.png");
    await converged(await change(`input[data-material='${material}'][data-channel='${channel}']`, rho));
    const reflectance = await snapshot("viewer-reflectance.png");
    await converged(await change("input[data-group='0']", "0"));
    const after = await snapshot("viewer-after.png");
    const frames = await page.evaluate(() => window.viewer.frames);
    const stats = await page.evaluate(() => window.viewer.stats);
    console.log(JSON.stringify({ errors, before, colour: colourPhase, reflectance, after, frames, stats }));
} finally {
    await browser.close();
}
