// The relume viewer: creates a scene, opens its WebSocket stream and plays a server-side
// recording on it, one frame after the other (or at the recording's rate, letting the server
// drop frames), showing each relit frame, its per-stage timings, its error estimate, the quality
// level and parameters it ran at, and the settings in effect.
// Everything goes through the public API: POST /v1/scenes, GET /v1/recordings/..., and the
// protobuf stream of proto/relume.proto (encoded by ./proto.js).
//
// URL parameters (all optional): scene=<URL of a scene file> (default /default-scene.json),
// recording=<name>, downscale=<1..8>, quality=<fast|balanced|accurate|reference> and
// budget_ms=<ms> (default: the scene's settings.quality and settings.budget_ms).
//
// A server run with --token: the page takes the token from the URL fragment (#token=<token>,
// which the browser never sends to the server) or, after a 401, from the field it then shows.
// It sends it as `Authorization: Bearer` on /v1 requests and, since a browser cannot set a
// WebSocket's headers, opens each stream with a single-use ticket (POST /v1/tickets) offered
// as the subprotocol `relume.ticket.<ticket>` beside `relume.v1`, which keeps it out of URLs.

import { Component, ImageFormat, QualityLevel, decodeEnvelope, encodeControl } from "./proto.js";

const params = new URLSearchParams(location.search);
const fragment = new URLSearchParams(location.hash.slice(1));
const $ = (id) => document.getElementById(id);
const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));
const COMPONENT_NAMES = { [Component.FULL]: "composited", [Component.DIRECT]: "direct only", [Component.INDIRECT]: "indirect only" };
const FRAME_ANSWER_TIMEOUT_MS = 60_000;
// Level names by number ({1: "fast", ...}), as a scene file writes them.
const LEVEL_NAMES = Object.fromEntries(Object.entries(QualityLevel).filter(([, v]) => v !== 0)
  .map(([name, v]) => [v, name.toLowerCase()]));
const levelNumber = (name) => QualityLevel[String(name).toUpperCase()] || undefined;
// A float32 from the wire (0.1 arrives as 0.10000000149) as the number the user typed.
const formatMs = (ms) => String(Number(ms.toPrecision(6)));
const formatBudget = (ms) => (ms === undefined ? undefined : ms ? `${formatMs(ms)} ms` : "none");
// A relative error as a percentage, two significant digits.
const percent = (x) => `${Number((100 * x).toPrecision(2))} %`;

// Everything the page knows; exposed as `window.relumeViewer` for tests and the curious.
const state = {
  // What the controls ask for.
  wanted: {
    component: Component.FULL,
    // The quality level (a QualityLevel number) and the frame budget in ms (0: none); both
    // start at the URL's or, once the scene is created, the scene's.
    level: params.has("quality") ? levelNumber(params.get("quality")) : undefined,
    budgetMs: params.has("budget_ms") ? Number(params.get("budget_ms")) : undefined,
    glossy: true,
    downscale: Number(params.get("downscale") ?? 2),
  },
  // What the server acknowledged on the current stream (SettingsAck), and requests in flight.
  applied: {},
  pending: new Map(),
  requestId: 0,
  sceneText: null,
  scene: null, // SceneInfo of the scene in use
  recording: null, // RecordingInfo being played
  socket: null,
  streamTicket: null, // the (spent) ticket the current stream was opened with, if any
  generation: 0, // bumped on every (re)connection: older playback loops stop
  playing: true,
  realtime: false,
  nextIndex: 0,
  sent: new Map(), // frame id -> {sentAt, frame}
  waiter: null, // {frameId, resolve} of the frame the paced loop waits for
  framesShown: 0,
  lastFrame: null,
  droppedFrames: 0,
  errors: [],
  connection: "connecting",
  token: fragment.get("token") || null, // the server's bearer token, if it wants one
  needsToken: false, // a /v1 request was refused with 401
};
window.relumeViewer = state;

// ----------------------------------------------------------------------------------------
// Display

function setStatus(kind, text) {
  state.connection = kind;
  const status = $("status");
  status.className = `status ${kind}`;
  status.dataset.state = kind;
  status.textContent = text;
}

function log(kind, text) {
  if (kind === "error") state.errors.push(text);
  const item = document.createElement("li");
  item.className = kind;
  item.textContent = `${new Date().toLocaleTimeString()} ${text}`;
  const list = $("log");
  list.prepend(item);
  while (list.children.length > 50) list.lastChild.remove();
}

