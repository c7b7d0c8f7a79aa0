#!/usr/bin/env bash
# CI referee of the camera model (issue 16): the EMVA 1288 reference analysis (PyPI emva1288,
# which needs numpy < 2) reads the raw photon-transfer frames of `specmux ptc --emva` and must
# find the camera the experiment gives and specmux's own figures (tools/emva/referee.py).
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$repo"
venv=tools/.venv-emva
if [ ! -x "$venv/bin/python" ]; then
  python3 -m venv "$venv"
  "$venv/bin/pip" install -q "emva1288==1.0.2" "numpy<2"
fi
out="$(mktemp -d)"
trap 'rm -rf "$out"' EXIT
cargo run -q -- ptc --emva --out "$out/ptc" >/dev/null
"$venv/bin/python" tools/emva/referee.py "$out/ptc" --check
