"""An independent numpy implementation of specmux's ideal real-time pipeline (Fourier
demultiplexing + per-pixel unmixing) at 768², run beside specmux on the same frames.

Run (from the repository root; the binary is a release build of specmux, any path):

    python3 -m venv /tmp/np-venv && /tmp/np-venv/bin/pip install numpy scipy
    OPENBLAS_NUM_THREADS=1 /tmp/np-venv/bin/python tools/numpy_pipeline.py \
        --specmux bin/specmux-release [--scene dead-leaves|shaded-objects]... \
        [--repeats 10] [--nnls-pixels 0] [--work /tmp/numpy-pipeline]

For each scene it asks specmux for the frame, the truth, specmux's demultiplexed channels x̂
and its cube (`simulate --npy`, then `demo --npy` with `[reconstruct.gap] method = "fourier"`),
and builds everything else from what the rig knows: the default carriers (ideal gain ½, phase
0), crop 0.25 with the square window, η, J and the curve names of scenes/prototype.toml, the
curves of spectra/. It prints the agreement with specmux, PSNR against the truth, and the
median times of `--repeats` (≥ 10) runs with the load average. `--nnls-pixels 0` solves the
exact fit on every constrained pixel (about a minute for dead-leaves), N on a random sample.
docs/speed.md has the figures. Not part of CI.
"""

import argparse
import csv
import json
import os
import statistics
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import numpy as np
import scipy
from scipy.optimize import nnls

ROOT = Path(__file__).resolve().parent.parent
# The two built-in scenes with the seeds of scenes/prototype.toml and scenes/shaded-objects.toml
# (the ones README.md, docs/results.md and `cargo bench --bench pipeline` use).
SCENES = {"dead-leaves": 7, "shaded-objects": 11}
# specmux's default layout (docs/model.md), cycles/pixel (fx, fy), phase 0.
CARRIERS = [(0.25, 0.0), (0.0, 0.25), (0.25, 0.25), (-0.25, 0.25), (0.5, 0.25), (0.25, 0.5)]
# The e^{+iω·p} term of an ideal pattern 1 + cos(ω·p): amplitude ½.
GAIN = 0.5
GRID_NM = np.arange(400.0, 701.0, 10.0)


def read_curves(path):
    """A spectra/ CSV file: (wavelengths in nm, {column name: values})."""
    with open(path, newline="") as f:
        rows = [r for r in csv.reader(line for line in f if not line.startswith("#"))]
    data = np.array(rows[1:], dtype=float)
    return data[:, 0], {name: data[:, k + 1] for k, name in enumerate(rows[0][1:])}


def curve(spectra, name):
    """One curve `folder/file` (a two-column CSV) as (wavelengths, values)."""
    wl, cols = read_curves(spectra / f"{name}.csv")
    (values,) = cols.values()
    return wl, values


def evaluate(c, x):
    """Piecewise linear between samples, zero outside them (specmux's Curve::eval)."""
    return np.interp(x, c[0], c[1], left=0.0, right=0.0)


def channel_response(filters, light, qe):
    """A (channels × bands): ∫ T_i L QE hat_b dλ, exact (3-point Gauss–Legendre between the
    knots of all factors integrates their degree-4 product exactly), scaled so that a white
    reflector gives 1 in the brightest channel."""
    nodes, weights = np.polynomial.legendre.leggauss(3)
    step = GRID_NM[1] - GRID_NM[0]
    a = np.zeros((len(filters), len(GRID_NM)))
    for b, centre in enumerate(GRID_NM):
        lo, hi = max(centre - step, GRID_NM[0]), min(centre + step, GRID_NM[-1])
        hat = (GRID_NM, np.eye(len(GRID_NM))[b])
        for i, t in enumerate(filters):
            knots = np.concatenate([c[0] for c in (t, light, qe)] + [[lo, centre, hi]])
            knots = np.unique(knots[(knots >= lo) & (knots <= hi)])
            mid, half = (knots[1:] + knots[:-1]) / 2, (knots[1:] - knots[:-1]) / 2
            x = mid[:, None] + half[:, None] * nodes
            f = evaluate(t, x) * evaluate(light, x) * evaluate(qe, x) * evaluate(hat, x)
            a[i, b] = np.sum(half[:, None] * weights * f)
    return a / a.sum(axis=1).max()


