#!/usr/bin/env bash
# Installs what relume needs beyond a Rust toolchain: a Vulkan loader and Mesa's lavapipe
# (Vulkan on the CPU), so wgpu finds an adapter on machines without a GPU. Idempotent.
set -euo pipefail

have_lavapipe() {
    ls /usr/share/vulkan/icd.d/lvp_icd*.json >/dev/null 2>&1 && ldconfig -p | grep -q libvulkan.so.1
}

# nv-flip (the FLIP metric) builds its C++ with the system compiler.
packages=""
have_lavapipe || packages="mesa-vulkan-drivers libvulkan1"
# Mesa's llvmpipe through EGL: wgpu's GL backend, which the backend test runs beside Vulkan.
have_gl() {
    ldconfig -p | grep -q libEGL_mesa.so.0 && ls /usr/lib/*/dri/swrast_dri.so >/dev/null 2>&1
}
have_gl || packages="$packages libegl1 libegl-mesa0 libgl1-mesa-dri"
command -v c++ >/dev/null || packages="$packages g++"
# scripts/device-bench.sh writes its summary with python3 (standard library only).
command -v python3 >/dev/null || packages="$packages python3"
# shellcheck disable=SC2086
bash "$(dirname "${BASH_SOURCE[0]}")/apt-install.sh" $packages
command -v cargo >/dev/null || { echo "setup: cargo not found; install Rust (https://rustup.rs)" >&2; exit 1; }
# Mesa warns twice without a runtime dir; give it one.
if [ -z "${XDG_RUNTIME_DIR:-}" ]; then
    export XDG_RUNTIME_DIR="${TMPDIR:-/tmp}/relume-runtime-$(id -u)"
    mkdir -p "$XDG_RUNTIME_DIR" && chmod 700 "$XDG_RUNTIME_DIR"
fi
