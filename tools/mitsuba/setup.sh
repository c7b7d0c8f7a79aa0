#!/usr/bin/env bash
# One-command environment for the Mitsuba 3 spectral cross-check.
#   bash tools/mitsuba/setup.sh
# Creates tools/.venv-mitsuba (git-ignored) with the pinned packages of
# tools/mitsuba/requirements.txt, and fetches libLLVM 19 (needed by the llvm_ad_*
# variants of Dr.Jit 1.5; the LLVM 15/16 of Debian 12 abort at the first render)
# without a root install: `apt-get download` + `dpkg-deb -x` into tools/.llvm
# (git-ignored). Dependencies of libllvm19 that the system lacks are fetched the
# same way. Then it renders one tiny scene with llvm_ad_spectral; if that fails it
# warns and checks scalar_spectral instead (render.py falls back the same way).
# Idempotent: a second run only re-checks (a few seconds).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
tools="$(cd "$here/.." && pwd)"
venv="$tools/.venv-mitsuba"
llvm="$tools/.llvm"
py="${PYTHON:-python3}"
req="$here/requirements.txt"

# --- Python environment ------------------------------------------------------
if [ ! -x "$venv/bin/python" ]; then
    "$py" -m venv "$venv"
fi
stamp="$venv/.requirements.sha"
want="$(sha256sum "$req" | cut -d' ' -f1)"
if [ "$(cat "$stamp" 2>/dev/null || true)" != "$want" ]; then
    "$venv/bin/python" -m pip install --quiet --disable-pip-version-check -r "$req"
    echo "$want" > "$stamp"
fi

# --- libLLVM 19 (no root install) ----------------------------------------------
libdir="$llvm/usr/lib/x86_64-linux-gnu"
fetch_deb() { # fetch_deb <package>: download and unpack one .deb into $llvm
    local pkg="$1" tmp
    tmp="$(mktemp -d)"
    if ! (cd "$tmp" && apt-get download -q "$pkg" >/dev/null 2>&1); then
        # A fresh machine may have empty package lists: refresh them once (root only), retry.
        if [ "$(id -u)" = 0 ] && [ -z "${apt_updated:-}" ]; then
            apt_updated=1
            apt-get update -qq >/dev/null 2>&1 || true
        fi
        (cd "$tmp" && apt-get download -q "$pkg" >/dev/null 2>&1) || { rm -rf "$tmp"; return 1; }
    fi
    dpkg-deb -x "$tmp"/*.deb "$llvm"
    rm -rf "$tmp"
}
if [ ! -e "$libdir/libLLVM-19.so" ] && command -v apt-get >/dev/null && command -v dpkg-deb >/dev/null; then
    mkdir -p "$llvm"
    if fetch_deb libllvm19; then
        # Unpack any shared library libLLVM needs that the system does not have.
        missing="$(ldd "$libdir"/libLLVM-19.so 2>/dev/null | awk '/not found/{print $1}' || true)"
        for lib in $missing; do
            case "$lib" in
                libedit.so.2) pkg=libedit2 ;; libffi.so.8) pkg=libffi8 ;;
                libxml2.so.2) pkg=libxml2 ;; libz3.so.4) pkg=libz3-4 ;;
                libzstd.so.1) pkg=libzstd1 ;; libz.so.1) pkg=zlib1g ;;
                libtinfo.so.6) pkg=libtinfo6 ;; libbsd.so.0) pkg=libbsd0 ;;
                libmd.so.0) pkg=libmd0 ;; libicuuc.so.72|libicudata.so.72) pkg=libicu72 ;;
                liblzma.so.5) pkg=liblzma5 ;; *) pkg="" ;;
            esac
            [ -n "$pkg" ] && fetch_deb "$pkg" || echo "setup.sh: warning: cannot fetch $lib for libLLVM 19" >&2
        done
    else
        echo "setup.sh: warning: 'apt-get download libllvm19' failed (no Debian 12 apt sources?)" >&2
    fi
fi

# --- check that a render works -------------------------------------------------
"$venv/bin/python" "$here/render.py" --selftest