def train_basis(spectra, j):
    """B (bands × J): uncentred PCA of the even-numbered reflectances of spectra/reflectance/
    (files sorted by name, columns in order), each vector signed to a non-negative sum."""
    samples = []
    for path in sorted((spectra / "reflectance").glob("*.csv")):
        wl, cols = read_curves(path)
        samples += [np.interp(GRID_NM, wl, v) for v in cols.values()]
    r = np.array(samples[::2]).T
    values, vectors = np.linalg.eigh(r @ r.T)
    b = vectors[:, np.argsort(values)[::-1][:j]]
    return b * np.where(b.sum(axis=0) < 0, -1.0, 1.0)


def unmix_matrices(a, b, eta):
    """F = A B, the Hessian H = FᵀF + η/Δλ⁴ (D₂B)ᵀ(D₂B) and P = B H⁻¹ Fᵀ (bands × channels), the
    unconstrained map from x̂ to the cube."""
    f = a @ b
    d2b = np.diff(np.eye(len(GRID_NM)), n=2, axis=0) @ b
    h = f.T @ f + eta / (GRID_NM[1] - GRID_NM[0]) ** 4 * d2b.T @ d2b
    return f, h, b @ np.linalg.solve(h, f.T)


class Demux:
    """Square window of w = crop·n bins around each carrier bin of the frame's real FFT, divided
    by the ideal gain ½ (phase 0), and the real part of its inverse, computed as the inverse of
    the window's Hermitian part on its columns kx ∈ [0, ⌊w/2⌋] only (ifft along y, then irfft
    along x). The default carriers lie on bins, so nothing is left to demodulate."""

    def __init__(self, n, crop):
        w = round(crop * n)
        self.n, self.half = n, w // 2
        # The window spans d ∈ [−⌊w/2⌋, w − ⌊w/2⌋); the array runs over the symmetric range
        # [−⌊w/2⌋, ⌊w/2⌋] so that reversing it maps d to −d, with the bins outside weighed 0.
        d = np.arange(-self.half, self.half + 1)
        self.inside = (d < w - self.half)[:, None] & (d < w - self.half)[None, :]
        kx = np.array([np.broadcast_to(round(fx * n) + d, (len(d), len(d))) for fx, _ in CARRIERS])
        ky = np.array([np.broadcast_to(round(fy * n) + d[:, None], (len(d), len(d)))
                       for _, fy in CARRIERS])
        kx, ky = kx % n, ky % n
        # Bins with kx > n/2 are read as the conjugate of (−kx, −ky) in the half spectrum.
        self.conj = kx > n // 2
        self.ky = np.where(self.conj, -ky % n, ky)
        self.kx = np.where(self.conj, -kx % n, kx)
        self.rows = d % n

    def run(self, frame):
        """x̂ (channels × n × n, float32) of a float32 frame."""
        y = np.fft.rfft2(frame)
        z = y[self.ky, self.kx]
        z = np.where(self.conj, z.conj(), z) * self.inside / GAIN
        # Hermitian part (Z(d) + Z*(−d))/2 on dx ≥ 0; the window's array holds d and −d.
        mirror = z[:, ::-1, ::-1].conj()
        herm = 0.5 * (z + mirror)[:, :, self.half:]
        cols = np.zeros((len(CARRIERS), self.n, herm.shape[2]), dtype=herm.dtype)
        cols[:, self.rows, :] = herm
        return np.fft.irfft(np.fft.ifft(cols, axis=1), n=self.n, axis=2)