const STAGE_COLOURS = ["#f0b44c", "#5ca8f0", "#6cc788", "#c77ce0", "#f06a5c", "#4cd3c8", "#e0d05c",
  "#9aa3b2", "#f08fc0", "#7c8cf0", "#b0e05c", "#f0905c"];
const stageColours = new Map();
function stageColour(stage) {
  if (!stageColours.has(stage)) stageColours.set(stage, STAGE_COLOURS[stageColours.size % STAGE_COLOURS.length]);
  return stageColours.get(stage);
}

function showTimings(timings) {
  const total = timings.reduce((sum, t) => sum + t.ms, 0) || 1;
  const bar = $("stage-bar");
  const legend = $("stage-legend");
  bar.replaceChildren();
  legend.replaceChildren();
  for (const { stage, ms } of timings) {
    const segment = document.createElement("div");
    segment.style.width = `${(100 * ms) / total}%`;
    segment.style.background = stageColour(stage);
    segment.title = `${stage}: ${ms.toFixed(1)} ms`;
    segment.dataset.stage = stage;
    bar.append(segment);
    const entry = document.createElement("span");
    const swatch = document.createElement("i");
    swatch.style.background = stageColour(stage);
    entry.append(swatch, `${stage} ${ms.toFixed(1)} ms`);
    legend.append(entry);
  }
}

function showSettings() {
  const a = state.applied;
  const w = state.wanted;
  const onOff = (v) => (v ? "on" : "off");
  const rows = [
    ["view", COMPONENT_NAMES[a.component], COMPONENT_NAMES[w.component]],
    ["quality level", LEVEL_NAMES[a.level], LEVEL_NAMES[w.level]],
    ["frame budget", formatBudget(a.budgetMs), formatBudget(w.budgetMs)],
    ["glossy", a.glossy === undefined ? undefined : onOff(a.glossy) + (state.scene?.glossy ? "" : " (no glossy material)"),
      onOff(w.glossy) + (state.scene?.glossy ? "" : " (no glossy material)")],
    ["sparse points", state.scene?.sparse_points, undefined],
    ["frame size", state.lastFrame ? `${state.lastFrame.width}×${state.lastFrame.height}` : undefined, undefined],
    ["VALs", state.lastFrame?.valCount, undefined],
    ["recording", state.recording ? `${state.recording.name} (${state.recording.frames} frames)` : undefined, undefined],
    ["scene", state.scene?.id, undefined],
  ];
  const list = $("settings");
  list.replaceChildren();
  for (const [name, applied, wanted] of rows) {
    const dt = document.createElement("dt");
    dt.textContent = name;
    const dd = document.createElement("dd");
    dd.dataset.setting = name;
    const pending = wanted !== undefined && String(applied) !== String(wanted);
    dd.textContent = pending ? `${applied ?? "–"} → ${wanted}` : String(applied ?? "–");
    if (pending) dd.classList.add("pending");
    list.append(dt, dd);
  }
  $("glossy-value").textContent = onOff(w.glossy);
  $("downscale-value").textContent = w.downscale === 1 ? "full" : `1/${w.downscale}`;
  for (const button of document.querySelectorAll("[data-component]")) {
    button.classList.toggle("active", Number(button.dataset.component) === w.component);
  }
  for (const button of document.querySelectorAll("[data-level]")) {
    button.classList.toggle("active", Number(button.dataset.level) === w.level);
  }
}

// The frame's error estimate, the level and parameters it ran at, and the budget it ran under.
// With a budget, the controller may have moved the frame off the stream's level: below it
// (a cheaper level, or the cheapest level with fewer VALs) or above it.
function showFrameQuality(frame) {
  const e = frame.errorEstimate;
  const error = $("frame-error");
  error.textContent = e ? `error estimate ${percent(e.relRmse)} ± ${percent(e.spread)} rel RMSE` : "error estimate – (no indirect light)";
  error.dataset.relRmse = e ? String(e.relRmse) : "";
  const parameters = Object.fromEntries(frame.parameters.map((p) => [p.name, p.value]));
  const level = LEVEL_NAMES[frame.quality] ?? `level ${frame.quality}`;
  const streamLevel = state.applied.level;
  const rank = (l) => (l === QualityLevel.REFERENCE ? QualityLevel.ACCURATE : l);
  // Cheaper than any level's own parameters: fewer VALs or a smaller render.
  const cheaper = Number(parameters.vals_step) > 1 || Number(parameters.resolution_scale) < 1;
  let moved = "";
  if (frame.budgetMs > 0 && streamLevel !== undefined) {
    const from = rank(frame.quality) !== rank(streamLevel) ? ` from ${LEVEL_NAMES[streamLevel]}` : "";
    if (cheaper || rank(frame.quality) < rank(streamLevel)) moved = `, lowered by the budget${from}`;
    else if (rank(frame.quality) > rank(streamLevel)) moved = `, raised by the budget${from}`;
  }
  const levelText = $("frame-level");
  levelText.textContent = `ran ${cheaper ? "below" : "at"} ${level}${moved}`;
  levelText.dataset.level = level;
  levelText.classList.toggle("moved", moved !== "");
  $("frame-parameters").textContent = frame.parameters.filter((p) => p.name !== "level")
    .map((p) => `${p.name.replace(/_/g, " ")} ${p.value}`).join(" · ");
  $("frame-budget").textContent = frame.budgetMs > 0 ? `budget ${formatMs(frame.budgetMs)} ms` : "no budget";
}

