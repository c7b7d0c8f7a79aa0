#!/usr/bin/env python3
"""Extreme values for the experiment file's numeric keys, each run end to end.

Every case is a small full rig (64 x 64 mirrors, every optical stage, the joint method) with
one key set to an extreme value (0, -1, tiny, huge, NaN, infinities, ...) and run with
`specmux demo --npy`. Each must end one of two ways: exit 0 with a finite cube, channels and
frame (its report's warnings printed below it, to read for a degenerate run reported without
one), or a refusal — a non-zero exit whose stderr is one line starting "specmux:". A panic,
a NaN in an output, several lines of error or a run past the timeout is a failure, listed
with the file to rerun it. Too long for CI (about 2 s a case); run it by hand:

    cargo build --release && python3 tools/stress_keys.py --out /tmp/stress [--seed N --cases N]

needs numpy (reads the .npy outputs).
"""
import argparse
import json
import math
import random
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np

BASE = {
    "scene": {"source": "dead-leaves", "size": [64, 64]},
    "rig": {
        "dmd": {"width": 64, "height": 64, "dither": "in-band-feedback"},
        "fourier_filter": {"illumination": "coherent"},
        "lens": {},
        "alignment": {},
        "timing": {},
        "sensor": {},
    },
    "reconstruct": {"budget_s": 0.5, "gap": {"method": "joint"}, "joint": {"iterations": 20}},
}

# Numeric keys of the experiment file (their structs: sensor/config.rs, optics/dmd.rs,
# fourier_filter.rs, psf.rs, alignment.rs, timing/config.rs, core gap.rs and joint.rs).
FLOATS = """
scene.velocity_px_per_s
rig.sensor.full_well_e rig.sensor.electrons_at_full_scale rig.sensor.gain_dn_per_e
rig.sensor.read_noise_e rig.sensor.dark_current_e_per_s rig.sensor.dark_doubling_c
rig.sensor.temperature_c rig.sensor.reference_temperature_c rig.sensor.black_offset_dn
rig.sensor.prnu_fraction rig.sensor.dsnu_e rig.sensor.exposure_s rig.sensor.pixel_pitch_um
rig.dmd.pitch_um rig.dmd.fill_factor
rig.fourier_filter.focal_length_mm rig.fourier_filter.wavelength_nm
rig.fourier_filter.design_wavelength_nm rig.fourier_filter.pinhole_radius_um
rig.lens.na rig.lens.magnification rig.lens.camera_magnification rig.lens.sensor_pitch_um
rig.alignment.rotation_deg rig.alignment.magnification
rig.timing.wheel.rate_hz rig.timing.wheel.spot_diameter_mm rig.timing.wheel.index_offset_deg
rig.timing.dmd.max_rate_hz rig.timing.dmd.dark_time_s
rig.timing.camera.exposure_s rig.timing.camera.start_s rig.timing.camera.frame_rate_hz
rig.timing.camera.readout_s rig.timing.camera.max_frame_rate_hz
reconstruct.crop reconstruct.eta reconstruct.budget_s
reconstruct.gap.keep reconstruct.gap.level_ratio reconstruct.gap.tv_weight reconstruct.gap.floor
reconstruct.joint.tv_weight reconstruct.joint.step_ratio reconstruct.joint.relaxation
reconstruct.joint.pnp_weight reconstruct.joint.pnp_edge reconstruct.joint.reweight_eps
reconstruct.joint.dual_flush
""".split()
INTS = """
scene.seed rig.sensor.bits rig.sensor.seed rig.dmd.width rig.dmd.height rig.dmd.bayer_tile
rig.dmd.feedback_iterations reconstruct.basis calibration.frames calibration.search_bins
reconstruct.gap.iterations reconstruct.gap.levels reconstruct.gap.tv_iterations
reconstruct.joint.iterations reconstruct.joint.search_iterations reconstruct.joint.pnp_passes
reconstruct.joint.reweight_rounds
""".split()
FLOAT_VALUES = [0.0, -0.0, -1.0, 1e-300, 5e-324, 1e-9, 1e9, 1e300, math.nan, math.inf, -math.inf]
INT_VALUES = [0, 1, 2, 3, 7, 100000, 2**31, 2**62]
# Keys whose large values are legitimately slow: only up to this value.
SLOW = {"rig.dmd.width": 4096, "rig.dmd.height": 4096, "calibration.frames": 64,
        "reconstruct.gap.iterations": 2000, "reconstruct.gap.tv_iterations": 2000,
        "reconstruct.joint.iterations": 2000, "reconstruct.joint.search_iterations": 50,
        "reconstruct.joint.pnp_passes": 50, "reconstruct.joint.reweight_rounds": 20,
        "rig.dmd.feedback_iterations": 100}


