#!/usr/bin/env bash
# Time and test specmux-gpu on a lent GPU machine that has no Rust toolchain (docs/gpu.md).
#
#   crates/gpu/device-bench.sh stage DIR   here: build the release test and bench binaries and
#                                          specmux with the gpu feature, strip and gzip them
#                                          into DIR (x86-64 only)
#   bash DIR/device-bench.sh run DIR       there, from a checkout with spectra/: unpack, run the
#                                          GPU tests, the bench and `specmux bench` on the GPU
#                                          and on the CPU; logs to $OUT (or DIR/out)
set -euo pipefail
mode=${1:?stage or run}
dir=${2:?folder}

stage() {
  local tgt=${CARGO_TARGET_DIR:-target}
  mkdir -p "$dir"
  cargo bench -p specmux-gpu --no-run
  cargo test --release -p specmux-gpu --no-run
  cargo build --release --features gpu --bin specmux
  strip -o "$dir/specmux" "$tgt/release/specmux"
  gzip -f9 "$dir/specmux"
  for t in fft demux unmix gap joint reconstructor realtime; do
    local bin
    bin=$(ls -t "$tgt"/release/deps/"$t"-* | grep -v '\.d$' | head -1)
    strip -o "$dir/$t" "$bin"
    gzip -f9 "$dir/$t"
  done
  cp "$0" "$dir/device-bench.sh"
}

run() {
  local out=${OUT:-$dir/out}
  mkdir -p "$out"
  export SPECMUX_SPECTRA=${SPECMUX_SPECTRA:-$PWD/spectra}
  nvidia-smi --query-gpu=name,driver_version,clocks.sm,clocks.mem --format=csv | tee "$out/gpu.txt" || true
  for t in fft demux unmix gap joint reconstructor realtime specmux; do
    gunzip -c "$dir/$t.gz" >"/tmp/$t" && chmod +x "/tmp/$t"
  done
  for t in fft demux unmix gap joint reconstructor; do
    "/tmp/$t" --nocapture --test-threads 1 >"$out/test-$t.log" 2>&1 || echo "TEST $t FAILED"
    grep -E "adapter|test result" "$out/test-$t.log" | sort -u
  done
  "/tmp/realtime" --bench 2>"$out/bench.err" | tee "$out/bench.md"
  for d in gpu cpu; do
    "/tmp/specmux" bench dead-leaves --device "$d" --out "$out/work-precision-$d" \
      >"$out/work-precision-$d.log" 2>&1 || echo "specmux bench --device $d FAILED"
  done
}

"$mode"
