#!/usr/bin/env node
// Writes the browser viewer's protobuf files (src/service/viewer/), which relume builds into
// its binary so that the page loads nothing from elsewhere:
//   - vendor/protobufjs/protobuf.min.js, LICENSE: protobuf.js's `light` browser build (reflection:
//     it encodes and decodes from a JSON descriptor; no parser), copied unchanged from the
//     package that tests/e2e/package-lock.json pins (npm ci checks its integrity hash);
//   - vendor/protobufjs/SOURCE: the version, where it came from and the copied files' SHA-256;
//   - relume.proto.json: the descriptor of proto/relume.proto, as protobuf.js's own parser reads
//     it (field names as in the .proto file).
//
// Run `scripts/e2e-setup.sh` first (it installs the pinned package), then
// `node scripts/viewer-protobuf.mjs` to write the files, or with `--check` to fail, naming
// them, when a committed file differs from what this script writes (scripts/test.sh does).
// To move to another protobuf.js version: change it in tests/e2e/package.json, `npm install`
// there, run this script, commit.

import { createHash } from "node:crypto";
import { readFileSync, writeFileSync } from "node:fs";
import { createRequire } from "node:module";
import path from "node:path";
import { fileURLToPath } from "node:url";

const root = path.resolve(path.dirname(fileURLToPath(import.meta.url)), "..");
const e2e = path.join(root, "tests", "e2e");
const viewer = path.join(root, "src", "service", "viewer");
const vendor = path.join(viewer, "vendor", "protobufjs");
const check = process.argv.includes("--check");

const require = createRequire(path.join(e2e, "package.json"));
let packageDir;
try {
  packageDir = path.dirname(require.resolve("protobufjs/package.json"));
} catch {
  console.error("protobufjs is not installed in tests/e2e/node_modules: run scripts/e2e-setup.sh");
  process.exit(1);
}
const protobuf = require("protobufjs");
const { version } = require("protobufjs/package.json");
const lock = JSON.parse(readFileSync(path.join(e2e, "package-lock.json"), "utf8")).packages["node_modules/protobufjs"];
if (lock?.version !== version) {
  console.error(`tests/e2e/node_modules has protobufjs ${version}, the lock file ${lock?.version}: run scripts/e2e-setup.sh`);
  process.exit(1);
}

const sha256 = (bytes) => createHash("sha256").update(bytes).digest("hex");
const files = new Map();
for (const [from, to] of [["dist/light/protobuf.min.js", "protobuf.min.js"], ["LICENSE", "LICENSE"]]) {
  files.set(path.join(vendor, to), readFileSync(path.join(packageDir, from)));
}
files.set(path.join(vendor, "SOURCE"), Buffer.from(
  `protobuf.js ${version} (npm package protobufjs), BSD-3-Clause (LICENSE, also served at\n` +
  `/vendor/protobufjs/LICENSE), https://github.com/protobufjs/protobuf.js\n` +
  `Package: https://registry.npmjs.org/protobufjs/-/protobufjs-${version}.tgz\n` +
  `Integrity: ${lock.integrity}\n` +
  `Copied unchanged by scripts/viewer-protobuf.mjs:\n` +
  `  protobuf.min.js = dist/light/protobuf.min.js, sha256 ${sha256(files.get(path.join(vendor, "protobuf.min.js")))}\n` +
  `  LICENSE = LICENSE, sha256 ${sha256(files.get(path.join(vendor, "LICENSE")))}\n`));

const schema = new protobuf.Root().loadSync(path.join(root, "proto", "relume.proto"), { keepCase: true });
files.set(path.join(viewer, "relume.proto.json"),
  Buffer.from(`${JSON.stringify(schema.toJSON(), null, 1)}\n`));

const stale = [];
for (const [file, bytes] of files) {
  const name = path.relative(root, file);
  if (check) {
    let committed = null;
    try { committed = readFileSync(file); } catch { /* missing: stale */ }
    if (!committed?.equals(bytes)) stale.push(name);
  } else {
    writeFileSync(file, bytes);
    console.log(`wrote ${name}`);
  }
}
if (stale.length > 0) {
  console.error(`not what scripts/viewer-protobuf.mjs writes (run it and commit): ${stale.join(", ")}`);
  process.exit(1);
}
if (check) console.log(`the viewer's protobuf.js ${version} and relume.proto.json are up to date`);
