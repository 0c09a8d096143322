// End-to-end test of the browser viewer: `relume serve` on a free port with a token, Debian's
// chromium (headless, driven by playwright-core), the page playing the bundled recording. It
// checks that a page without the token asks for it and connects once it is entered, that the
// page given the token in its URL fragment opens its streams with tickets (offered as a
// WebSocket subprotocol, out of the URL); and
// that frames arrive with their stage timings and error estimate, that the page's protobuf
// codec (protobuf.js, served by relume) and the server's (prost) agree both ways, that the
// indirect-only view, the quality level and the frame budget change the next frames and what
// the page reports (a level changed mid-stream, a budget the frames report and are lowered to
// hold, a budget the server refuses, the budget removed), that a closed stream reconnects with
// a new ticket and the page's settings, that dropped frames, stream errors and a server that
// goes away are shown; and it takes the README's screenshot.
//
// Run by scripts/test.sh after `cargo test` (which builds the binary). Environment:
// RELUME_BIN (default $CARGO_TARGET_DIR/debug/relume or target/debug/relume), CHROMIUM
// (default /usr/bin/chromium), BLESS=1 to also write docs/images/viewer.png.

import { spawn } from "node:child_process";
import { randomBytes } from "node:crypto";
import { copyFileSync, mkdirSync } from "node:fs";
import path from "node:path";
import { createInterface } from "node:readline";
import { fileURLToPath } from "node:url";

import { chromium } from "playwright-core";

const root = path.resolve(path.dirname(fileURLToPath(import.meta.url)), "../..");
const binary = process.env.RELUME_BIN ?? path.join(process.env.CARGO_TARGET_DIR ?? path.join(root, "target"), "debug", "relume");
const screenshot = path.join(root, "out", "e2e", "viewer.png");
const readmeScreenshot = path.join(root, "docs", "images", "viewer.png");
const WAIT_MS = 60_000;
// The server's bearer token: the page must get it from the user and open streams with tickets.
const TOKEN = randomBytes(18).toString("base64url");
const started = Date.now();

function step(text) {
  console.log(`[${((Date.now() - started) / 1000).toFixed(1)} s] ${text}`);
}

function assert(condition, message) {
  if (!condition) throw new Error(`assertion failed: ${message}`);
}

// How the page's current stream was opened: its URL, the subprotocol the server selected and
// the ticket the page offered beside it.
function streamOpening(page) {
  return page.evaluate(() => {
    const { socket, streamTicket } = window.relumeViewer;
    return { url: socket.url, protocol: socket.protocol, ticket: streamTicket };
  });
}

// A stream opened with a ticket as a subprotocol: none in the URL, `relume.v1` selected, a
// ticket of 75 base64url characters offered (expiry, nonce and MAC: src/service/tickets.rs).
// (The server wants its token, so the frames that arrived on it are the proof that the server
// took the ticket.)
function ticketed({ url, protocol, ticket }) {
  return /\/stream$/.test(url) && protocol === "relume.v1" && /^[A-Za-z0-9_-]{75}$/.test(ticket ?? "");
}

// Starts the server; resolves with its address once it logs "serving".
function startServer() {
  const server = spawn(binary, ["serve", "--addr", "127.0.0.1:0", "--assets", path.join(root, "fixtures")], {
    env: { ...process.env, NO_COLOR: "1", RUST_LOG: process.env.RUST_LOG ?? "info", RELUME_TOKEN: TOKEN },
    stdio: ["ignore", "inherit", "pipe"],
  });
  const log = [];
  const address = new Promise((resolve, reject) => {
    server.on("error", (error) => reject(new Error(`cannot start ${binary}: ${error.message}`)));
    server.on("exit", (code) => reject(new Error(`the server exited (${code}) before serving:\n${log.join("\n")}`)));
    createInterface({ input: server.stderr }).on("line", (line) => {
      log.push(line);
      if (process.env.E2E_SERVER_LOG) console.error(`server: ${line}`);
      const match = line.includes("serving") && line.match(/127\.0\.0\.1:(\d+)/);
      if (match) resolve(`127.0.0.1:${match[1]}`);
    });
  });
  return { server, address, log };
}

