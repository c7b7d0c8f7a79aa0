#!/usr/bin/env bash
# Time and test specmux-gpu on a lent GPU machine that has no Rust toolchain (docs/gpu.md).
#
#   crates/gpu/device-bench.sh stage DIR   here: build the release test and bench binaries and
#                                          specmux with the gpu feature, strip and gzip them
#                                          into DIR (x86-64 only)
#   bash DIR/device-bench.sh run DIR       there, from a checkout with spectra/ and scenes/:
#                                          unpack, run the GPU tests (the twin's GPU stages
#                                          too), the realtime and relay benches and `specmux
#                                          bench` on the GPU and on the CPU; logs to $OUT (or
#                                          DIR/out)
set -euo pipefail
mode=${1:?stage or run}
dir=${2:?folder}

stage() {
  local tgt=${CARGO_TARGET_DIR:-target}
  mkdir -p "$dir"
  cargo bench -p specmux-gpu --no-run
  cargo test --release -p specmux-gpu --no-run
  cargo test --release -p specmux-twin --features gpu --lib --no-run
  cargo bench --features gpu --bench relay --no-run
  cargo build --release --features gpu --bin specmux
  strip -o "$dir/specmux" "$tgt/release/specmux"
  gzip -f9 "$dir/specmux"
  for t in fft demux unmix gap joint reconstructor backend pair_sums realtime relay specmux_twin; do
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
  for t in fft demux unmix gap joint reconstructor backend pair_sums realtime relay specmux_twin specmux; do
    gunzip -c "$dir/$t.gz" >"/tmp/$t" && chmod +x "/tmp/$t"
  done
  for t in fft demux unmix gap joint reconstructor backend pair_sums; do
    "/tmp/$t" --nocapture --test-threads 1 >"$out/test-$t.log" 2>&1 || echo "TEST $t FAILED"
    grep -E "adapter|test result" "$out/test-$t.log" | sort -u
  done
  /tmp/specmux_twin gpu --test-threads 1 >"$out/test-twin.log" 2>&1 || echo "TEST twin gpu FAILED"
  grep -E "test result" "$out/test-twin.log" || true
  "/tmp/realtime" --bench 2>"$out/bench.err" | tee "$out/bench.md"
  "/tmp/relay" 2>"$out/relay.err" | tee "$out/relay.md" || echo "relay bench FAILED"
  # BENCH_DEVICES="gpu" skips the CPU's pass (minutes); BENCH_REPEATS sets --repeats (5).
  for d in ${BENCH_DEVICES:-gpu cpu}; do
    "/tmp/specmux" bench dead-leaves --device "$d" --repeats "${BENCH_REPEATS:-5}" \
      --out "$out/work-precision-$d" \
      >"$out/work-precision-$d.log" 2>&1 || echo "specmux bench --device $d FAILED"
  done
}

"$mode"
