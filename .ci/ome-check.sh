#!/usr/bin/env bash
# CI check of the controller's recording (issue 13): acquire 20 frames of the moving scene on the
# simulated rig and read them back with tifffile, the OME-TIFF reader the field uses from Python
# (tools/ome/check_recording.py). Prints one summary line; exits non-zero on failure.
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$repo"
venv=tools/.venv-ome
if [ ! -x "$venv/bin/python" ]; then
  python3 -m venv "$venv"
  "$venv/bin/pip" install -q tifffile numpy
fi
out="$(mktemp -d)"
trap 'rm -rf "$out"' EXIT
cargo run -q -- acquire scenes/moving-spheres.toml --frames 20 --out "$out/rec" >/dev/null
"$venv/bin/python" tools/ome/check_recording.py "$out/rec" 20
