"""Where a reconstructed cube's error lies: inside or outside the spectral basis B, and inside
along the right singular vectors of the system F = A·B (strongly or weakly seen by the filters).

Run (from the repository root, with the venv of tools/numpy_pipeline.py):

    specmux simulate dead-leaves --npy --out /tmp/ed/sim
    specmux demo --scene EXP --npy --out /tmp/ed/demo       # EXP: the reconstruction to study
    /tmp/np-venv/bin/python tools/error_directions.py /tmp/ed/sim/truth.npy /tmp/ed/demo/cube.npy

The rig is scenes/prototype.toml's (A and B built as tools/numpy_pipeline.py builds them), so
the cube must come from an experiment with that rig. Not part of CI; docs/results.md quotes it.
"""

import sys
import tomllib
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import numpy_pipeline as npp  # noqa: E402


def load(path, bands):
    """A (bands, h, w) cube from .npy as float64, or exit with a one-line message."""
    try:
        c = np.load(path).astype(np.float64)
    except (OSError, ValueError) as e:
        sys.exit(f"error_directions: {path}: {e}")
    if c.ndim != 3 or c.shape[0] != bands:
        sys.exit(f"error_directions: {path}: shape {c.shape}, expected ({bands}, h, w)")
    return c.reshape(bands, -1)


def main():
    if len(sys.argv) != 3:
        sys.exit("error_directions: usage: error_directions.py TRUTH.npy CUBE.npy")
    args = type("Args", (), {})()
    args.design = tomllib.loads((npp.ROOT / "scenes" / "prototype.toml").read_text())
    args.spectra = npp.ROOT / "spectra"
    a, b, *_ = npp.build_rig(args)
    truth, cube = (load(p, b.shape[0]) for p in sys.argv[1:])
    if truth.shape != cube.shape:
        sys.exit(f"error_directions: truth {truth.shape} and cube {cube.shape} differ in size")
    err = cube - truth
    inside = b @ (b.T @ err)
    print(f"cube error mean square {np.mean(err**2):.4g}: inside B {np.mean(inside**2):.4g}, "
          f"outside {np.mean((err - inside)**2):.4g} "
          f"(the truth's own part outside B: {np.mean((truth - b @ (b.T @ truth))**2):.4g})")
    _, s, vt = np.linalg.svd(a @ b)
    d_err, d_true = vt @ (b.T @ err), vt @ (b.T @ truth)
    print("direction  singular value  error rms  truth rms  channel error rms (s·error)")
    for i, sv in enumerate(s):
        e = np.sqrt(np.mean(d_err[i] ** 2))
        t = np.sqrt(np.mean(d_true[i] ** 2))
        print(f"{i:9d}  {sv:14.4g}  {e:9.4f}  {t:9.4f}  {sv * e:9.4f}")


if __name__ == "__main__":
    main()