def unmix(p32, xhat, out=None):
    """The unconstrained cube P x̂ (bands × n × n): one matrix product for every pixel, written
    into `out` (bands × n·n, float32) when given, as a real-time loop reuses its output."""
    c, h, w = xhat.shape
    return np.matmul(p32, xhat.reshape(c, -1), out=out).reshape(-1, h, w)


def exact_pixel(f, h, b, xhat):
    """argmin ‖x̂ − Fα‖² + η'‖D₂Bα‖² s.t. Bα ≥ 0, exactly: with H = LLᵀ and β = Lᵀα it is the
    least-distance problem min ‖γ‖ s.t. Gγ ≥ −Gβ₀ (β = β₀ + γ, G = B L⁻ᵀ), solved by Lawson
    and Hanson's reduction to one NNLS of [Gᵀ; −(Gβ₀)ᵀ] u ≈ (0, …, 0, 1). Returns r = Bα."""
    l = np.linalg.cholesky(h)
    beta0 = np.linalg.solve(l, f.T @ xhat)
    g = np.linalg.solve(l, b.T).T
    e = np.vstack([g.T, -(g @ beta0)[None, :]])
    target = np.zeros(e.shape[0])
    target[-1] = 1.0
    u, _ = nnls(e, target)
    resid = e @ u - target
    gamma = -resid[:-1] / resid[-1]
    return b @ np.linalg.solve(l.T, beta0 + gamma)


def psnr(truth, estimate):
    """specmux's PSNR: per plane, peak = the truth's maximum over the cube, mean over planes."""
    peak = float(truth.max())
    mse = ((truth.astype(np.float64) - estimate) ** 2).reshape(len(truth), -1).mean(axis=1)
    return float(np.mean(10 * np.log10(peak * peak / mse)))


def median_time(fn, repeats):
    """Wall seconds of `repeats` calls (median, min, max) and the 1-minute load average before
    and after."""
    load = [os.getloadavg()[0]]
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    load.append(os.getloadavg()[0])
    return (statistics.median(times), min(times), max(times)), load


def specmux_outputs(binary, scene, work, repeats):
    """Run specmux: the frame and truth (`simulate`), x̂ and the cube of the Fourier method
    (`demo`, `repeats` times); returns the arrays and the medians of demo's stage seconds."""
    exp = work / f"{scene}-fourier.toml"
    exp.write_text(f'[scene]\nsource = "{scene}"\nseed = {SCENES[scene]}\n'
                   '[reconstruct.gap]\nmethod = "fourier"\n')
    sim, demo = work / f"{scene}-simulate", work / f"{scene}-demo"
    subprocess.run([binary, "simulate", exp, "--npy", "--out", sim], check=True,
                   stdout=subprocess.DEVNULL)
    stages = {"demultiplex": [], "unmix": [], "reconstruction": []}
    for _ in range(repeats):
        subprocess.run([binary, "demo", "--scene", exp, "--npy", "--out", demo], check=True,
                       stdout=subprocess.DEVNULL)
        report = json.loads((demo / "report.json").read_text())
        for row in report["results"]:
            if row["stage"] in stages:
                stages[row["stage"]].append(row["seconds"])
        stages["reconstruction"].append(report["reconstruction_seconds"])
    arrays = {k: np.load(d / f"{k}.npy") for d, k in
              [(sim, "frame"), (sim, "truth"), (demo, "channels"), (demo, "cube")]}
    if not np.array_equal(arrays["frame"], np.load(demo / "frame.npy")):
        sys.exit(f"numpy_pipeline: {scene}: simulate and demo recorded different frames")
    return arrays, {k: statistics.median(v) for k, v in stages.items()}


