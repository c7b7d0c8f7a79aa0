"""Spectral curves from spectra/*.csv and the band sensitivities of the Mitsuba cross-check.

Every curve is piecewise linear between its samples and zero outside them (the convention of
Mitsuba's `irregular` spectrum and of the Rust twin's src/spectral). Integrals of products of
such curves are computed exactly: Gauss-Legendre with 4 nodes on each interval between the union
of breakpoints is exact for polynomials up to degree 7, and a product of up to 7 linear pieces is
such a polynomial.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
SPECTRA = REPO / "spectra"

#: Spectral range of the truth cube and of every sensitivity handed to the specfilm (nm).
LO_NM, HI_NM = 400.0, 700.0
#: Wheel filters of the default rig, in channel order (paper section 4: three dichroic segments
#: of a projector colour wheel, then three colour papers).
WHEEL = ["wheel/red", "wheel/green", "wheel/blue", "paper/a", "paper/b", "paper/c"]
QE = "camera/mono_qe"


@dataclass(frozen=True)
class Curve:
    """A piecewise-linear curve, zero outside [wl[0], wl[-1]]."""

    wl: np.ndarray
    val: np.ndarray

    def __call__(self, x):
        x = np.asarray(x, dtype=float)
        y = np.interp(x, self.wl, self.val)
        return np.where((x < self.wl[0]) | (x > self.wl[-1]), 0.0, y)

    def pairs(self):
        """(wavelength, value) pairs for a Mitsuba `spectrum`/`irregular` plugin."""
        return [(float(a), float(b)) for a, b in zip(self.wl, self.val)]


def read_csv(name: str) -> dict[str, Curve]:
    """All columns of spectra/<name>.csv (format: spectra/README.md) as curves."""
    path = SPECTRA / f"{name}.csv"
    rows = [r for r in csv.reader(l for l in path.open() if not l.startswith("#")) if r]
    header, data = rows[0], np.array(rows[1:], dtype=float)
    if header[0] != "wavelength_nm" or np.any(np.diff(data[:, 0]) <= 0):
        raise ValueError(f"{path}: not a spectra/ CSV (header {header[0]!r} or wavelengths)")
    return {h: Curve(data[:, 0], data[:, k + 1]) for k, h in enumerate(header[1:])}


def curve(name: str, column: str | None = None) -> Curve:
    """One curve: `wheel/red`, or `reflectance/colorchecker:red` (file:column)."""
    if ":" in name:
        name, column = name.split(":")
    cols = read_csv(name)
    if column is None:
        if len(cols) != 1:
            raise ValueError(f"spectra/{name}.csv has {len(cols)} columns; name one")
        return next(iter(cols.values()))
    return cols[column]


def breakpoints(curves, lo=LO_NM, hi=HI_NM) -> np.ndarray:
    pts = [np.array([lo, hi])] + [c.wl[(c.wl > lo) & (c.wl < hi)] for c in curves]
    return np.unique(np.concatenate(pts))


_GL_X, _GL_W = np.polynomial.legendre.leggauss(4)


def integrate(*curves, lo=LO_NM, hi=HI_NM) -> float:
    """Exact ∫_lo^hi Π curves dλ for piecewise-linear curves (at most 7 factors)."""
    b = breakpoints(curves, lo, hi)
    a0, a1 = b[:-1], b[1:]
    half, mid = (a1 - a0) / 2, (a1 + a0) / 2
    x = mid[:, None] + half[:, None] * _GL_X[None, :]
    y = np.ones_like(x)
    for c in curves:
        y = y * c(x)
    return float(np.sum(half[:, None] * _GL_W[None, :] * y))


def product(*curves, step=1.0, lo=LO_NM, hi=HI_NM) -> Curve:
    """Product of curves sampled every `step` nm on [lo, hi] (linear in between).

    All spectra/ curves used here have breakpoints on a 1 nm grid, so the samples are exact at
    every breakpoint; only the curvature of the product inside 1 nm is dropped (see docs)."""
    wl = np.arange(lo, hi + step / 2, step)
    v = np.ones_like(wl)
    for c in curves:
        v = v * c(wl)
    return Curve(wl, v)


# --- truth bands: hat functions -------------------------------------------------------------

def band_centres(step: float) -> np.ndarray:
    n = int(round((HI_NM - LO_NM) / step))
    return LO_NM + step * np.arange(n + 1)


def hat(centre: float, step: float) -> Curve:
    """h_b: 1 at the centre, 0 at centre ± step, cut to [400, 700] (half hats at the ends)."""
    wl = np.array([centre - step, centre, centre + step])
    val = np.array([0.0, 1.0, 0.0])
    keep = (wl >= LO_NM - 1e-9) & (wl <= HI_NM + 1e-9)
    return Curve(wl[keep], val[keep])


def hat_weights(step: float) -> np.ndarray:
    """∫ h_b dλ: `step` inside, `step/2` for the two end hats. Truth EXR value = m_b / weight."""
    w = np.full(len(band_centres(step)), step)
    w[0] = w[-1] = step / 2
    return w


def hat_gram(step: float) -> np.ndarray:
    """G_ab = ∫ h_a h_b dλ: tridiagonal step·[1/6, 2/3, 1/6], diagonal step/3 at the ends."""
    n = len(band_centres(step))
    g = np.zeros((n, n))
    i = np.arange(n)
    g[i, i] = 2 * step / 3
    g[0, 0] = g[-1, -1] = step / 3
    g[i[:-1], i[:-1] + 1] = g[i[:-1] + 1, i[:-1]] = step / 6
    return g


def wheel_sensitivities() -> dict[str, Curve]:
    """S_i = T_i · QE on [400, 700] nm, 1 nm samples, named f<i>_<filter>."""
    qe = curve(QE)
    return {
        f"f{i}_{name.split('/')[1]}": product(curve(name), qe)
        for i, name in enumerate(WHEEL)
    }


def hat_projection_matrix(sens: dict[str, Curve], step: float) -> np.ndarray:
    """W_ib = ∫ S_i h_b dλ (filters × bands)."""
    hats = [hat(c, step) for c in band_centres(step)]
    return np.array([[integrate(s, h) for h in hats] for s in sens.values()])


def wheel_from_truth(truth: np.ndarray, step: float, W: np.ndarray) -> np.ndarray:
    """Wheel channels predicted from truth values (…, bands) in EXR units (m_b / weight):
    x_i = Σ_b c_b W_ib with c = G⁻¹ m, m_b = truth_b · weight_b."""
    m = truth * hat_weights(step)
    c = np.linalg.solve(hat_gram(step), np.moveaxis(m, -1, 0).reshape(m.shape[-1], -1))
    c = np.moveaxis(c.reshape((m.shape[-1],) + m.shape[:-1]), 0, -1)
    return c @ W.T


def projection_bias(radiance: Curve | list, step: float, sens: dict[str, Curve]) -> np.ndarray:
    """Relative bias of the hat route per filter for one radiance spectrum, given as a list of
    factors (e.g. [illuminant, reflectance]): (Σ_b c_b W_ib − ∫ S_i L dλ) / ∫ S_i L dλ."""
    factors = radiance if isinstance(radiance, list) else [radiance]
    hats = [hat(c, step) for c in band_centres(step)]
    m = np.array([integrate(h, *factors) for h in hats])
    W = hat_projection_matrix(sens, step)
    pred = np.linalg.solve(hat_gram(step), m) @ W.T
    exact = np.array([integrate(s, *factors) for s in sens.values()])
    return (pred - exact) / exact