let frameUrl = null;
function showFrame(frame, sent) {
  const image = frame.png ? new Blob([frame.png], { type: "image/png" }) : null;
  if (image) {
    if (frameUrl) URL.revokeObjectURL(frameUrl);
    frameUrl = URL.createObjectURL(image);
    $("frame").src = frameUrl;
    $("frame-placeholder").hidden = true;
  }
  state.framesShown += 1;
  state.lastFrame = frame;
  state.droppedFrames = frame.droppedFrames;
  const serverMs = frame.timings.reduce((sum, t) => sum + t.ms, 0);
  const roundTrip = sent ? performance.now() - sent.sentAt : undefined;
  const source = sent?.frame;
  $("frame-info").textContent = `frame ${frame.frameId}` +
    (source ? ` · t = ${source.timestamp.toFixed(3)} s` : "") +
    ` · ${frame.width}×${frame.height} · ${frame.valCount} VALs`;
  $("frame-time").textContent = `frame time ${serverMs.toFixed(0)} ms on the server` +
    (roundTrip !== undefined ? ` · ${roundTrip.toFixed(0)} ms round trip` : "");
  const dropped = $("dropped");
  dropped.dataset.dropped = String(frame.droppedFrames);
  dropped.textContent = `dropped frames: ${frame.droppedFrames}`;
  showTimings(frame.timings);
  showFrameQuality(frame);
  showSettings();
}

// ----------------------------------------------------------------------------------------
// HTTP

// `options` with the bearer token, when the page has one, on requests to the API (/v1).
function withToken(url, options = {}) {
  if (!state.token || !url.startsWith("/v1/")) return options;
  return { ...options, headers: { ...options.headers, authorization: `Bearer ${state.token}` } };
}

async function fetchOk(url, options) {
  let response;
  try {
    response = await fetch(url, withToken(url, options));
  } catch (error) {
    throw new Error(`${url}: the server cannot be reached (${error.message})`);
  }
  if (!response.ok) {
    let detail = response.statusText;
    try {
      const body = await response.json();
      detail = `${body.error.code}: ${body.error.message}`;
    } catch (_) { /* not a JSON error */ }
    const error = new Error(`${options?.method ?? "GET"} ${url}: ${response.status} ${detail}`);
    error.status = response.status;
    throw error;
  }
  return response;
}

// Creates the scene; deletes the previous one.
async function createScene() {
  const response = await fetchOk("/v1/scenes", {
    method: "POST",
    headers: { "content-type": "application/json" },
    body: state.sceneText,
  });
  const previous = state.scene;
  state.scene = await response.json();
  if (previous) {
    const url = `/v1/scenes/${previous.id}`;
    fetch(url, withToken(url, { method: "DELETE" })).catch(() => {});
  }
  const budget = state.scene.resolved.budget_ms;
  log("info", `scene ${state.scene.id}: ${state.scene.triangles} triangles, ${state.scene.sparse_points} sparse points, `
    + `level ${state.scene.resolved.quality}${budget ? `, budget ${budget} ms` : ""}`);
}

async function fetchFrame(index) {
  const r = state.recording;
  const url = `/v1/recordings/${encodeURIComponent(r.name)}/frames/${index}?downscale=${state.wanted.downscale}`;
  return new Uint8Array(await (await fetchOk(url)).arrayBuffer());
}

// ----------------------------------------------------------------------------------------
// The stream

