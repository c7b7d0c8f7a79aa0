#!/usr/bin/env bash
# Regenerate everything under spectra/ from pinned PyPI packages.
#   bash tools/extract_spectra.sh
# Creates tools/.venv-data (git-ignored) with colour-science==0.4.7 and numpy
# pinned, downloads the pyxel-sim 3.0.2 wheel (read as data only: its embedded
# silicon absorption table feeds the modelled mono QE curve; never installed
# or imported), then runs tools/extract_spectra.py.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
repo="$(cd "$here/.." && pwd)"
venv="$here/.venv-data"
py="${PYTHON:-python3}"

if [ ! -x "$venv/bin/python" ]; then
    "$py" -m venv "$venv"
fi
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check \
    "colour-science==0.4.7" "numpy==2.4.6"

wheel_dir="$venv/wheels"
wheel="$wheel_dir/pyxel_sim-3.0.2-py3-none-any.whl"
if [ ! -f "$wheel" ]; then
    "$venv/bin/python" -m pip download --quiet --disable-pip-version-check \
        --no-deps --only-binary=:all: -d "$wheel_dir" "pyxel-sim==3.0.2"
fi

cd "$repo"
"$venv/bin/python" "$here/extract_spectra.py" --pyxel-wheel "$wheel" --out "$repo/spectra" "$@"
