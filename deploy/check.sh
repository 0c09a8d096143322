#!/usr/bin/env bash
# Checks the deployment files offline (docs/deploy.md): checkov (from PyPI, pinned, in its own
# virtual environment, installed once) on the Kubernetes manifests and both Dockerfiles (relume's
# and the balancer's, deploy/haproxy/Dockerfile), and
# HAProxy's own parser (`haproxy -c`) on both balancer configurations. Every checkov finding is
# fixed or skipped in the file with its reason. Run by scripts/test.sh.
set -euo pipefail
cd "$(dirname "$0")/.."
CHECKOV_VERSION=3.3.30
venv="${XDG_CACHE_HOME:-$HOME/.cache}/relume/checkov-$CHECKOV_VERSION"
if [ ! -x "$venv/bin/checkov" ]; then
    python3 -m venv "$venv"
    "$venv/bin/pip" install --quiet "checkov==$CHECKOV_VERSION"
fi
command -v haproxy >/dev/null || scripts/apt-install.sh haproxy
# --skip-download: offline, no policy updates; --quiet: failures only.
"$venv/bin/checkov" --skip-download --quiet --compact --framework kubernetes -d deploy/k8s
"$venv/bin/checkov" --skip-download --quiet --compact --framework dockerfile -f Dockerfile \
    -f deploy/haproxy/Dockerfile
RELUME_LB_BIND=127.0.0.1:8080 RELUME_BACKEND_1=127.0.0.1:8081 RELUME_BACKEND_2=127.0.0.1:8082 \
    RELUME_BACKEND_3=127.0.0.1:8083 haproxy -c -q -f deploy/haproxy/haproxy.cfg
config=$(mktemp)
trap 'rm -f "$config"' EXIT
"$venv/bin/python" -c '
import sys, yaml
for doc in yaml.safe_load_all(open("deploy/k8s/haproxy.yaml")):
    if doc and doc.get("kind") == "ConfigMap":
        sys.stdout.write(doc["data"]["haproxy.cfg"])' >"$config"
haproxy -c -q -f "$config"
echo "deploy/check.sh: manifests, Dockerfiles and HAProxy configurations pass"