function sendControl(parts) {
  const socket = state.socket;
  if (!socket || socket.readyState !== WebSocket.OPEN) return;
  const requestId = ++state.requestId;
  state.pending.set(requestId, parts);
  const control = { requestId };
  if (parts.component !== undefined) control.quality = { component: parts.component, format: ImageFormat.PNG };
  if (parts.glossy !== undefined || parts.level !== undefined || parts.budgetMs !== undefined) {
    control.render = { glossy: parts.glossy, quality: parts.level, budgetMs: parts.budgetMs };
  }
  socket.send(encodeControl(control));
  showSettings();
}

function sendAllSettings() {
  const w = state.wanted;
  sendControl({ component: w.component, glossy: w.glossy, level: w.level });
  // Apart: the server refuses a control as a whole, and a budget from the URL may be refused.
  sendControl({ budgetMs: w.budgetMs });
}

function onMessage(event, socket) {
  if (socket !== state.socket) return;
  let envelope;
  try {
    envelope = decodeEnvelope(event.data);
  } catch (error) {
    log("error", `undecodable message from the server: ${error.message}`);
    return;
  }
  const { kind, body } = envelope;
  if (kind === "renderedFrame") {
    const sent = state.sent.get(body.frameId);
    state.sent.delete(body.frameId);
    showFrame(body, sent);
    answered(body.frameId);
  } else if (kind === "settingsAck") {
    const parts = state.pending.get(body.requestId);
    state.pending.delete(body.requestId);
    if (parts) Object.assign(state.applied, parts);
    showSettings();
  } else if (kind === "error") {
    const about = body.frameId !== undefined ? ` (frame ${body.frameId})` : body.requestId !== undefined ? ` (settings request ${body.requestId})` : "";
    log("error", `stream error ${body.code}${about}: ${body.message}${body.field ? ` [${body.field}]` : ""}`);
    if (body.requestId !== undefined) {
      // Refused as a whole: the controls go back to what is in effect.
      const parts = state.pending.get(body.requestId) ?? {};
      state.pending.delete(body.requestId);
      const scenes = { level: levelNumber(state.scene?.resolved.quality), budgetMs: state.scene?.resolved.budget_ms ?? 0 };
      for (const name of Object.keys(parts)) state.wanted[name] = state.applied[name] ?? scenes[name] ?? state.wanted[name];
      syncSliders();
    }
    if (body.frameId !== undefined) answered(body.frameId);
    showSettings();
  }
}

function answered(frameId) {
  if (state.waiter && (frameId === undefined || state.waiter.frameId === frameId)) {
    state.waiter.resolve();
    state.waiter = null;
  }
}

// Opens the scene's stream; with a token, through a ticket (the handshake cannot carry the
// header) offered as a subprotocol. The server selects `relume.v1`.
async function openStream(generation) {
  const url = `${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/v1/scenes/${state.scene.id}/stream`;
  const protocols = ["relume.v1"];
  state.streamTicket = null;
  if (state.token) {
    const { ticket } = await (await fetchOk("/v1/tickets", { method: "POST" })).json();
    if (generation !== state.generation) return;
    protocols.push(`relume.ticket.${ticket}`);
    state.streamTicket = ticket;
  }
  const socket = new WebSocket(url, protocols);
  socket.binaryType = "arraybuffer";
  state.socket = socket;
  state.applied = {};
  state.pending.clear();
  socket.onopen = () => {
    setStatus("live", "live");
    sendAllSettings();
    play(generation, socket);
  };
  socket.onmessage = (event) => onMessage(event, socket);
  socket.onclose = (event) => {
    if (socket !== state.socket) return; // replaced on purpose
    const why = event.reason || (event.code === 1006 ? "connection lost" : `code ${event.code}`);
    setStatus("closed", `disconnected: ${why} — the server is gone? click to reconnect`);
    log("error", `stream closed (${event.code}${event.reason ? `, ${event.reason}` : ""})`);
    answered(undefined);
  };
}

// Plays the recording on `socket` until the page moves to another stream.
async function play(generation, socket) {
  const live = () => generation === state.generation && socket.readyState === WebSocket.OPEN;
  while (live()) {
    if (!state.playing) {
      await sleep(100);
      continue;
    }
    const index = state.nextIndex;
    state.nextIndex = (index + 1) % state.recording.frames;
    const started = performance.now();
    let bytes;
    try {
      bytes = await fetchFrame(index);
    } catch (error) {
      log("error", error.message);
      await sleep(1000);
      continue;
    }
    if (!live()) break;
    const frame = decodeEnvelope(bytes).body;
    state.sent.set(frame.frameId, { sentAt: performance.now(), frame });
    const answer = new Promise((resolve) => { state.waiter = { frameId: frame.frameId, resolve }; });
    socket.send(bytes);
    if (state.realtime) {
      // The recording's rate: the server keeps the newest frame and drops the others.
      await sleep(Math.max(0, 1000 / 30 - (performance.now() - started)));
    } else {
      await Promise.race([answer, sleep(FRAME_ANSWER_TIMEOUT_MS)]);
    }
  }
}

