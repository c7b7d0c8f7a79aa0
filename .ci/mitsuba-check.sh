#!/usr/bin/env bash
# CI cross-check against Mitsuba 3 (issue 5): install (tools/mitsuba/setup.sh), re-render the
# cheapest golden fixture (chart, 64x64, same spp, a different seed) and compare it with
# tests/fixtures/mitsuba/ within the Monte Carlo bound (tools/mitsuba/compare.py check).
# Prints one summary line; exits non-zero on failure.
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$repo"
start=$(date +%s)
bash tools/mitsuba/setup.sh >/dev/null
py=tools/.venv-mitsuba/bin/python
fixtures=tests/fixtures/mitsuba
scene=chart
spp=$("$py" -c "import json,sys; print(json.load(open(sys.argv[1]))['spp'])" "$fixtures/$scene.json")
live="$(mktemp -d)"
trap 'rm -rf "$live"' EXIT
"$py" tools/mitsuba/render.py --scenes "$scene" --spp "$spp" --seed 20240905 --out "$live" >/dev/null
"$py" tools/mitsuba/compare.py check --ref "$fixtures" --live "$live" --scene "$scene"
echo "mitsuba-check: total $(( $(date +%s) - start )) s including install"
