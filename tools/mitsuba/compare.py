#!/usr/bin/env python3
"""Monte Carlo noise of the Mitsuba renders, from two renders that differ only in the seed.

  compare.py noise --a DIR_A --b DIR_B --scene chart [--store]
      per channel c = σ_p·√spp, σ_p = std over pixels of (a−b)/((a+b)/2) / √2 (the per-pixel
      relative std of one render); prints the median c of the truth and of the wheel channels;
      --store writes c per channel into DIR_A/<scene>.json ("noise").
  compare.py check --ref DIR_REF --live DIR_LIVE --scene chart
      the CI test (.ci/mitsuba-check.sh): per channel, with σ_p = c/√spp from the reference
      sidecar, (1) Δ = mean(live−ref)/mean(ref) must satisfy |Δ| < 5·sd_Δ, where
      sd_Δ = √2·σ_p·√(Σx²)/Σx over the N pixels (= √2·σ_p/√N for a flat image), and
      (2) std over pixels of (live−ref)/((live+ref)/2) must be √2·σ_p within 30%.
      Exits 1 on any failure; prints a one-line summary.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))


def load(dirpath: Path, scene: str):
    import render

    meta = json.loads((dirpath / f"{scene}.json").read_text())
    planes, names = [], []
    for part in ("truth", "wheel"):
        arr, nm = render.read_exr(dirpath / f"{scene}_{part}.exr")
        planes.append(arr.astype(np.float64))
        names += nm
    return np.concatenate(planes, -1), names, meta


def rel_pixel_diff(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(a−b)/((a+b)/2) per pixel and channel, over pixels whose mean is above 1e-3 of the
    channel mean (so no division by a near-zero pixel); others are NaN."""
    m = (a + b) / 2
    ok = m > 1e-3 * m.mean(axis=(0, 1), keepdims=True)
    return np.where(ok, (a - b) / np.where(ok, m, 1.0), np.nan)


def noise(a: Path, b: Path, scene: str, store: bool) -> dict:
    import mitsuba as mi  # noqa: F401  (render.read_exr needs a variant)

    mi.set_variant("scalar_spectral")
    xa, names, ma = load(a, scene)
    xb, names_b, mb = load(b, scene)
    if names != names_b or ma["spp"] != mb["spp"] or ma["seed"] == mb["seed"]:
        raise SystemExit("noise: the two renders must share channels and spp, not the seed")
    r = rel_pixel_diff(xa, xb)
    c = np.nanstd(r, axis=(0, 1)) / np.sqrt(2) * np.sqrt(ma["spp"])
    nb = len(ma["truth"]["channels"])
    out = {"c_per_channel": dict(zip(names, map(float, c))),
           "median_c_truth": float(np.median(c[:nb])),
           "median_c_wheel": float(np.median(c[nb:])),
           "spp": ma["spp"], "seeds": [ma["seed"], mb["seed"]],
           "definition": "per-pixel relative std of one render = c/sqrt(spp)"}
    print(f"{scene} {ma['spp']} spp: c = σ_p·√spp median truth {out['median_c_truth']:.3f} "
          f"(range {c[:nb].min():.3f}-{c[:nb].max():.3f}), wheel {out['median_c_wheel']:.3f} "
          f"(range {c[nb:].min():.3f}-{c[nb:].max():.3f})")
    if store:
        ma["noise"] = out
        (a / f"{scene}.json").write_text(json.dumps(ma, indent=1) + "\n")
    return out


def check(ref: Path, live: Path, scene: str) -> bool:
    import mitsuba as mi  # noqa: F401

    mi.set_variant("scalar_spectral")
    xr, names, mr = load(ref, scene)
    xl, names_l, ml = load(live, scene)
    if names != names_l or xr.shape != xl.shape or mr["spp"] != ml["spp"]:
        print(f"mitsuba-check FAILED: {scene}: live render does not match the fixture layout")
        return False
    c = np.array([mr["noise"]["c_per_channel"][n] for n in names])
    sigma = c / np.sqrt(mr["spp"])
    sx = xr.sum(axis=(0, 1))
    sd_mean = np.sqrt(2) * sigma * np.sqrt((xr ** 2).sum(axis=(0, 1))) / sx
    delta = (xl - xr).sum(axis=(0, 1)) / sx
    z = np.abs(delta) / sd_mean
    ratio = np.nanstd(rel_pixel_diff(xl, xr), axis=(0, 1)) / (np.sqrt(2) * sigma)
    bad = [f"{n}: |Δ|={abs(d):.2e} ({zz:.1f} sd)" for n, d, zz in zip(names, delta, z) if zz >= 5]
    bad += [f"{n}: pixel-diff std / expected = {q:.2f}" for n, q in zip(names, ratio)
            if abs(q - 1) > 0.3]
    ok = not bad
    print(f"mitsuba-check {'ok' if ok else 'FAILED'}: {scene} {mr['size'][0]}x{mr['size'][1]} "
          f"{mr['spp']} spp seeds {mr['seed']}/{ml['seed']} {ml['variant']} "
          f"{ml['render_seconds']} s; {len(names)} channels: max |Δ|/sd = {z.max():.2f} (< 5), "
          f"pixel-diff std ratio {ratio.min():.2f}-{ratio.max():.2f} (1 ± 0.3)"
          + ("" if ok else "; " + "; ".join(bad[:6])))
    return ok


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    n = sub.add_parser("noise")
    n.add_argument("--a", type=Path, required=True)
    n.add_argument("--b", type=Path, required=True)
    n.add_argument("--scene", required=True)
    n.add_argument("--store", action="store_true")
    k = sub.add_parser("check")
    k.add_argument("--ref", type=Path, required=True)
    k.add_argument("--live", type=Path, required=True)
    k.add_argument("--scene", required=True)
    a = ap.parse_args()
    if a.cmd == "noise":
        noise(a.a, a.b, a.scene, a.store)
    else:
        sys.exit(0 if check(a.ref, a.live, a.scene) else 1)


if __name__ == "__main__":
    main()