// (Re)creates the scene and opens its stream; the previous stream, if any, is closed.
async function connect() {
  const generation = ++state.generation;
  const previous = state.socket;
  state.socket = null;
  if (previous) previous.close(1000, "replaced");
  setStatus("connecting", "connecting…");
  try {
    if (state.sceneText === null) state.sceneText = await (await fetchOk(params.get("scene") ?? "/default-scene.json")).text();
    if (state.recording === null) {
      const { recordings } = await (await fetchOk("/v1/recordings")).json();
      if (recordings.length === 0) {
        throw new Error("the server holds no recordings: start it with --assets fixtures (recordings/ under the asset directory)");
      }
      state.recording = recordings.find((r) => r.name === params.get("recording")) ?? recordings[0];
    }
    const first = state.scene === null;
    await createScene();
    if (first) {
      if (params.has("quality") && state.wanted.level === undefined) {
        log("error", `?quality=${params.get("quality")} is not a level (${Object.values(LEVEL_NAMES).join(", ")}): the scene's is used`);
      }
      state.wanted.level ??= levelNumber(state.scene.resolved.quality);
      state.wanted.budgetMs ??= state.scene.resolved.budget_ms ?? 0;
    }
    if (generation !== state.generation) return;
    await openStream(generation);
  } catch (error) {
    if (error.status === 401) {
      state.needsToken = true;
      $("token-form").hidden = false;
      $("token").focus();
      setStatus("error", state.token ? "wrong token: enter the server's token" : "this server wants its token: enter it");
    } else {
      setStatus("error", `${error.message} — click to retry`);
    }
    log("error", error.message);
  }
  showSettings();
}

// ----------------------------------------------------------------------------------------
// Controls

function bind() {
  for (const button of document.querySelectorAll("[data-component]")) {
    button.addEventListener("click", () => {
      state.wanted.component = Number(button.dataset.component);
      sendControl({ component: state.wanted.component });
    });
  }
  for (const button of document.querySelectorAll("[data-level]")) {
    button.addEventListener("click", () => {
      state.wanted.level = Number(button.dataset.level);
      sendControl({ level: state.wanted.level });
    });
  }
  // The budget as typed (empty: none), checked by the server: a value it refuses comes back
  // as an Error naming control.render.budget_ms, listed under Messages.
  $("budget-form").addEventListener("submit", (event) => {
    event.preventDefault();
    const text = $("budget").value.trim();
    state.wanted.budgetMs = text === "" ? 0 : Number(text);
    sendControl({ budgetMs: state.wanted.budgetMs });
  });
  $("play").addEventListener("click", () => {
    state.playing = !state.playing;
    $("play").textContent = state.playing ? "Pause" : "Play";
  });
  $("realtime").addEventListener("change", (event) => { state.realtime = event.target.checked; });
  window.addEventListener("hashchange", () => {
    const token = new URLSearchParams(location.hash.slice(1)).get("token");
    if (token && token !== state.token) {
      state.token = token;
      state.needsToken = false;
      $("token-form").hidden = true;
      connect();
    }
  });
  $("token-form").addEventListener("submit", (event) => {
    event.preventDefault();
    state.token = $("token").value.trim() || null;
    state.needsToken = false;
    $("token-form").hidden = true;
    connect();
  });
  $("status").addEventListener("click", () => {
    if (state.connection === "closed" || state.connection === "error") connect();
  });
  const slider = (id, apply) => $(id).addEventListener("change", (event) => apply(Number(event.target.value)));
  slider("glossy", (v) => { state.wanted.glossy = v === 1; sendControl({ glossy: v === 1 }); });
  slider("downscale", (v) => { state.wanted.downscale = v; showSettings(); });
}

function syncSliders() {
  const w = state.wanted;
  $("budget").value = w.budgetMs ? formatMs(w.budgetMs) : "";
  $("glossy").value = w.glossy ? 1 : 0;
  $("downscale").value = w.downscale;
}

bind();
syncSliders();
showSettings();
connect().then(syncSliders);
