#!/usr/bin/env python3
"""Extract the spectral data used by specmux into CSV files under ``spectra/``.

Run through ``tools/extract_spectra.sh`` (it creates the pinned virtual
environment ``tools/.venv-data`` and fetches the one extra wheel needed).

Sources
-------
* colour-science 0.4.7 (PyPI): reflectance libraries, illuminants, light
  sources, CIE 1931 colour-matching functions.
* pyxel-sim 3.0.2 (PyPI wheel, read as data only, never imported): the table of
  silicon absorption coefficients embedded in
  ``pyxel/models/charge_generation/exponential_qe.py``, used to build the
  *modelled* monochrome camera QE curve.

CSV format (the Rust loader depends on it)::

    # provenance: ...
    # further comment lines ...
    wavelength_nm,<col1>[,<col2>...]
    <wavelength>,<value>[,<value>...]

Usage::

    python tools/extract_spectra.py [--pyxel-wheel PATH] [--out DIR]
"""

from __future__ import annotations

import argparse
import ast
import csv
import itertools
import math
import re
import sys
import warnings
import zipfile
from pathlib import Path

import numpy as np

warnings.filterwarnings("ignore")  # colour warns about missing optional deps

import colour  # noqa: E402
import colour.characterisation  # noqa: E402
import colour.quality  # noqa: E402

COLOUR_VERSION = colour.__version__
EXPECTED_COLOUR_VERSION = "0.4.7"
PYXEL_VERSION = "3.0.2"

REPO = Path(__file__).resolve().parent.parent
NAME_RE = re.compile(r"^[A-Za-z0-9_.-]+$")

# Selection grid for the colour-paper search: 400-700 nm at 10 nm.  Every
# reflectance dataset used here is sampled natively on these wavelengths
# (5 nm or 10 nm grids starting at 360/380 nm), so no interpolation is needed.
SEL_GRID = np.arange(400.0, 701.0, 10.0)

# Near-neutral threshold for the colour-paper candidates (CIELAB chroma under
# D65 / CIE 1931 2 deg, computed on the 400-700 nm / 10 nm grid).
NEUTRAL_CHROMA_MAX = 10.0


# --------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------
def fmt(x: float) -> str:
    """Plain decimal (no exponent), shortest round-trip representation."""
    x = float(x)
    if not math.isfinite(x):
        raise ValueError(f"non-finite value {x!r}")
    if x == 0.0:
        return "0.0"
    return np.format_float_positional(x, unique=True, trim="0")


def sanitize(name: str) -> str:
    s = re.sub(r"[^A-Za-z0-9_.-]+", "_", name.strip())
    s = re.sub(r"_+", "_", s).strip("_")
    return s or "unnamed"


def unique_names(names):
    out, seen = [], {}
    for n in names:
        s = sanitize(n)
        if s in seen:
            seen[s] += 1
            s = f"{s}_{seen[s]}"
        else:
            seen[s] = 0
        out.append(s)
    return out


def clean(values: np.ndarray) -> np.ndarray:
    """Set floating-point noise (|x| < 1e-12) to exactly 0."""
    v = np.asarray(values, dtype=float).copy()
    v[np.abs(v) < 1e-12] = 0.0
    return v


