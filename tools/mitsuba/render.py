#!/usr/bin/env python3
"""Render the Mitsuba 3 spectral cross-check scenes: per scene ONE render with ONE specfilm
whose channels are the truth bands (hat functions on the 400-700 nm grid) and the six wheel
channels (T_i·QE). Writes <scene>_truth.exr, <scene>_wheel.exr and <scene>.json.

  tools/.venv-mitsuba/bin/python tools/mitsuba/render.py --out tests/fixtures/mitsuba
  ... render.py --scenes chart --size 256 --spp 1024 --seed 7 --out out/mitsuba
  ... render.py --selftest            (checks the specfilm convention; used by setup.sh)
  ... render.py --bias                (deterministic check of the hat route, no rendering)

Conventions (docs/mitsuba.md): λ in nm; specfilm channel j = ∫ S_j(λ) L(λ) dλ with L the
spectral radiance reaching the pixel, no normalisation. Truth EXR channel `{wl:06.1f}nm` holds
m_b / ∫h_b dλ (m_b = ∫ h_b L dλ; ∫h_b = step, step/2 at 400 and 700 nm): a hat-weighted mean
radiance. Wheel EXR channel `f<i>_<filter>` holds ∫_400^700 T_i QE L dλ.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import spectral as sp  # noqa: E402

LLVM_DIR = HERE.parent / ".llvm" / "usr" / "lib" / "x86_64-linux-gnu"
VARIANTS = ["llvm_ad_spectral", "scalar_spectral"]


def llvm19_path() -> str | None:
    """libLLVM 19 for Dr.Jit: $DRJIT_LIBLLVM_PATH, else the copy setup.sh put in tools/.llvm."""
    p = os.environ.get("DRJIT_LIBLLVM_PATH")
    if p:
        return p if Path(p).exists() else None
    q = LLVM_DIR / "libLLVM-19.so"
    return str(q) if q.exists() else None


def choose_variant(requested: str) -> str:
    """`auto`: llvm_ad_spectral when libLLVM 19 is present and a self-test render passes in a
    subprocess (an older LLVM aborts the process, so it is never tried in-process), otherwise
    scalar_spectral with a warning."""
    if requested != "auto":
        return requested
    if llvm19_path() is not None:
        r = subprocess.run([sys.executable, __file__, "--selftest", "--variant",
                            "llvm_ad_spectral", "--quiet"], capture_output=True, text=True)
        if r.returncode == 0:
            return "llvm_ad_spectral"
        print(f"warning: llvm_ad_spectral self-test failed ({r.stderr.strip()[-300:]}); "
              "using scalar_spectral (about 4x slower)", file=sys.stderr)
    else:
        print("warning: libLLVM 19 not found (run tools/mitsuba/setup.sh or set "
              "DRJIT_LIBLLVM_PATH); using scalar_spectral (about 4x slower)", file=sys.stderr)
    return "scalar_spectral"


def import_mitsuba(variant: str):
    if variant.startswith("llvm"):
        p = llvm19_path()
        if p is None:
            raise SystemExit(f"variant {variant} needs libLLVM 19: run tools/mitsuba/setup.sh")
        os.environ["DRJIT_LIBLLVM_PATH"] = p
    import drjit as dr
    import mitsuba as mi

    mi.set_variant(variant)
    return mi, dr


def sens_dict(c: sp.Curve) -> dict:
    return {"type": "spectrum", "value": c.pairs()}


def channel_plan(step: float):
    """The specfilm's curves in channel order: truth hats, then wheel sensitivities.
    Returns (exr names, sensitivity curves, number of truth channels)."""
    centres = sp.band_centres(step)
    names = [f"{wl:06.1f}nm" for wl in centres]
    curves = [sp.hat(wl, step) for wl in centres]
    wheel = sp.wheel_sensitivities()
    return names + list(wheel), curves + list(wheel.values()), len(centres)


def render_scene(name: str, size: int, spp: int, seed: int, step: float, variant: str):
    """One render. Returns (truth [H,W,B] in EXR units, wheel [H,W,6], metadata dict)."""
    mi, dr = import_mitsuba(variant)
    import scenes

    sc = scenes.SCENES[name]()
    names, curves, nb = channel_plan(step)
    film = {"type": "specfilm", "width": size, "height": size,
            "component_format": "float32", "rfilter": {"type": "box"}}
    # Keys sort like the channel order (the film orders channels by key).
    for j, c in enumerate(curves):
        film[f"ch{j:03d}"] = sens_dict(c)
    d = dict(sc.dict)
    d["sensor"] = dict(d["sensor"], film=film,
                       sampler={"type": "independent", "sample_count": spp})
    d["integrator"] = {"type": "path", "max_depth": sc.max_depth}
    scene = mi.load_dict(d)
    t0 = time.perf_counter()
    img = mi.render(scene, seed=seed)
    arr = np.array(img, dtype=np.float64)
    seconds = time.perf_counter() - t0
    if arr.shape != (size, size, len(curves)):
        raise RuntimeError(f"specfilm returned {arr.shape}, expected {(size, size, len(curves))}")
    truth = arr[..., :nb] / sp.hat_weights(step)
    wheel = arr[..., nb:]
    meta = {
        "scene": name,
        "description": sc.description,
        "size": [size, size],
        "spp": spp,
        "seed": seed,
        "variant": variant,
        "mitsuba_version": mi.__version__,
        "drjit_version": dr.__version__,
        "integrator": {"type": "path", "max_depth": sc.max_depth},
        "render_seconds": round(seconds, 3),
        "truth": {
            "step_nm": step,
            "channels": names[:nb],
            "centres_nm": sp.band_centres(step).tolist(),
            "weights_nm": sp.hat_weights(step).tolist(),
            "definition": "channel b = m_b / weight_b, m_b = ∫ h_b(λ) L(λ) dλ; h_b = hat, 1 at "
                          "centre_b, 0 at centre_b ± step_nm, cut to [400, 700] nm",
        },
        "wheel": {
            "channels": names[nb:],
            "filters": sp.WHEEL,
            "qe": sp.QE,
            "definition": "channel i = ∫_400^700 S_i(λ) L(λ) dλ, S_i = T_i·QE sampled every "
                          "1 nm on [400, 700] nm, linear in between, 0 outside",
        },
        "units": "L = spectral radiance in the units of spectra/illuminants/D65.csv per nm "
                 "(CSV verbatim); λ in nm; no normalisation",
        "orientation": "row 0 = top of image, column x grows to the right",
    }
    return truth.astype(np.float32), wheel.astype(np.float32), meta


def write_exr(path: Path, planes: np.ndarray, names: list[str]):
    import mitsuba as mi

    bmp = mi.Bitmap(np.ascontiguousarray(planes, dtype=np.float32),
                    pixel_format=mi.Bitmap.PixelFormat.MultiChannel, channel_names=names)
    tmp = path.with_suffix(".tmp.exr")
    bmp.write(str(tmp))
    os.replace(tmp, path)


def read_exr(path: Path) -> tuple[np.ndarray, list[str]]:
    """Planes [H,W,C] and names, in name order (as the Rust side sees them)."""
    import mitsuba as mi

    bmp = mi.Bitmap(str(path))
    names = [bmp.struct_()[k].name for k in range(bmp.channel_count())]
    arr = np.array(bmp, dtype=np.float32).reshape(bmp.height(), bmp.width(), -1)
    order = np.argsort(names)
    return arr[..., order], [names[k] for k in order]


def agreement(truth: np.ndarray, wheel: np.ndarray, step: float) -> list[dict]:
    """Per filter: Σ_b c_b W_ib from the truth channels vs the wheel channel of the same
    render. Δ = mean(pred − wheel)/mean(wheel); its Monte Carlo std is estimated from the
    per-pixel scatter of (pred − wheel) over the N pixels: std(pred−wheel)/√N/mean(wheel)."""
    W = sp.hat_projection_matrix(sp.wheel_sensitivities(), step)
    pred = sp.wheel_from_truth(truth.astype(np.float64), step, W)
    out = []
    names = list(sp.wheel_sensitivities())
    n = truth.shape[0] * truth.shape[1]
    for i, nm in enumerate(names):
        d = (pred[..., i] - wheel[..., i]).ravel()
        mean = float(np.mean(wheel[..., i]))
        out.append({"filter": nm, "rel_diff": float(np.mean(d) / mean),
                    "mc_std": float(np.std(d) / np.sqrt(n) / mean)})
    return out


def chart_patch_check(truth: np.ndarray, step: float) -> dict:
    """Chart only: truth channels averaged over the central 4×4 pixels of each patch vs the
    exact value (1/weight_b)·∫ h_b r E/π dλ (Lambertian patch under the frontal directional
    light). Returns the worst |Δ|/σ (σ from the pixel scatter) and the worst relative error."""
    import scenes as scn

    cc = sp.read_csv("reflectance/colorchecker")
    illum = sp.curve("illuminants/D65")
    n = truth.shape[0]
    hats = [sp.hat(c, step) for c in sp.band_centres(step)]
    w = sp.hat_weights(step)
    worst_sig, worst_rel = 0.0, 0.0
    for k, name in enumerate(cc):
        x, y = scn.chart_patch_centre(k)
        col = int(round((x + scn.CHART_HALF) / (2 * scn.CHART_HALF) * n - 0.5))
        row = int(round((scn.CHART_HALF - y) / (2 * scn.CHART_HALF) * n - 0.5))
        block = truth[row - 1:row + 3, col - 1:col + 3].reshape(16, -1).astype(np.float64)
        exact = np.array([sp.integrate(h, cc[name], illum) for h in hats]) / w / np.pi
        m, s = block.mean(0), block.std(0) / 4.0
        worst_sig = max(worst_sig, float(np.max(np.abs(m - exact) / s)))
        worst_rel = max(worst_rel, float(np.max(np.abs(m - exact) / exact)))
    return {"worst_abs_dev_over_sigma": worst_sig, "worst_rel_dev": worst_rel}


def bias_table(step: float) -> dict:
    """Deterministic relative bias of the hat route for every radiance spectrum each scene can
    produce (scenes.py, direct light and bounces up to two surfaces): max |bias| per filter."""
    import scenes as scn

    sens = sp.wheel_sensitivities()
    out = {}
    for name, build in scn.SCENES.items():
        spectra = build(build=False).spectra
        b = np.array([sp.projection_bias(f, step, sens) for f in spectra])
        out[name] = {"n_spectra": len(spectra),
                     "max_abs_rel_bias": {k: float(v) for k, v in zip(sens, np.abs(b).max(0))}}
    return out


def selftest(variant: str, quiet: bool) -> None:
    """Flat radiance 1 seen directly: a flat sensitivity on [400,700] must give 300 and a
    10 nm hat 10 (the specfilm convention: ∫ S L dλ in nm, no normalisation)."""
    mi, _ = import_mitsuba(variant)
    film = {"type": "specfilm", "width": 8, "height": 8, "component_format": "float32",
            "a": {"type": "spectrum", "value": [(400.0, 1.0), (700.0, 1.0)]},
            "b": {"type": "spectrum", "value": [(540.0, 0.0), (550.0, 1.0), (560.0, 0.0)]}}
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "path", "max_depth": 2},
        "env": {"type": "constant", "radiance": {"type": "spectrum", "value": 1.0}},
        "sensor": {"type": "perspective", "film": film,
                   "sampler": {"type": "independent", "sample_count": 256}}})
    a = np.array(mi.render(scene, seed=3), dtype=np.float64).reshape(-1, 2)
    m, e = a.mean(0), a.std(0) / np.sqrt(len(a))
    ok = all(abs(m[k] - v) < 5 * e[k] + 1e-6 * v for k, v in enumerate([300.0, 10.0]))
    if not quiet or not ok:
        print(f"selftest {variant} mitsuba {mi.__version__}: flat→{m[0]:.3f}±{e[0]:.3f} "
              f"(300), hat→{m[1]:.4f}±{e[1]:.4f} (10): {'ok' if ok else 'FAILED'}")
    if not ok:
        raise SystemExit(1)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenes", default="chart,cornell,strips")
    ap.add_argument("--size", type=int, default=64)
    ap.add_argument("--spp", type=int, default=1024)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--step", type=float, default=10.0, help="truth hat spacing, nm")
    ap.add_argument("--variant", default="auto", choices=["auto"] + VARIANTS)
    ap.add_argument("--out", type=Path, default=Path("out/mitsuba"))
    ap.add_argument("--selftest", action="store_true")
    ap.add_argument("--bias", action="store_true")
    ap.add_argument("--quiet", action="store_true")
    a = ap.parse_args(argv)
    if a.bias:
        print(json.dumps(bias_table(a.step), indent=1))
        return
    variant = choose_variant(a.variant)
    if a.selftest:
        selftest(variant, a.quiet)
        return
    a.out.mkdir(parents=True, exist_ok=True)
    for name in a.scenes.split(","):
        truth, wheel, meta = render_scene(name, a.size, a.spp, a.seed, a.step, variant)
        meta["agreement"] = agreement(truth, wheel, a.step)
        if name == "chart":
            meta["exact_patch_check"] = chart_patch_check(truth, a.step)
        write_exr(a.out / f"{name}_truth.exr", truth, meta["truth"]["channels"])
        write_exr(a.out / f"{name}_wheel.exr", wheel, meta["wheel"]["channels"])
        side = a.out / f"{name}.json"
        side.write_text(json.dumps(meta, indent=1) + "\n")
        worst = max(abs(r["rel_diff"]) / r["mc_std"] for r in meta["agreement"])
        print(f"{name}: {a.size}x{a.size} {a.spp} spp {variant} {meta['render_seconds']} s; "
              f"hat route vs wheel: worst |Δ|/σ = {worst:.2f}")


if __name__ == "__main__":
    main()
