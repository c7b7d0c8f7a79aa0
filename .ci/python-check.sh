#!/usr/bin/env bash
# CI check of the Python package : a venv under tools/.venv-python (git-ignored),
# `pip install ./python` (maturin builds crates/python, PyO3 + numpy), then the pytest
# suite python/tests, which also runs the CLI's `specmux demo --size 64` and checks that Python's
# simulate + reconstruct prints the same PSNR. Prints one summary line; exits non-zero on failure.
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$repo"
start=$(date +%s)
venv=tools/.venv-python
if [ ! -x "$venv/bin/python" ]; then
  python3 -m venv "$venv"
fi
"$venv/bin/pip" install -q --upgrade pip >/dev/null
"$venv/bin/pip" install -q maturin pytest numpy
# Always rebuild from this tree (the same version number would otherwise be kept). In CI the
# extension is built with the dev profile into the workspace's target folder, so it reuses what
# `cargo test` compiled (a release build of the whole stack would add ten minutes on 2 cores);
# a user's `pip install ./python` builds in release.
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$repo/target}"
MATURIN_PEP517_ARGS="--profile dev" "$venv/bin/pip" install -q --force-reinstall --no-deps ./python
# The CLI the test compares with (already built by `cargo test` in .ci/run).
cargo build -q --bin specmux
export SPECMUX_BIN="${CARGO_TARGET_DIR:-$repo/target}/debug/specmux"
log="$(mktemp)"
trap 'rm -f "$log"' EXIT
# Run from python/tests so that the installed package, not the source folder, is imported.
if ! (cd python && "../$venv/bin/python" -m pytest -q -rs tests >"$log" 2>&1); then
  cat "$log"
  echo "python-check: FAILED ($(( $(date +%s) - start )) s)"
  exit 1
fi
# Skipped tests pass; say which and why (pytest's -rs lines), so a summary short of the
# collected count is explained.
grep -E '^SKIPPED' "$log" || true
echo "python-check: $(tail -n 1 "$log" | sed 's/=//g; s/^ *//; s/ *$//') (pip install ./python + pytest python/tests, $(( $(date +%s) - start )) s)"