def toml_value(v):
    """A TOML literal of a number, string, bool or list."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float) and math.isnan(v):
        return "nan"
    if isinstance(v, float) and math.isinf(v):
        return "inf" if v > 0 else "-inf"
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    return repr(v)


def to_toml(d, prefix=""):
    """The nested dict as TOML tables (enough for the experiment file's shape)."""
    plain = [f"{k} = {toml_value(v)}" for k, v in d.items() if not isinstance(v, dict)]
    out = [f"[{prefix}]"] + plain if prefix and (plain or not d) else plain
    for k, v in d.items():
        if isinstance(v, dict):
            out += to_toml(v, f"{prefix}.{k}" if prefix else k)
    return out


def with_key(key, value):
    """BASE with `key` (dotted) set to `value`."""
    exp = json.loads(json.dumps(BASE))
    *path, last = key.split(".")
    node = exp
    for p in path:
        node = node.setdefault(p, {})
    node[last] = value
    return exp


def cases(rng, n):
    """n (key, value) pairs, every key at least once when n allows."""
    pool = [(k, v) for k in FLOATS for v in FLOAT_VALUES]
    pool += [(k, v) for k in INTS for v in INT_VALUES if v <= SLOW.get(k, v)]
    rng.shuffle(pool)
    return pool[:n]


def finite_outputs(folder):
    """The name of the first output array holding a non-finite value, or None."""
    for name in ("frame", "channels", "cube"):
        a = np.load(folder / f"{name}.npy")
        if not np.isfinite(a).all():
            return name
    return None


def run_case(binary, folder, key, value, timeout):
    """'ok', 'refused' or a failure's description."""
    folder.mkdir(parents=True, exist_ok=True)
    exp = folder / "case.toml"
    exp.write_text("\n".join(to_toml(with_key(key, value))) + "\n")
    tomllib.loads(exp.read_text())  # the harness's own TOML must be valid
    cmd = [binary, "demo", "--scene", str(exp), "--out", str(folder / "out"), "--npy"]
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return f"timeout after {timeout} s"
    if "panicked" in p.stderr or p.returncode == 101:
        return "panic: " + p.stderr.strip().splitlines()[-1][:300]
    if p.returncode != 0:
        lines = [l for l in p.stderr.strip().splitlines() if l.startswith("specmux:")]
        if len(lines) != 1:
            return f"exit {p.returncode} without one 'specmux:' line: {p.stderr.strip()[-300:]}"
        return "refused"
    bad = finite_outputs(folder / "out")
    if bad:
        return f"non-finite {bad}"
    warnings = json.loads((folder / "out" / "report.json").read_text())["warnings"]
    return "ok" + "".join(f"\n    warning: {w[:160]}" for w in warnings)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--binary", default="target/release/specmux")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--cases", type=int, default=10**6, help="at most this many (default: all)")
    ap.add_argument("--timeout", type=float, default=120)
    a = ap.parse_args()
    counts, failures = {}, []
    todo = cases(random.Random(a.seed), a.cases)
    for i, (key, value) in enumerate(todo):
        folder = a.out / f"case{i:04d}"
        outcome = run_case(a.binary, folder, key, value, a.timeout)
        kind = outcome.split("\n")[0] if outcome.startswith(("ok", "refused")) else "failure"
        counts[kind] = counts.get(kind, 0) + 1
        print(f"{i + 1}/{len(todo)} {key} = {toml_value(value)}: {outcome}", flush=True)
        if kind == "failure":
            failures.append(f"{folder / 'case.toml'}: {key} = {toml_value(value)}: {outcome}")
    print("counts:", counts)
    print("\n".join(failures) if failures else "no failures")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