async function main() {
  const { server, address, log } = startServer();
  let browser;
  try {
    const addr = await address;
    step(`server on ${addr}`);
    browser = await chromium.launch({
      executablePath: process.env.CHROMIUM ?? "/usr/bin/chromium",
      args: ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "--disable-sync"],
    });

    // The server wants its token: the API refuses a request without it.
    const refused = await fetch(`http://${addr}/v1/recordings`);
    assert(refused.status === 401 && (await refused.json()).error.code === "unauthorized", "the API wants the token");

    // A page opened without the token says so and shows the token field; entered there, the
    // token gets the page its stream through a ticket. (A page of its own: its refused
    // requests are console errors.)
    const asking = await browser.newPage();
    asking.setDefaultTimeout(WAIT_MS);
    await asking.goto(`http://${addr}/?downscale=4`);
    // `window.relumeViewer` exists once viewer.js's module graph (protobuf.js and the descriptor,
    // fetched by proto.js) has run, which can be after `goto`'s load event: `?.` until then, since
    // a predicate that throws fails the wait at once instead of polling.
    await asking.waitForFunction(() => window.relumeViewer?.needsToken);
    assert(await asking.locator("#token-form").isVisible(), "the token field is shown");
    const asked = await asking.locator("#status").textContent();
    assert(asked.includes("token"), `the status asks for the token: ${asked}`);
    await asking.locator("#token").fill(TOKEN);
    await asking.getByRole("button", { name: "Connect" }).click();
    await asking.waitForFunction(() => window.relumeViewer?.framesShown >= 1);
    const askedOpening = await streamOpening(asking);
    assert(ticketed(askedOpening), `the stream opened with a ticket subprotocol: ${JSON.stringify(askedOpening)}`);
    assert(!(await asking.locator("#token-form").isVisible()), "the token field is hidden again");
    await asking.close();
    step("a page without the token asks for it, then streams with a ticket");

    const page = await browser.newPage({ viewport: { width: 1200, height: 800 } });
    const pageErrors = [];
    page.on("pageerror", (error) => pageErrors.push(error.message));
    page.on("console", (message) => { if (message.type() === "error") pageErrors.push(message.text()); });
    page.setDefaultTimeout(WAIT_MS);

    await page.goto(`http://${addr}/?downscale=2#token=${TOKEN}`);
    const viewer = () => page.evaluate(() => {
      const s = window.relumeViewer;
      return { framesShown: s.framesShown, applied: { ...s.applied }, connection: s.connection, errors: [...s.errors],
        scene: s.scene, lastFrame: s.lastFrame && { frameId: s.lastFrame.frameId, width: s.lastFrame.width,
          height: s.lastFrame.height, valCount: s.lastFrame.valCount, stages: s.lastFrame.timings.map((t) => t.stage),
          png: s.lastFrame.png ? Array.from(s.lastFrame.png.subarray(0, 4)) : null,
          quality: s.lastFrame.quality, budgetMs: s.lastFrame.budgetMs, errorEstimate: s.lastFrame.errorEstimate,
          parameters: Object.fromEntries(s.lastFrame.parameters.map((p) => [p.name, p.value])) } };
    });
    const framesAfter = async (n) => {
      await page.waitForFunction((n) => window.relumeViewer?.framesShown >= n, n);
      return viewer();
    };
    const setting = (name) => page.locator(`#settings dd[data-setting="${name}"]`).textContent();
    const text = (id) => page.locator(`#${id}`).textContent();
    // The frames after the one that may have been on the server when a setting was applied.
    const nextFrames = async () => framesAfter((await viewer()).framesShown + 2);
    // What a frame's error estimate shows: "error estimate 3.1 % ± 0.42 % rel RMSE".
    const ERROR_SHOWN = /^error estimate \d[\d.e+-]* % ± \d[\d.e+-]* % rel RMSE$/;

    // Frames arrive, composited, with every stage timed; the status says live.
    let v = await framesAfter(2);
    step(`${v.framesShown} frames, ${v.lastFrame.width}x${v.lastFrame.height}, ${v.lastFrame.valCount} VALs`);
    assert(v.connection === "live", `status live, got ${v.connection}`);
    assert(v.errors.length === 0, `no errors at start: ${v.errors}`);
    const opened = await streamOpening(page);
    assert(ticketed(opened), `the stream opened with a ticket subprotocol: ${JSON.stringify(opened)}`);
    assert(v.lastFrame.width === 320 && v.lastFrame.height === 240, "downscale=2 of 640x480");
    assert(v.lastFrame.png?.join() === "137,80,78,71", "a PNG");
    for (const stage of ["decode", "queue", "rgbd_vals", "gather", "shade", "composite", "encode"]) {
      assert(v.lastFrame.stages.includes(stage), `stage ${stage} in ${v.lastFrame.stages}`);
    }
    assert(await page.locator("#stage-bar > div").count() === v.lastFrame.stages.length, "one bar segment per stage");
    assert(await page.locator("#frame").getAttribute("src"), "the frame is shown");

    // The codec both ways: the page's Control (encoded in JS) was decoded and acknowledged by
    // the server, and the server's RgbdFrame (encoded by prost) decodes in the page.
    // The first controls: the view, glossy, and the scene's level and (no) budget.
    assert(v.applied.component === 1 && v.applied.glossy === true && v.applied.level === 2 && v.applied.budgetMs === 0,
      `the first controls were acknowledged: ${JSON.stringify(v.applied)}`);
    const decoded = await page.evaluate(async (token) => {
      const { decodeEnvelope, encodeControl } = await import("/proto.js");
      const response = await fetch("/v1/recordings/tum_fr1_xyz/frames/5?downscale=8",
        { headers: { authorization: `Bearer ${token}` } });
      const frame = decodeEnvelope(await response.arrayBuffer());
      const control = Array.from(encodeControl({ requestId: 300, quality: { component: 3, format: 1 },
        rgbd: { gridStep: 12 }, render: { occlusion: 2, glossy: false } }));
      const floats = Array.from(encodeControl({ requestId: 0, quality: { component: 1, exposure: 0.5, format: 2 },
        rgbd: { gridStep: 4, radianceScale: 2.5 }, render: { glossy: true } }));
      const library = window.protobuf?.build;
      return { version: frame.version, kind: frame.kind, body: frame.body, width: response.headers.get("x-relume-width"),
        control, floats, library };
    }, TOKEN);
    assert(decoded.version === 1 && decoded.kind === "rgbdFrame", `an RgbdFrame envelope: ${decoded.kind}`);
    assert(decoded.body.frameId === 5 && String(decoded.body.intrinsics.width) === decoded.width
      && decoded.body.intrinsics.height === 60 && Math.abs(decoded.body.intrinsics.fx - 525 / 8) < 1e-3,
      `the frame's id and intrinsics: ${JSON.stringify(decoded.body)}`);
    assert(decoded.library === "light", `protobuf.js's light build, served by relume: ${decoded.library}`);
    // Bytes protoc / prost write for the same Controls (field order, fixed32 float, bool, default
    // values left out unless the field has presence): src/service/wire.rs checks them with prost.
    const expected = [8, 1, 26, 19, 8, 172, 2, 42, 4, 16, 3, 32, 1, 50, 2, 8, 12, 58, 4, 8, 2, 16, 0];
    assert(decoded.control.join() === expected.join(), `Control bytes ${decoded.control}`);
    const expectedFloats = [8, 1, 26, 24, 42, 9, 16, 1, 29, 0, 0, 0, 63, 32, 2, 50, 7, 8, 4, 37, 0, 0, 32, 64, 58, 2, 16, 1];
    assert(decoded.floats.join() === expectedFloats.join(), `Control bytes ${decoded.floats}`);

    // One click to the indirect-only view: acknowledged, and the next frames are not composited.
    await page.getByRole("button", { name: "Indirect only" }).click();
    await page.waitForFunction(() => window.relumeViewer.applied.component === 3);
    v = await viewer();
    v = await framesAfter(v.framesShown + 2);
    assert(!v.lastFrame.stages.includes("composite"), `indirect alone is not composited: ${v.lastFrame.stages}`);
    assert((await setting("view")) === "indirect only", "the settings show the view");
    step("indirect-only view");
    await page.getByRole("button", { name: "Composited" }).click();
    await page.waitForFunction(() => window.relumeViewer.applied.component === 1);

    // The scene's level (balanced) and no budget: each frame says so, with its error estimate.
    v = await nextFrames();
    assert(v.lastFrame.quality === 2 && v.lastFrame.parameters.level === "balanced" && v.lastFrame.budgetMs === 0,
      `a balanced frame without a budget: ${JSON.stringify(v.lastFrame)}`);
    const estimate = v.lastFrame.errorEstimate;
    assert(estimate && Number.isFinite(estimate.relRmse) && estimate.relRmse >= 0 && estimate.spread >= 0 && estimate.pixels > 0,
      `a composited frame has an error estimate: ${JSON.stringify(estimate)}`);
    assert(ERROR_SHOWN.test(await text("frame-error")), `the error estimate is shown: ${await text("frame-error")}`);
    assert((await text("frame-level")) === "ran at balanced" && (await text("frame-budget")) === "no budget",
      `level and budget shown: ${await text("frame-level")} / ${await text("frame-budget")}`);
    assert((await text("frame-parameters")).includes("visibility "), `parameters shown: ${await text("frame-parameters")}`);
    const balancedVals = v.lastFrame.valCount;

    // The level mid-stream: one click, acknowledged, and the next frames run at it and say so.
    await page.getByRole("button", { name: "fast", exact: true }).click();
    await page.waitForFunction(() => window.relumeViewer.applied.level === 1);
    v = await nextFrames();
    assert(v.lastFrame.quality === 1 && v.lastFrame.parameters.level === "fast", `a fast frame: ${JSON.stringify(v.lastFrame)}`);
    assert((await text("frame-level")) === "ran at fast", `the frame's level shown: ${await text("frame-level")}`);
    assert((await setting("quality level")) === "fast", "the settings show the level");
    assert(v.lastFrame.errorEstimate && ERROR_SHOWN.test(await text("frame-error")),
      `the fast frame's error estimate is shown: ${await text("frame-error")}`);
    step(`level balanced -> fast; error estimate ${await text("frame-error")}`);

    // A budget no frame can hold (0.1 ms): the frames report it and the controller lowers their
    // parameters below the level's own (fewer VALs: a coarser grid), which the page shows.
    await page.locator("#budget").fill("0.1");
    await page.getByRole("button", { name: "Set", exact: true }).click();
    await page.waitForFunction(() => window.relumeViewer.applied.budgetMs === 0.1);
    v = await nextFrames();
    assert(Math.abs(v.lastFrame.budgetMs - 0.1) < 1e-6, `the frame reports the budget: ${v.lastFrame.budgetMs}`);
    assert((await text("frame-budget")) === "budget 0.1 ms", `the budget shown: ${await text("frame-budget")}`);
    assert((await setting("frame budget")) === "0.1 ms", "the settings show the budget");
    await page.waitForFunction(() => Number(window.relumeViewer.lastFrame.parameters.find((p) => p.name === "vals_step")?.value) >= 2);
    v = await viewer();
    const lowered = await text("frame-level");
    assert(lowered === "ran below fast, lowered by the budget", `the lowered frame shown: ${lowered}`);
    assert(v.lastFrame.valCount < balancedVals / 2, `vals_step ${v.lastFrame.parameters.vals_step}: fewer VALs, ${balancedVals} -> ${v.lastFrame.valCount}`);
    step(`budget 0.1 ms: ${balancedVals} -> ${v.lastFrame.valCount} VALs, ${await text("frame-parameters")}`);

    // The budget removed (empty field): the frames report none and run at the level again.
    await page.locator("#budget").fill("");
    await page.getByRole("button", { name: "Set", exact: true }).click();
    await page.waitForFunction(() => window.relumeViewer.applied.budgetMs === 0);
    v = await nextFrames();
    assert(v.lastFrame.budgetMs === 0 && v.lastFrame.parameters.vals_step === "1" && v.lastFrame.quality === 1,
      `no budget, the level's parameters: ${JSON.stringify(v.lastFrame)}`);
    assert((await text("frame-budget")) === "no budget" && (await text("frame-level")) === "ran at fast",
      `shown: ${await text("frame-budget")} / ${await text("frame-level")}`);
    step("budget removed");

    // Glossy: acknowledged, frames keep coming.
    await page.locator("#glossy").fill("0");
    await page.waitForFunction(() => window.relumeViewer.applied.glossy === false);
    v = await framesAfter((await viewer()).framesShown + 1);
    assert((await setting("glossy")).startsWith("off"), "glossy off reported");

    // Real time: frames sent at 30 fps, faster than lavapipe renders them; the server drops
    // the ones it cannot keep up with and the page shows the count. (A burst of one frame sent
    // five times makes sure of drops on any machine: the newest waiting frame wins.)
    await page.locator("#realtime").check();
    await page.evaluate(async (token) => {
      const response = await fetch("/v1/recordings/tum_fr1_xyz/frames/0?downscale=2",
        { headers: { authorization: `Bearer ${token}` } });
      const bytes = new Uint8Array(await response.arrayBuffer());
      for (let i = 0; i < 5; i++) window.relumeViewer.socket.send(bytes);
    }, TOKEN);
    await page.waitForFunction(() => window.relumeViewer.droppedFrames > 0);
    v = await framesAfter((await viewer()).framesShown + 1);
    const dropped = await page.locator("#dropped").textContent();
    assert(/dropped frames: [1-9]/.test(dropped), `dropped frames shown: ${dropped}`);
    step(dropped);

    // The README's picture: composited, level fast, real time (before the errors below).
    mkdirSync(path.dirname(screenshot), { recursive: true });
    await page.screenshot({ path: screenshot });
    if (process.env.BLESS) {
      mkdirSync(path.dirname(readmeScreenshot), { recursive: true });
      copyFileSync(screenshot, readmeScreenshot);
      step(`screenshot written to ${path.relative(root, readmeScreenshot)}`);
    }

    // A budget the server refuses: its Error, naming the field, is listed and the field goes
    // back to the budget in effect (none).
    await page.locator("#budget").fill("fast please");
    await page.getByRole("button", { name: "Set", exact: true }).click();
    await page.waitForFunction(() => window.relumeViewer.errors.some((e) => e.includes("control.render.budget_ms")));
    assert((await page.locator("#budget").inputValue()) === "", `the field shows the budget in effect: ${await page.locator("#budget").inputValue()}`);
    assert((await setting("frame budget")) === "none", "the budget in effect is unchanged");
    v = await nextFrames();
    assert(v.lastFrame.budgetMs === 0, `the frames still have no budget: ${v.lastFrame.budgetMs}`);
    await page.evaluate(() => { window.relumeViewer.errors.length = 0; });

    // A stream that closes: the status says so; a click reconnects, on a new scene and a stream
    // opened with a new ticket, with the page's level and glossy setting sent again.
    const oldScene = v.scene;
    await page.evaluate(() => window.relumeViewer.socket.close(4000, "closed by the test"));
    await page.waitForFunction(() => window.relumeViewer.connection === "closed");
    assert((await text("status")).includes("disconnected"), `closed status: ${await text("status")}`);
    await page.locator("#status").click();
    await page.waitForFunction((id) => window.relumeViewer.scene?.id !== id && window.relumeViewer.connection === "live"
      && window.relumeViewer.applied.level === 1 && window.relumeViewer.applied.glossy === false, oldScene.id);
    v = await nextFrames();
    assert(v.lastFrame.quality === 1, `the reconnected stream runs at the page's level: ${v.lastFrame.quality}`);
    const reopened = await streamOpening(page);
    assert(ticketed(reopened) && reopened.ticket !== opened.ticket, `a new ticket: ${JSON.stringify(reopened)}`);
    await page.evaluate(() => { window.relumeViewer.errors.length = 0; });
    step("reconnected");

    // A stream error is shown, not swallowed: a message that is not an Envelope.
    await page.evaluate(() => window.relumeViewer.socket.send(new Uint8Array([0xff, 0xff, 0xff])));
    await page.waitForFunction(() => window.relumeViewer.errors.some((e) => e.includes("MALFORMED")));
    assert((await page.locator("#log li.error").first().textContent()).includes("MALFORMED"), "the error is listed");
    assert(pageErrors.length === 0, `no page errors: ${pageErrors}`);

    // The server goes away: the page says so.
    server.kill("SIGTERM");
    await page.waitForFunction(() => window.relumeViewer.connection === "closed");
    const status = await page.locator("#status").textContent();
    assert(status.includes("disconnected"), `status after the server stopped: ${status}`);
    step(`server gone: "${status}"`);
    step("viewer end-to-end test passed");
  } catch (error) {
    console.error(`viewer end-to-end test FAILED: ${error.stack ?? error}`);
    console.error(`server log (last 40 lines):\n${log.slice(-40).join("\n")}`);
    process.exitCode = 1;
  } finally {
    await browser?.close();
    if (server.exitCode === null) server.kill("SIGTERM");
  }
}

const watchdog = setTimeout(() => {
  console.error("viewer end-to-end test FAILED: over 3 minutes");
  process.exit(1);
}, 180_000);
await main();
clearTimeout(watchdog);
