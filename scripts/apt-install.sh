#!/usr/bin/env bash
# Installs Debian packages non-interactively (through sudo unless root): the one way the
# project's scripts install what a fresh machine lacks. Nothing to do without arguments.
#   scripts/apt-install.sh PACKAGE...
set -euo pipefail
[ $# -gt 0 ] || exit 0
sudo=""
if [ "$(id -u)" -ne 0 ]; then sudo="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
$sudo apt-get update -qq
$sudo apt-get install -y -qq "$@" >/dev/null