def write_csv(path: Path, provenance: str, comments, wl, columns: dict):
    """columns: ordered mapping name -> 1-D array (same length as wl)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    wl = np.asarray(wl, dtype=float)
    assert np.all(np.diff(wl) > 0), f"{path}: wavelengths not increasing"
    names = list(columns)
    for n in names:
        assert NAME_RE.match(n), f"{path}: bad column name {n!r}"
    assert "\n" not in provenance
    data = np.column_stack([np.asarray(columns[n], dtype=float) for n in names])
    assert data.shape[0] == wl.size
    assert np.all(np.isfinite(data)), f"{path}: non-finite values"
    with open(path, "w", newline="\n") as f:
        f.write(f"# provenance: {provenance}\n")
        for c in comments:
            assert "\n" not in c
            f.write(f"# {c}\n")
        f.write("wavelength_nm," + ",".join(names) + "\n")
        for i, w in enumerate(wl):
            f.write(fmt(w) + "," + ",".join(fmt(v) for v in data[i]) + "\n")
    print(f"wrote {path.relative_to(REPO) if path.is_relative_to(REPO) else path}: "
          f"{len(names)} curve(s), {wl[0]:g}-{wl[-1]:g} nm, {wl.size} rows")


def sd_arrays(sd):
    return np.asarray(sd.wavelengths, float), np.asarray(sd.values, float)


def sds_to_table(sds: dict):
    """dict name -> SpectralDistribution (common shape) -> wl, {name: values}."""
    items = list(sds.items())
    lo = max(float(sd.wavelengths[0]) for _, sd in items)
    hi = min(float(sd.wavelengths[-1]) for _, sd in items)
    wl0 = None
    cols = {}
    for n, (_, sd) in zip(unique_names([k for k, _ in items]), items):
        wl = np.asarray(sd.wavelengths, float)
        m = (wl >= lo - 1e-9) & (wl <= hi + 1e-9)
        if wl0 is None:
            wl0 = wl[m]
        # only cropping to the common range is allowed, never resampling
        assert np.array_equal(wl[m], wl0), "mixed sampling"
        cols[n] = clean(np.asarray(sd.values, float)[m])
    return wl0, cols


def sampling(wl):
    steps = np.unique(np.round(np.diff(wl), 9))
    return f"{wl[0]:g}-{wl[-1]:g} nm, step {'/'.join(f'{s:g}' for s in steps)} nm"


# --------------------------------------------------------------------------
# reflectance libraries
# --------------------------------------------------------------------------
def reflectance(out: Path):
    libs = {}  # file stem -> (wl, {col: values}, dataset label)
    base = Path(colour.__file__).parent

    # ACES rawtoaces 190 training patches: read the shipped CSV directly to
    # keep the native values untouched.
    p = base / "characterisation" / "datasets" / "rawtoaces" / "190_Patches.csv"
    with open(p, newline="") as f:
        rows = list(csv.reader(f))
    header, body = rows[0], [r for r in rows[1:] if r]
    arr = np.array([[float(x) for x in r] for r in body])
    wl = arr[:, 0]
    cols = {n: clean(arr[:, i + 1]) for i, n in enumerate(unique_names(header[1:]))}
    nfluo = sum(1 for v in cols.values() if v.max() > 1.0)
    write_csv(
        out / "reflectance" / "aces190.csv",
        f"colour-science {COLOUR_VERSION} (PyPI), file colour/characterisation/datasets/"
        "rawtoaces/190_Patches.csv (same data as colour.characterisation."
        "read_training_data_rawtoaces_v1()): the 190-patch spectral reflectance "
        "training set of AMPAS rawtoaces v1 (Academy Color Encoding System IDT "
        "tooling; measured reflectances of physical colour samples). Native "
        "sampling kept; values are reflectance factors as fractions; values with "
        "|x|<1e-12 (floating-point noise in the source, e.g. -2.2e-16) set to 0; "
        "no other processing.",
        ["units: spectral reflectance factor (fraction; 1.0 = perfect white diffuser)",
         f"note: {nfluo} patches exceed 1.0 somewhere (fluorescent samples); values kept as published",
         f"sampling: {sampling(wl)}; {len(cols)} samples"],
        wl, cols)
    libs["aces190"] = (wl, cols, "ACES rawtoaces 190 patches")

    # ColorChecker Classic, BabelColor average of 30 charts.
    wl, cols = sds_to_table(colour.SDS_COLOURCHECKERS["BabelColor Average"])
    write_csv(
        out / "reflectance" / "colorchecker.csv",
        f"colour-science {COLOUR_VERSION} (PyPI), colour.SDS_COLOURCHECKERS['BabelColor Average']: "
        "X-Rite/GretagMacbeth ColorChecker Classic 24 patches, average of "
        "measurements of 30 charts by BabelColor (D. Pascale, 'The ColorChecker, "
        "page 2', BabelColor 2012). Native sampling kept; column names are the "
        "patch names sanitized to [A-Za-z0-9_.-]; no other processing.",
        ["units: spectral reflectance factor (fraction)",
         f"sampling: {sampling(wl)}; {len(cols)} samples"],
        wl, cols)
    libs["colorchecker"] = (wl, cols, "ColorChecker BabelColor Average")

    # CIE test colour samples (CIE 13.3 TCS01-14 + TCS15).
    wl, cols = sds_to_table(colour.quality.SDS_TCS["CIE 2024"])
    write_csv(
        out / "reflectance" / "tcs.csv",
        f"colour-science {COLOUR_VERSION} (PyPI), colour.quality.SDS_TCS['CIE 2024']: "
        "CIE test colour samples TCS01-TCS15 used for the colour rendering index "
        "(CIE 13.3-1995 samples TCS01-TCS14, measured Munsell-type surface samples, "
        "identical to colour.quality.SDS_TCS['CIE 1995'], plus TCS15). Native "
        "5 nm sampling kept; TCS01-14 are tabulated 360-830 nm but TCS15 only "
        "380-780 nm, so all columns are cropped to the common 380-780 nm range "
        "(no resampling); no other processing.",
        ["units: spectral reflectance factor (fraction)",
         f"sampling: {sampling(wl)}; {len(cols)} samples"],
        wl, cols)
    libs["tcs"] = (wl, cols, "CIE TCS01-15")

    # NIST CQS 9.0 samples.
    wl, cols = sds_to_table(colour.quality.SDS_VS["NIST CQS 9.0"])
    write_csv(
        out / "reflectance" / "vs.csv",
        f"colour-science {COLOUR_VERSION} (PyPI), colour.quality.SDS_VS['NIST CQS 9.0']: "
        "the 15 saturated Munsell reflectance samples VS1-VS15 of the NIST Colour "
        "Quality Scale, version 9.0 (W. Davis & Y. Ohno, NIST). Native sampling "
        "kept; no processing. (6 of the 15 differ from the CQS 7.4 set, which is "
        "not exported.)",
        ["units: spectral reflectance factor (fraction)",
         f"sampling: {sampling(wl)}; {len(cols)} samples"],
        wl, cols)
    libs["vs"] = (wl, cols, "NIST CQS 9.0 VS1-15")
    return libs


def on_grid(wl, v, grid):
    idx = []
    for g in grid:
        k = np.nonzero(np.isclose(wl, g))[0]
        if k.size != 1:
            raise ValueError(f"wavelength {g} not on native grid")
        idx.append(k[0])
    return v[np.array(idx)]


def count_distinct(libs):
    """Count samples, merging those that agree within 0.005 at every 10 nm
    sample over 400-700 nm (i.e. the same physical sample in two datasets)."""
    keys, mats = [], []
    for stem, (wl, cols, _) in libs.items():
        for n, v in cols.items():
            assert wl[0] <= 400 and wl[-1] >= 700, f"{stem}:{n} does not cover 400-700"
            keys.append(f"{stem}:{n}")
            mats.append(on_grid(wl, v, SEL_GRID))
    M = np.array(mats)
    d = np.abs(M[:, None, :] - M[None, :, :]).max(-1)
    parent = list(range(len(keys)))

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    dups = []
    for i in range(len(keys)):
        for j in range(i + 1, len(keys)):
            if d[i, j] < 0.005:
                dups.append((keys[i], keys[j]))
                parent[find(i)] = find(j)
    distinct = len({find(i) for i in range(len(keys))})
    return len(keys), distinct, dups


# --------------------------------------------------------------------------
# illuminants and CMFs
# --------------------------------------------------------------------------
def illuminants_and_cmf(out: Path):
    I = colour.SDS_ILLUMINANTS
    desc = {
        "D65": "CIE standard illuminant D65 (CIE 15:2004 / ISO 11664-2 table; average daylight, CCT ~6504 K)",
        "A": "CIE standard illuminant A (CIE 15:2004 / ISO 11664-2 table; Planckian radiator at 2856 K, "
             "the CIE model of a tungsten-filament lamp; colour-science has no tungsten-halogen "
             "lamp spectrum, so A serves as the tungsten-halogen stand-in)",
        "LED-B3": "CIE illuminant LED-B3 (CIE 15:2018; phosphor-converted blue LED, CCT ~4103 K, "
                  "derived from measured LED spectra)",
    }
    for k in ["D65", "A", "LED-B3"]:
        wl, v = sd_arrays(I[k])
        write_csv(
            out / "illuminants" / f"{k}.csv",
            f"colour-science {COLOUR_VERSION} (PyPI), colour.SDS_ILLUMINANTS['{k}']: {desc[k]}. "
            "Native sampling of the colour-science dataset kept; no processing.",
            ["units: relative spectral power (arbitrary scale as tabulated by CIE)",
             f"sampling: {sampling(wl)}"],
            wl, {"relative_power": clean(v)})

    wl, v = sd_arrays(colour.SDS_LIGHT_SOURCES["60 A/W (Soft White)"])
    write_csv(
        out / "illuminants" / "incandescent.csv",
        f"colour-science {COLOUR_VERSION} (PyPI), colour.SDS_LIGHT_SOURCES['60 A/W (Soft White)']: "
        "spectrum of a Philips 60 W A-type soft-white incandescent (tungsten filament, "
        "not halogen) lamp from the NIST CQS simulation 7.4 spreadsheet (Ohno & Davis 2008), "
        "Philips light-source set; identical to the NIST 'Incandescent' entry. The "
        "curve carries measurement noise (it is not a Planck curve). Native sampling "
        "kept; no processing. Closest thing to a tungsten-halogen lamp in colour-science.",
        ["units: relative spectral power (peak normalised to 1 in the source)",
         f"sampling: {sampling(wl)}"],
        wl, {"relative_power": clean(v)})

    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    wl = np.asarray(cmfs.wavelengths, float)
    vals = np.asarray(cmfs.values, float)
    write_csv(
        out / "cmf" / "cie1931_2deg.csv",
        f"colour-science {COLOUR_VERSION} (PyPI), colour.MSDS_CMFS['CIE 1931 2 Degree Standard "
        "Observer']: CIE 1931 2-degree standard observer colour-matching functions "
        "x-bar, y-bar, z-bar (CIE 15:2004 / CVRL 1 nm table). Native sampling kept; no processing.",
        ["units: dimensionless tristimulus weights (y-bar peak 1.0 at 555 nm)",
         f"sampling: {sampling(wl)}"],
        wl, {"x": clean(vals[:, 0]), "y": clean(vals[:, 1]), "z": clean(vals[:, 2])})


# --------------------------------------------------------------------------
# monochrome camera QE (model)
# --------------------------------------------------------------------------
QE_MODEL = dict(cce=0.70, reflectance=0.10, x_epi_um=5.0, x_poly_um=0.10)


def silicon_absorption_from_pyxel(wheel: Path):
    member = "pyxel/models/charge_generation/exponential_qe.py"
    with zipfile.ZipFile(wheel) as z:
        src = z.read(member).decode()
    tree = ast.parse(src)
    found = {}
    for node in ast.walk(tree):
        if (isinstance(node, ast.Assign) and len(node.targets) == 1
                and isinstance(node.targets[0], ast.Name)
                and node.targets[0].id == "embedded_absorptivity_values"):
            call = node.value
            found["alpha"] = [float(ast.literal_eval(e)) for e in call.args[0].elts]
            unit = [kw.value.value for kw in call.keywords if kw.arg == "unit"]
            found["unit"] = unit[0] if unit else None
        if (isinstance(node, ast.Assign) and len(node.targets) == 1
                and isinstance(node.targets[0], ast.Name)
                and node.targets[0].id == "embedded_wavelengths"):
            found["wl_src"] = ast.unparse(node.value)
    if "alpha" not in found:
        raise RuntimeError("absorption table not found in pyxel wheel")
    # The table is declared as np.arange(250, 1460, 10) nm; check it.
    assert "arange(250, 1460, 10)" in found["wl_src"].replace(" ", "").replace(",", ", "), found["wl_src"]
    wl = np.arange(250.0, 1460.0, 10.0)
    alpha = np.array(found["alpha"])
    assert alpha.size == wl.size and found["unit"] == "1/cm", (alpha.size, found["unit"])
    return wl, alpha, member


def mono_qe(out: Path, wheel: Path):
    wl, alpha_cm, member = silicon_absorption_from_pyxel(wheel)
    a_um = alpha_cm * 1e-4  # 1/cm -> 1/um
    m = QE_MODEL
    qe = (m["cce"] * (1.0 - m["reflectance"]) * np.exp(-a_um * m["x_poly_um"])
          * (1.0 - np.exp(-a_um * m["x_epi_um"])))
    qe = np.round(qe, 6)
    ipk = int(np.argmax(qe))
    write_csv(
        out / "camera" / "mono_qe.csv",
        "MODEL, NOT MEASURED: no measured monochrome-sensor QE curve is available offline "
        "from PyPI packages that were checked (colour-science 0.4.7 has only RGB DSLR "
        "sensitivities; emva1288 1.0.2 ships no data; pvlib 0.16.1 only has a spline-smoothed "
        "c-Si solar-cell spectral response; pyxel-sim 3.0.2 ships only model inputs). "
        "Front-illuminated silicon CMOS pixel model QE = CCE*(1-R)*exp(-alpha*x_poly)*"
        "(1-exp(-alpha*x_epi)) (the 'FI' formula of pyxel's exponential_qe model) with "
        f"CCE={m['cce']}, R={m['reflectance']} (constant), x_poly={m['x_poly_um']} um, "
        f"x_epi={m['x_epi_um']} um, chosen by hand to give a typical FI CMOS peak of "
        "~0.6 near 550 nm. alpha(lambda) = absorption coefficient of crystalline silicon "
        f"at 300 K taken from the table embedded in pyxel-sim {PYXEL_VERSION} (PyPI wheel, "
        f"file {member}, 250-1450 nm / 10 nm, 1/cm; pyxel cites no source, the values agree "
        "within a few percent with published 300 K c-Si tables such as M. A. Green, Sol. Energy "
        "Mater. Sol. Cells 92 (2008) 1305, e.g. 1.11e4 /cm at 500 nm). "
        "Evaluated on that native 10 nm grid; rounded to 6 decimals.",
        ["units: quantum efficiency (electrons per incident photon, fraction 0..1)",
         f"model: peak {qe[ipk]:.3f} at {wl[ipk]:g} nm; QE(400)={qe[wl == 400][0]:.3f}, "
         f"QE(700)={qe[wl == 700][0]:.3f}, QE(900)={qe[wl == 900][0]:.3f}",
         f"sampling: {sampling(wl)}"],
        wl, {"qe": qe})


# --------------------------------------------------------------------------
# colour wheel: dichroic models + colour papers chosen from measured data
# --------------------------------------------------------------------------
EDGE_10_90_NM = 15.0
PASS_T = 0.90
BLOCK_T = 0.02
DICHROIC = {
    # name: (cut-on nm or None, cut-off nm or None)
    "blue": (None, 500.0),   # short-pass
    "green": (495.0, 580.0),  # band-pass
    "red": (590.0, None),    # long-pass
}
WHEEL_GRID = np.arange(380.0, 781.0, 1.0)


def logistic(x):
    return 1.0 / (1.0 + np.exp(-x))


def dichroic(wl, on, off):
    s = EDGE_10_90_NM / (2.0 * math.log(9.0))  # 10-90 % width of a logistic = 2 s ln 9
    g = np.ones_like(wl)
    if on is not None:
        g = g * logistic((wl - on) / s)
    if off is not None:
        g = g * logistic((off - wl) / s)
    return BLOCK_T + (PASS_T - BLOCK_T) * g


def chroma_d65(R):
    """CIELAB C*ab under D65, CIE 1931 2 deg, on SEL_GRID (simple summation)."""
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    cw = np.asarray(cmfs.wavelengths, float)
    cv = np.asarray(cmfs.values, float)
    xyz_bar = np.array([on_grid(cw, cv[:, i], SEL_GRID) for i in range(3)])
    d65 = colour.SDS_ILLUMINANTS["D65"]
    S = on_grid(np.asarray(d65.wavelengths, float), np.asarray(d65.values, float), SEL_GRID)
    k = 1.0 / np.sum(S * xyz_bar[1])
    XYZ = k * (R * S) @ xyz_bar.T  # (n, 3)
    W = k * S @ xyz_bar.T
    f = lambda t: np.where(t > (6 / 29) ** 3, np.cbrt(t), t / (3 * (6 / 29) ** 2) + 4 / 29)
    fx, fy, fz = (f(XYZ[:, i] / W[i]) for i in range(3))
    a, b = 500 * (fx - fy), 200 * (fy - fz)
    return np.hypot(a, b)


def wheel(out: Path, libs):
    # --- dichroic models
    dich = {n: dichroic(WHEEL_GRID, *p) for n, p in DICHROIC.items()}
    for n, (on, off) in DICHROIC.items():
        if on is None:
            kind = f"short-pass, cut-off {off:g} nm"
        elif off is None:
            kind = f"long-pass, cut-on {on:g} nm"
        else:
            kind = f"band-pass {on:g}-{off:g} nm"
        formula = ("T = Tb + (Tp - Tb) * " +
                   " * ".join(x for x in [
                       f"L((lambda-{on:g})/s)" if on is not None else None,
                       f"L(({off:g}-lambda)/s)" if off is not None else None] if x))
        write_csv(
            out / "wheel" / f"{n}.csv",
            f"MODEL, NOT MEASURED: {n} dichroic segment of an off-the-shelf projector colour wheel "
            f"(paper section 4), modelled as a smooth interference edge filter ({kind}) because no "
            "measured dichroic colour-wheel transmittance is available offline. "
            f"{formula} with logistic L(x)=1/(1+exp(-x)), 50% points at the stated edges, "
            f"10-90% edge width {EDGE_10_90_NM:g} nm (s = {EDGE_10_90_NM:g}/(2 ln 9) nm), passband "
            f"Tp={PASS_T}, blocking Tb={BLOCK_T}; no angle-of-incidence shift, no passband ripple. "
            "Generated by tools/extract_spectra.py; rounded to 6 decimals.",
            ["units: transmittance (fraction 0..1)",
             f"sampling: {sampling(WHEEL_GRID)}"],
            WHEEL_GRID, {"transmittance": np.round(dich[n], 6)})

    # --- candidate colour papers: all measured reflectance samples that are
    # chromatic (C*ab >= NEUTRAL_CHROMA_MAX) and physically usable as a
    # transmittance (0 <= value <= 1 everywhere, i.e. not fluorescent).
    cand_keys, cand_sel = [], []
    excluded_neutral, excluded_fluo = 0, 0
    for stem, (wl, cols, _) in libs.items():
        names = list(cols)
        sel = np.array([on_grid(wl, cols[n], SEL_GRID) for n in names])
        C = chroma_d65(sel)
        for n, v, c, s in zip(names, cols.values(), C, sel):
            if c < NEUTRAL_CHROMA_MAX:
                excluded_neutral += 1
                continue
            if v.max() > 1.0 or v.min() < 0.0:
                excluded_fluo += 1
                continue
            cand_keys.append((stem, n))
            cand_sel.append(s)
    X = np.array(cand_sel)
    D = np.array([on_grid(WHEEL_GRID, dich[n], SEL_GRID) for n in DICHROIC])
    allv = np.vstack([D, X])
    R = np.corrcoef(allv)  # Pearson correlation over 400-700 nm, 10 nm
    Rdd = R[:3, :3]
    d0 = max(Rdd[i, j] for i in range(3) for j in range(3) if i != j)
    mdx = R[3:, :3].max(axis=1)  # worst correlation of each candidate with the dichroics
    Rxx = R[3:, 3:]
    n = len(cand_keys)
    print(f"paper search: {n} candidates ({excluded_neutral} near-neutral with C*ab<"
          f"{NEUTRAL_CHROMA_MAX:g} excluded, {excluded_fluo} fluorescent/out-of-range excluded), "
          f"{n * (n - 1) * (n - 2) // 6} triples")
    # Exhaustive search over all triples (vectorised).
    tri = np.array(list(itertools.combinations(range(n), 3)), dtype=np.int32)
    base_i = np.maximum(mdx, d0)
    s = np.maximum.reduce([base_i[tri[:, 0]], base_i[tri[:, 1]], base_i[tri[:, 2]],
                           Rxx[tri[:, 0], tri[:, 1]], Rxx[tri[:, 0], tri[:, 2]],
                           Rxx[tri[:, 1], tri[:, 2]]])
    score = float(s.min())
    tied = tri[s <= score + 1e-12]
    # The min-max objective is often decided by a single pair and then ties;
    # break ties lexicographically (minimise the largest, then the 2nd largest,
    # ... pairwise correlation of the six curves), then by sample order.
    def lexkey(t):
        six_idx = [0, 1, 2] + [3 + int(x) for x in t]
        sub = R[np.ix_(six_idx, six_idx)][np.triu_indices(6, 1)]
        return tuple(np.round(np.sort(sub)[::-1], 12)) + tuple(int(x) for x in t)
    i, j, k = min((tuple(t) for t in tied), key=lexkey)
    n_tied = len(tied)
    print(f"  best max-correlation {score:.6f} reached by {n_tied} triple(s); tie broken lexicographically")
    triple = [cand_keys[t] for t in (i, j, k)]
    six = np.vstack([D, X[[i, j, k]]])
    R6 = np.corrcoef(six)
    off = R6[~np.eye(6, dtype=bool)]
    assert abs(off.max() - score) < 1e-12
    labels = list(DICHROIC) + [f"{s}:{c}" for s, c in triple]
    ia, ib = np.unravel_index(np.argmax(np.where(np.eye(6, dtype=bool), -np.inf, R6)), R6.shape)
    nrm = six / np.linalg.norm(six, axis=1, keepdims=True)
    cos6 = (nrm @ nrm.T)[~np.eye(6, dtype=bool)].max()
    print(f"chosen colour papers: {triple}; max pairwise Pearson correlation of the six "
          f"curves = {score:.4f} (between {labels[ia]} and {labels[ib]}); "
          f"max cosine similarity = {cos6:.4f}")

    triple_txt = ", ".join(f"{s}.csv:{c}" for s, c in triple)
    for letter, (stem, col) in zip("abc", triple):
        wl, cols, label = libs[stem]
        v = cols[col]
        m = (wl >= 380.0 - 1e-9) & (wl <= 780.0 + 1e-9)
        crop = "" if m.all() else f" (native {wl[0]:g}-{wl[-1]:g} nm cropped to 380-780 nm, no resampling)"
        write_csv(
            out / "paper" / f"{letter}.csv",
            f"MEASURED REFLECTANCE USED AS A STAND-IN for broadband colour-paper transmittance "
            "(no measured colour-paper transmittance data are available offline): sample "
            f"'{col}' of spectra/reflectance/{stem}.csv ({label}, colour-science {COLOUR_VERSION}), "
            f"native sampling{crop}. Selected by tools/extract_spectra.py with the paper's criterion "
            "(section 4): over all triples of candidate samples, minimise the maximum pairwise "
            "Pearson correlation (over 400-700 nm, native 10 nm samples) of the six wheel curves "
            f"(model dichroic red/green/blue + the three papers); {n_tied} triples tie at the optimum, "
            "ties broken lexicographically (then minimise the 2nd-largest correlation, and so on). "
            "Candidates: every measured "
            f"reflectance sample of spectra/reflectance/ with CIELAB C*ab >= {NEUTRAL_CHROMA_MAX:g} "
            "(D65, CIE 1931 2 deg; near-neutral grey/white/black excluded) and 0<=value<=1 "
            f"(fluorescent samples excluded); {n} candidates. Chosen triple: a,b,c = {triple_txt}; "
            f"max pairwise correlation of the six = {score:.4f}.",
            ["units: treated as transmittance (fraction 0..1); source quantity is spectral reflectance factor",
             f"selection: max corr {score:.6f} between {labels[ia]} and {labels[ib]}; max cosine similarity {cos6:.6f}",
             f"sampling: {sampling(wl[m])}"],
            wl[m], {"transmittance": v[m]})
    return triple, score, labels, R6


# --------------------------------------------------------------------------
# verification
# --------------------------------------------------------------------------
def verify(path: Path):
    with open(path, newline="") as f:
        lines = f.read().split("\n")
    if lines and lines[-1] == "":
        lines = lines[:-1]
    assert lines[0].startswith("# provenance: ") and len(lines[0]) > 20, path
    i = 1
    while lines[i].startswith("#"):
        i += 1
    rows = list(csv.reader(lines[i:]))
    header = rows[0]
    assert header[0] == "wavelength_nm", path
    assert len(header) >= 2
    assert all(NAME_RE.match(h) for h in header[1:]), path
    assert len(set(header)) == len(header), f"{path}: duplicate column names"
    data = rows[1:]
    assert data, path
    wl = []
    for r in data:
        assert len(r) == len(header), f"{path}: ragged row {r[:3]}"
        assert all(c and "e" not in c.lower() for c in r), f"{path}: empty or exponent cell in {r[:3]}"
        vals = [float(c) for c in r]
        assert all(math.isfinite(v) for v in vals), path
        wl.append(vals[0])
    wl = np.array(wl)
    assert np.all(np.diff(wl) > 0), f"{path}: wavelengths not strictly increasing"
    return len(header) - 1, wl[0], wl[-1], sampling(wl)


README_META = {
    # path: (what, source, measured/model)
    "reflectance/aces190.csv": ("190 surface reflectances (rawtoaces IDT training set)",
                                "colour-science 0.4.7, rawtoaces/190_Patches.csv (AMPAS rawtoaces v1)", "measured"),
    "reflectance/colorchecker.csv": ("ColorChecker Classic 24 patches",
                                     "colour-science 0.4.7, SDS_COLOURCHECKERS['BabelColor Average']", "measured (average of 30 charts)"),
    "reflectance/tcs.csv": ("CIE test colour samples TCS01-TCS15 (cropped to common 380-780 nm)",
                            "colour-science 0.4.7, quality.SDS_TCS['CIE 2024'] (CIE 13.3)", "measured"),
    "reflectance/vs.csv": ("NIST CQS 9.0 samples VS1-VS15",
                           "colour-science 0.4.7, quality.SDS_VS['NIST CQS 9.0']", "measured"),
    "illuminants/D65.csv": ("CIE standard illuminant D65", "colour-science 0.4.7, SDS_ILLUMINANTS['D65']", "CIE standard table"),
    "illuminants/A.csv": ("CIE standard illuminant A (2856 K Planckian); stand-in for tungsten-halogen",
                          "colour-science 0.4.7, SDS_ILLUMINANTS['A']", "CIE standard table (computed Planck curve)"),
    "illuminants/LED-B3.csv": ("CIE LED illuminant B3 (phosphor-converted white LED, ~4100 K)",
                               "colour-science 0.4.7, SDS_ILLUMINANTS['LED-B3'] (CIE 15:2018)", "CIE standard table (from measured LEDs)"),
    "illuminants/incandescent.csv": ("Philips 60 W A-lamp soft-white incandescent (not halogen)",
                                     "colour-science 0.4.7, SDS_LIGHT_SOURCES['60 A/W (Soft White)'] (NIST CQS 7.4)", "measured lamp spectrum"),
    "cmf/cie1931_2deg.csv": ("CIE 1931 2-degree colour-matching functions x, y, z",
                             "colour-science 0.4.7, MSDS_CMFS['CIE 1931 2 Degree Standard Observer']", "CIE standard table"),
    "camera/mono_qe.csv": ("monochrome camera quantum efficiency (fraction)",
                           "front-illuminated Si CMOS model; Si absorption table from pyxel-sim 3.0.2", "**MODEL**"),
    "wheel/red.csv": ("red dichroic wheel segment, long-pass 590 nm", "tools/extract_spectra.py (logistic edges)", "**MODEL**"),
    "wheel/green.csv": ("green dichroic wheel segment, band-pass 495-580 nm", "tools/extract_spectra.py (logistic edges)", "**MODEL**"),
    "wheel/blue.csv": ("blue dichroic wheel segment, short-pass 500 nm", "tools/extract_spectra.py (logistic edges)", "**MODEL**"),
}


def write_readme(out: Path, total, distinct, dups, triple, score, labels, R6):
    meta = dict(README_META)
    for letter, (stem, col) in zip("abc", triple):
        meta[f"paper/{letter}.csv"] = (
            f"colour paper {letter}: reflectance of {stem}.csv:{col} as a stand-in for paper transmittance",
            f"colour-science 0.4.7 via spectra/reflectance/{stem}.csv; chosen by min-max correlation",
            "measured (reflectance, used as a transmittance proxy)")
    rows = []
    for p in sorted(out.rglob("*.csv")):
        rel = p.relative_to(out).as_posix()
        ncol, lo, hi, samp = verify(p)
        what, src, kind = meta[rel]
        step = samp.split("step ")[1]
        rows.append(f"| `{rel}` | {what} | {src} | {kind} | {lo:g}-{hi:g} | {step} | {ncol} |")
    corr = "\n".join(
        "| " + labels[i] + " | " + " | ".join(f"{R6[i, j]:.3f}" for j in range(6)) + " |"
        for i in range(6))
    text = f"""# spectra/