def compare(scene, args, rig):
    """Everything printed for one scene."""
    a, p = rig[0], rig[4]
    data, sm = specmux_outputs(args.specmux, scene, args.work, args.specmux_repeats)
    frame, truth = data["frame"], data["truth"]
    if frame.shape[0] != frame.shape[1]:
        sys.exit(f"numpy_pipeline: frame {frame.shape}: only square frames are implemented")
    demux = Demux(frame.shape[0], args.design["reconstruct"]["crop"])
    xhat = demux.run(frame)
    cube = unmix(p.astype(np.float32), xhat)
    x_true = np.einsum("cb,bhw->chw", a, truth.astype(np.float64))
    diff = np.abs(xhat - data["channels"])
    print(f"\n## {scene} (seed {SCENES[scene]}, {frame.shape[1]}×{frame.shape[0]})")
    print(f"x̂ numpy − specmux: max |Δ| {diff.max():.3e}, rms {np.sqrt((diff**2).mean()):.3e}, "
          f"channel range {data['channels'].min():.3f}..{data['channels'].max():.3f}")
    print(f"x̂ against the true channels A·r: numpy {psnr(x_true, xhat):.2f} dB, "
          f"specmux {psnr(x_true, data['channels']):.2f} dB")
    neg = (cube < 0).any(axis=0)
    print(f"cube against the truth: numpy unconstrained P·x̂ {psnr(truth, cube):.2f} dB "
          f"({neg.sum()} of {neg.size} pixels have a negative band), "
          f"specmux exact non-negative {psnr(truth, data['cube']):.2f} dB")
    exact_check(args, rig, xhat, cube, data, neg)
    timings(args, demux, p, frame, sm)


def exact_check(args, rig, xhat, cube, data, neg):
    """The exact non-negative fit (scipy NNLS per pixel, a Python loop) on the pixels where the
    unconstrained cube has a negative band (all of them, or a random `--nnls-pixels` sample):
    numpy's exact cube against the truth, and the same solver fed specmux's x̂ against specmux's
    cube (both solvers exact: they differ by round-off only)."""
    b, f, h = rig[1], rig[2], rig[3]
    idx = np.flatnonzero(neg.ravel())
    if args.nnls_pixels:
        rng = np.random.default_rng(0)
        idx = np.sort(rng.choice(idx, size=min(args.nnls_pixels, idx.size), replace=False))
    flat = lambda c: c.reshape(len(c), -1)[:, idx].astype(np.float64)
    t0 = time.perf_counter()
    ours = np.array([exact_pixel(f, h, b, x) for x in flat(xhat).T]).T
    per_pixel = (time.perf_counter() - t0) / len(idx)
    theirs = np.array([exact_pixel(f, h, b, x) for x in flat(data["channels"]).T]).T
    gap = np.abs(theirs - flat(data["cube"]))
    truth = flat(data["truth"])
    rmse = lambda c: np.sqrt(((c - truth) ** 2).mean())
    if len(idx) == neg.sum():
        exact = cube.reshape(len(cube), -1).copy()
        exact[:, idx] = ours
        whole = f"; numpy's exact cube {psnr(data['truth'], exact.reshape(cube.shape)):.2f} dB"
    else:
        whole = ""
    print(f"exact non-negative fit of {len(idx)} of the {neg.sum()} constrained pixels (scipy NNLS "
          f"of the LDP form, {per_pixel * 1e6:.0f} µs/pixel in a Python loop): RMSE to the truth "
          f"there: unconstrained {rmse(flat(cube)):.4f}, numpy exact {rmse(ours):.4f}, specmux "
          f"{rmse(flat(data['cube'])):.4f}{whole}; NNLS on specmux's x̂ against specmux's cube: "
          f"max |Δ| {gap.max():.2e}, 99.9th percentile {np.percentile(gap, 99.9):.2e}, median "
          f"{np.median(gap):.2e} (cube peak {data['cube'].max():.3f})")


