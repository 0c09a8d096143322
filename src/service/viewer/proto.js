// The messages of proto/relume.proto (package relume.v1) that the viewer uses, encoded and
// decoded by protobuf.js (its `light` build, vendored in ./vendor/protobufjs/ and served by
// relume) from the descriptor ./relume.proto.json; both are written by
// scripts/viewer-protobuf.mjs, which `--check`s that they match the pinned package and the
// .proto file. This module maps the generated messages to the small objects viewer.js uses.
// The end-to-end test round-trips them through the server's Rust (prost) codec and checks the
// Control bytes against prost's.

// protobuf.js's browser build is a script that defines the global `protobuf` (it is not an
// ES module); imported for that effect, it runs before this module's body.
import "./vendor/protobufjs/protobuf.min.js";

const protobuf = globalThis.protobuf;
const descriptor = await (await fetch(new URL("./relume.proto.json", import.meta.url))).json();
const root = protobuf.Root.fromJSON(descriptor);
const Envelope = root.lookupType("relume.v1.Envelope");
// Reading a uint64 field without long.js gives a Number (exact up to 2^53).
const enumNames = (name, prefix) => Object.fromEntries(Object.entries(root.lookupEnum(`relume.v1.${name}`).values)
  .filter(([, value]) => value !== 0).map(([key, value]) => [key.slice(prefix.length), value]));

export const PROTOCOL_VERSION = 1;

export const Component = enumNames("Component", "COMPONENT_");
export const Occlusion = { SCENE: 0, ...enumNames("Occlusion", "OCCLUSION_") };
export const ImageFormat = enumNames("ImageFormat", "IMAGE_FORMAT_");
// The quality levels by name ({FAST: 1, ...}); UNSPECIFIED (0) is "the scene's level".
export const QualityLevel = { SCENE: 0, ...enumNames("QualityLevel", "QUALITY_LEVEL_") };
// Names by number: ErrorCode[1] is "MALFORMED".
export const ErrorCode = Object.fromEntries(Object.entries(root.lookupEnum("relume.v1.ErrorCode").valuesById)
  .map(([value, key]) => [value, key.slice("ERROR_CODE_".length)]));

// protobuf.js writes every field the object holds; prost (like protoc) leaves out a field
// without presence (not `optional`, not in a oneof, not a message) that holds its default. This
// drops those, so that the bytes are prost's; fields with presence are written even when zero.
function canonical(type, object) {
  const out = {};
  for (const [name, value] of Object.entries(object)) {
    const field = type.fields[name];
    if (!field) throw new Error(`${type.name} has no field ${name}`);
    if (value === undefined || value === null) continue;
    field.resolve();
    const sub = field.resolvedType instanceof protobuf.Type ? field.resolvedType : null;
    if (sub) {
      out[name] = field.repeated ? value.map((v) => canonical(sub, v)) : canonical(sub, value);
    } else if (field.repeated || field.partOf || !(value === 0 || value === false || value === "" || value.length === 0)) {
      out[name] = value;
    }
  }
  return out;
}

// An Envelope holding a Control. `control` may hold `requestId`, `quality {component, exposure,
// format}`, `rgbd {gridStep, radianceScale}` and `render {occlusion, glossy, quality,
// budgetMs}`; absent parts are not sent (the server keeps their values). `render.quality` and
// `render.budgetMs` have presence, so 0 (back to the scene's level; no budget) is sent.
export function encodeControl(control) {
  const { quality, rgbd, render } = control;
  return Envelope.encode(canonical(Envelope, {
    version: PROTOCOL_VERSION,
    control: {
      request_id: control.requestId,
      quality: quality && { component: quality.component, exposure: quality.exposure, format: quality.format },
      rgbd: rgbd && { grid_step: rgbd.gridStep, radiance_scale: rgbd.radianceScale },
      render: render && { occlusion: render.occlusion, glossy: render.glossy, quality: render.quality,
        budget_ms: render.budgetMs },
    },
  })).finish();
}

// A field with presence that is not set reads as null; the viewer's objects say undefined.
const present = (value) => value ?? undefined;

const bodies = {
  // The parts of an RgbdFrame the viewer shows: id, time and intrinsics (not the pixels).
  rgbd_frame: ["rgbdFrame", (f) => {
    const k = f.intrinsics ?? {};
    return { frameId: f.frame_id, timestamp: f.timestamp,
      intrinsics: { width: k.width ?? 0, height: k.height ?? 0, fx: k.fx ?? 0, fy: k.fy ?? 0, cx: k.cx ?? 0, cy: k.cy ?? 0 } };
  }],
  rendered_frame: ["renderedFrame", (f) => ({
    frameId: f.frame_id,
    timestamp: f.timestamp,
    width: f.width,
    height: f.height,
    png: f.image === "png" ? f.png : undefined,
    rgba8: f.image === "rgba8" ? f.rgba8 : undefined,
    timings: f.timings.map((t) => ({ stage: t.stage, ms: t.ms })),
    valCount: f.val_count,
    droppedFrames: f.dropped_frames,
    // Unset when the frame has no indirect light to estimate.
    errorEstimate: f.error_estimate ? { relRmse: f.error_estimate.rel_rmse, spread: f.error_estimate.spread,
      pixels: f.error_estimate.pixels, ms: f.error_estimate.ms } : undefined,
    quality: f.quality,
    parameters: f.parameters.map((p) => ({ name: p.name, value: p.value })),
    budgetMs: f.budget_ms,
  })],
  error: ["error", (e) => ({
    code: ErrorCode[e.code] ?? `code ${e.code}`,
    message: e.message,
    field: e.field,
    limit: e.limit,
    frameId: present(e.frame_id),
    requestId: present(e.request_id),
  })],
  settings_ack: ["settingsAck", (a) => ({ requestId: a.request_id, applied: [...a.applied] })],
};

// An Envelope: `{version, kind, body}` with kind one of "rgbdFrame", "renderedFrame", "error",
// "settingsAck" (or "other" for a body the viewer does not read). Throws on malformed bytes.
export function decodeEnvelope(buffer) {
  const envelope = Envelope.decode(buffer instanceof Uint8Array ? buffer : new Uint8Array(buffer));
  const [kind, read] = bodies[envelope.body] ?? ["other", () => null];
  return { version: envelope.version, kind, body: read(envelope[envelope.body]) };
}
