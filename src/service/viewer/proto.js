// The few messages of proto/relume.proto (package relume.v1) that the viewer uses, encoded and
// decoded by hand: protobuf's wire format is varints, little-endian fixed-width numbers and
// length-prefixed bytes, and these messages need nothing more. Field numbers are those of the
// .proto file; the end-to-end test round-trips them through the server's Rust (prost) codec.

export const PROTOCOL_VERSION = 1;

export const Component = { FULL: 1, DIRECT: 2, INDIRECT: 3 };
export const Occlusion = { SCENE: 0, OFF: 1, DISKS: 2 };
export const ImageFormat = { PNG: 1, RGBA8: 2 };
export const ErrorCode = [
  "UNSPECIFIED", "MALFORMED", "UNSUPPORTED_VERSION", "INVALID_FIELD", "LIMIT_EXCEEDED",
  "UNEXPECTED_MESSAGE", "SCENE_NOT_FOUND", "NOT_IMPLEMENTED", "SHUTTING_DOWN", "INTERNAL",
];

const VARINT = 0, FIXED64 = 1, BYTES = 2, FIXED32 = 5;

class Writer {
  constructor() { this.parts = []; }
  varint(value) {
    let n = BigInt(value);
    const out = [];
    do {
      let byte = Number(n & 0x7fn);
      n >>= 7n;
      if (n > 0n) byte |= 0x80;
      out.push(byte);
    } while (n > 0n);
    this.parts.push(Uint8Array.from(out));
  }
  tag(field, wire) { this.varint((field << 3) | wire); }
  uint(field, value) { if (value !== undefined) { this.tag(field, VARINT); this.varint(value); } }
  bool(field, value) { if (value !== undefined) this.uint(field, value ? 1 : 0); }
  float(field, value) {
    if (value === undefined) return;
    const bytes = new Uint8Array(4);
    new DataView(bytes.buffer).setFloat32(0, value, true);
    this.tag(field, FIXED32);
    this.parts.push(bytes);
  }
  bytes(field, bytes) { this.tag(field, BYTES); this.varint(bytes.length); this.parts.push(bytes); }
  message(field, fill) {
    if (fill === undefined) return;
    const inner = new Writer();
    fill(inner);
    this.bytes(field, inner.finish());
  }
  finish() {
    const out = new Uint8Array(this.parts.reduce((n, p) => n + p.length, 0));
    let at = 0;
    for (const p of this.parts) { out.set(p, at); at += p.length; }
    return out;
  }
}

// An Envelope holding a Control. `control` may hold `requestId`, `quality {component, exposure,
// format}`, `rgbd {gridStep, radianceScale}` and `render {occlusion, glossy}`; absent parts
// are not sent (the server keeps their values).
export function encodeControl(control) {
  const w = new Writer();
  w.uint(1, PROTOCOL_VERSION);
  w.message(3, (c) => {
    c.uint(1, control.requestId ?? 0);
    c.message(5, control.quality && ((q) => {
      q.uint(2, control.quality.component);
      q.float(3, control.quality.exposure);
      q.uint(4, control.quality.format);
    }));
    c.message(6, control.rgbd && ((r) => {
      r.uint(1, control.rgbd.gridStep);
      r.float(4, control.rgbd.radianceScale);
    }));
    c.message(7, control.render && ((r) => {
      r.uint(1, control.render.occlusion);
      r.bool(2, control.render.glossy);
    }));
  });
  return w.finish();
}

// Reads every field of one message: a Map from field number to the list of its values (numbers
// for varints, BigInt for large ones, DataView-readable bytes for the rest).
function fields(bytes) {
  const view = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  const out = new Map();
  let at = 0;
  const varint = () => {
    let n = 0n, shift = 0n;
    for (;;) {
      if (at >= bytes.length) throw new Error("truncated varint");
      const byte = bytes[at++];
      n |= BigInt(byte & 0x7f) << shift;
      if ((byte & 0x80) === 0) return n;
      shift += 7n;
      if (shift > 63n) throw new Error("varint too long");
    }
  };
  while (at < bytes.length) {
    const key = Number(varint());
    const field = key >> 3, wire = key & 7;
    let value;
    if (wire === VARINT) {
      const n = varint();
      value = n <= BigInt(Number.MAX_SAFE_INTEGER) ? Number(n) : n;
    } else if (wire === FIXED64) {
      if (at + 8 > bytes.length) throw new Error("truncated fixed64");
      value = view.getFloat64(at, true);
      at += 8;
    } else if (wire === BYTES) {
      const length = Number(varint());
      if (at + length > bytes.length) throw new Error("truncated bytes");
      value = bytes.subarray(at, at + length);
      at += length;
    } else if (wire === FIXED32) {
      if (at + 4 > bytes.length) throw new Error("truncated fixed32");
      value = view.getFloat32(at, true);
      at += 4;
    } else {
      throw new Error(`unsupported wire type ${wire}`);
    }
    if (!out.has(field)) out.set(field, []);
    out.get(field).push(value);
  }
  return out;
}

const text = new TextDecoder();
const last = (f, n, fallback) => (f.has(n) ? f.get(n)[f.get(n).length - 1] : fallback);
const str = (f, n) => text.decode(last(f, n, new Uint8Array()));

function renderedFrame(bytes) {
  const f = fields(bytes);
  return {
    frameId: last(f, 1, 0),
    timestamp: last(f, 2, 0),
    width: last(f, 3, 0),
    height: last(f, 4, 0),
    png: last(f, 5, undefined),
    rgba8: last(f, 6, undefined),
    timings: (f.get(7) ?? []).map((t) => {
      const s = fields(t);
      return { stage: str(s, 1), ms: last(s, 2, 0) };
    }),
    valCount: last(f, 8, 0),
    droppedFrames: last(f, 9, 0),
  };
}

function error(bytes) {
  const f = fields(bytes);
  const code = last(f, 1, 0);
  return {
    code: ErrorCode[code] ?? `code ${code}`,
    message: str(f, 2),
    field: str(f, 3),
    limit: str(f, 4),
    frameId: last(f, 5, undefined),
    requestId: last(f, 6, undefined),
  };
}

function settingsAck(bytes) {
  const f = fields(bytes);
  return { requestId: last(f, 1, 0), applied: (f.get(2) ?? []).map((b) => text.decode(b)) };
}

// The parts of an RgbdFrame the viewer shows: id, time and intrinsics (not the pixels).
function rgbdFrame(bytes) {
  const f = fields(bytes);
  const k = fields(last(f, 3, new Uint8Array()));
  return {
    frameId: last(f, 1, 0),
    timestamp: last(f, 2, 0),
    intrinsics: { width: last(k, 1, 0), height: last(k, 2, 0), fx: last(k, 3, 0), fy: last(k, 4, 0),
      cx: last(k, 5, 0), cy: last(k, 6, 0) },
  };
}

// An Envelope: `{version, kind, body}` with kind one of "rgbdFrame", "renderedFrame", "error",
// "settingsAck" (or "other" for a body the viewer does not read). Throws on malformed bytes.
export function decodeEnvelope(buffer) {
  const f = fields(buffer instanceof Uint8Array ? buffer : new Uint8Array(buffer));
  const version = last(f, 1, 0);
  const bodies = [[2, "rgbdFrame", rgbdFrame], [4, "renderedFrame", renderedFrame], [5, "error", error],
    [6, "settingsAck", settingsAck]];
  for (const [field, kind, decode] of bodies) {
    if (f.has(field)) return { version, kind, body: decode(last(f, field)) };
  }
  return { version, kind: "other", body: null };
}