Spectral data for the specmux digital twin. **Generated, do not edit by hand**:
`bash tools/extract_spectra.sh` recreates every file (pinned colour-science==0.4.7,
numpy==2.4.6 in `tools/.venv-data`, plus the pyxel-sim 3.0.2 wheel read as data).

## Format

```
# provenance: <source, version, dataset, original publication, processing>
# <more comment lines: units, sampling, model parameters>
wavelength_nm,<col1>[,<col2>...]
380.0,0.1234[,...]
```

Wavelengths in nm, strictly increasing, native sampling of each dataset (no
resampling anywhere; the TCS file and the colour papers are only *cropped*).
Values are plain decimals; reflectance, transmittance and QE are fractions 0..1
(a few ACES patches are fluorescent and exceed 1). Column names match
`[A-Za-z0-9_.-]+`. Single curves have two columns; libraries have one column per
sample. Every file's first line says where it came from; files marked MODEL say
so in that line.

## Files

| file | what | source | measured / model | range nm | step nm | curves |
| --- | --- | --- | --- | --- | --- | --- |
{chr(10).join(rows)}

## Notes

* Reflectance libraries: {total} samples in 4 files, {distinct} distinct
  ({len(dups)} pair(s) agree within 0.005 everywhere in 400-700 nm and are
  probably the same physical patch: {'; '.join(a + ' ~ ' + b for a, b in dups) or 'none'}).
  Every sample covers at least 400-700 nm.
