#!/usr/bin/env bash
# Installs what the browser viewer's end-to-end test (tests/e2e/) needs: Debian's chromium,
# Node.js with npm, and playwright-core at the version of tests/e2e/package-lock.json (no
# browser download: the test drives /usr/bin/chromium), with protobufjs, from which
# scripts/viewer-protobuf.mjs copies the viewer's protobuf codec. Idempotent; source it or run it.
set -euo pipefail

e2e_packages=""
[ -x /usr/bin/chromium ] || e2e_packages="chromium"
command -v node >/dev/null || e2e_packages="$e2e_packages nodejs"
command -v npm >/dev/null || e2e_packages="$e2e_packages npm"
# shellcheck disable=SC2086
bash "$(dirname "${BASH_SOURCE[0]}")/apt-install.sh" $e2e_packages
e2e_dir="$(cd "$(dirname "${BASH_SOURCE[0]}")/../tests/e2e" && pwd)"
# `npm ci` again only when the lock file changed since the last install.
if ! cmp -s "$e2e_dir/package-lock.json" "$e2e_dir/node_modules/.package-lock.json.installed" 2>/dev/null; then
    (cd "$e2e_dir" && PLAYWRIGHT_SKIP_BROWSER_DOWNLOAD=1 npm ci --no-audit --no-fund --silent)
    cp "$e2e_dir/package-lock.json" "$e2e_dir/node_modules/.package-lock.json.installed"
fi