def timings(args, demux, p, frame, sm):
    """Medians of numpy's stages beside specmux `demo`'s stage seconds."""
    p32 = p.astype(np.float32)
    xhat = demux.run(frame)
    out = np.empty((p32.shape[0], xhat[0].size), dtype=np.float32)
    d, ld = median_time(lambda: demux.run(frame), args.repeats)
    u, lu = median_time(lambda: unmix(p32, xhat, out), args.repeats)
    w, lw = median_time(lambda: unmix(p32, demux.run(frame), out), args.repeats)
    fmt = lambda t, l: (f"{t[0] * 1e3:.1f} ms [{t[1] * 1e3:.1f}, {t[2] * 1e3:.1f}] "
                        f"(load {l[0]:.2f}→{l[1]:.2f})")
    print(f"numpy medians of {args.repeats} [min, max]: demultiplex {fmt(d, ld)}, unconstrained "
          f"unmix, output reused {fmt(u, lu)}, whole {fmt(w, lw)}")
    print(f"specmux demo medians of {args.specmux_repeats} (stage seconds of report.json, first "
          f"frame of a process, Fourier method): demultiplex {sm['demultiplex'] * 1e3:.1f} ms, "
          f"exact non-negative unmix {sm['unmix'] * 1e3:.1f} ms, "
          f"reconstruction {sm['reconstruction'] * 1e3:.1f} ms")


def build_rig(args):
    """A, B, F, H, P from the curves named in scenes/prototype.toml and the spectra folder."""
    design = args.design
    names = design["rig"]["wheel"]["filters"]
    filters = [curve(args.spectra, n) for n in names]
    light = curve(args.spectra, design["scene"]["illuminant"])
    qe = curve(args.spectra, design["rig"]["camera"]["qe"])
    a = channel_response(filters, light, qe)
    b = train_basis(args.spectra, design["reconstruct"]["basis"])
    return (a, b, *unmix_matrices(a, b, design["reconstruct"]["eta"]))


class Parser(argparse.ArgumentParser):
    """argparse, its errors in one line without the usage."""

    def error(self, message):
        sys.exit(f"numpy_pipeline: {message}")


def parse_args():
    """Arguments; a bad one ends the run with a one-line message."""
    ap = Parser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--specmux", type=Path, default=ROOT / "bin" / "specmux-release",
                    help="a release build of specmux")
    ap.add_argument("--scene", action="append", choices=sorted(SCENES), help="default: both")
    ap.add_argument("--repeats", type=int, default=10, help="numpy timing repeats, ≥ 10")
    ap.add_argument("--specmux-repeats", type=int, default=5, help="specmux demo processes")
    ap.add_argument("--nnls-pixels", type=int, default=0,
                    help="exact fit on a sample of N constrained pixels; 0: all")
    ap.add_argument("--work", type=Path, default=Path("/tmp/numpy-pipeline"),
                    help="where specmux writes its outputs")
    ap.add_argument("--spectra", type=Path, default=ROOT / "spectra", help="the curves")
    args = ap.parse_args()
    fail = lambda msg: sys.exit(f"numpy_pipeline: {msg}")
    if args.repeats < 10:
        fail(f"--repeats {args.repeats}: at least 10")
    if args.specmux_repeats < 1 or args.nnls_pixels < 0:
        fail("--specmux-repeats must be ≥ 1 and --nnls-pixels ≥ 0 (0: every constrained pixel)")
    if not os.access(args.specmux, os.X_OK):
        fail(f"--specmux {args.specmux}: not an executable file")
    if not (args.spectra / "reflectance").is_dir():
        fail(f"--spectra {args.spectra}: no reflectance/ folder in it")
    # specmux's defaults, which this file writes out: the rig the experiments below run on.
    args.design = tomllib.loads((ROOT / "scenes" / "prototype.toml").read_text())
    args.scene = args.scene or sorted(SCENES)
    args.work.mkdir(parents=True, exist_ok=True)
    return args


def main():
    args = parse_args()
    threads = {k: os.environ.get(k, "unset") for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}
    print(f"numpy {np.__version__}, scipy {scipy.__version__}, Python {sys.version.split()[0]}, "
          f"{os.cpu_count()} CPUs, {threads}; numpy's FFT is single-threaded, the matrix "
          f"product uses OpenBLAS threads")
    rig = build_rig(args)
    for scene in args.scene:
        compare(scene, args, rig)


if __name__ == "__main__":
    main()