* No measured data were found offline (PyPI packages checked: colour-science,
  emva1288, pvlib, pyxel-sim, speclite) for: the dichroic colour-wheel segments,
  coloured-paper transmittance, a monochrome sensor QE, or a tungsten-halogen
  lamp. The wheel segments and the QE are models (parameters in their
  provenance lines); the papers are measured *reflectances* used as stand-ins
  for broadband paper transmittance; CIE A (and the measured incandescent lamp)
  stand in for tungsten-halogen.
* Colour papers (paper section 4 criterion, min over triples of the max pairwise
  Pearson correlation of the six wheel curves over 400-700 nm at 10 nm):
  a, b, c = {', '.join(f'{s}:{c}' for s, c in triple)}; max correlation
  **{score:.4f}**. Candidates were the measured samples with CIELAB C*ab >= {NEUTRAL_CHROMA_MAX:g}
  (near-neutral samples excluded) and values within 0..1 (fluorescent ones excluded).
  Several triples tie at the optimum (the maximum is set by one
  dichroic/paper pair); ties are broken lexicographically on the sorted
  correlations. Correlation matrix of the six curves:

| | {' | '.join(labels)} |
| --- | {' | '.join('---' for _ in labels)} |
{corr}
"""
    (out / "README.md").write_text(text)
    print(f"wrote {(out / 'README.md').relative_to(out.parent)}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--pyxel-wheel", type=Path, required=True,
                    help=f"path to pyxel_sim-{PYXEL_VERSION}-py3-none-any.whl (read as data only)")
    ap.add_argument("--out", type=Path, default=REPO / "spectra")
    args = ap.parse_args()
    if COLOUR_VERSION != EXPECTED_COLOUR_VERSION:
        sys.exit(f"colour-science {EXPECTED_COLOUR_VERSION} required, found {COLOUR_VERSION}")
    out = args.out

    libs = reflectance(out)
    total, distinct, dups = count_distinct(libs)
    print(f"reflectance samples: {total} in {len(libs)} files; {distinct} distinct "
          f"(pairs agreeing within 0.005 over 400-700 nm merged: {len(dups)})")
    for a, b in dups:
        print(f"  near-duplicate: {a} ~ {b}")
    illuminants_and_cmf(out)
    mono_qe(out, args.pyxel_wheel)
    triple, score, labels, R6 = wheel(out, libs)

    print("\nverification:")
    files = sorted(out.rglob("*.csv"))
    for p in files:
        ncol, lo, hi, samp = verify(p)
        print(f"  OK {p.relative_to(out.parent)}: {ncol} column(s), {samp}")
    write_readme(out, total, distinct, dups, triple, score, labels, R6)
    print(f"\nSUMMARY reflectance_total={total} distinct={distinct} "
          f"paper_triple={triple} max_corr={score:.4f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
