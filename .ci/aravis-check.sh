#!/usr/bin/env bash
# CI check of the controller's GenICam camera backend (issue 13): installs Aravis 0.8 from
# Debian when missing (aravis-tools has arv-fake-gv-camera-0.8; libaravis-dev, with
# libusb-1.0-0-dev that its pkg-config file requires, builds the `aravis` feature), then runs
# the controller's tests with every real backend, the fake-camera test among them: configure,
# software-trigger and stream frames over loopback.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
if ! command -v arv-fake-gv-camera-0.8 >/dev/null || ! pkg-config --exists aravis-0.8; then
  if ! command -v apt-get >/dev/null; then
    echo "aravis-check: needs arv-fake-gv-camera-0.8 and libaravis-0.8 (Debian: aravis-tools libaravis-dev)" >&2
    exit 1
  fi
  apt-get update -qq
  apt-get install -y -qq aravis-tools libaravis-dev libusb-1.0-0-dev >/dev/null
fi
# One build with every real backend: the serial wheel and ALP-4 tests run here too.
cargo test -p specmux-controller --features aravis,serial-wheel,alp4
