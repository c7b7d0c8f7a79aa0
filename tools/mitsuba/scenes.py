"""Mitsuba 3 scene dictionaries of the cross-check, built from measured spectra in spectra/.

Each builder returns a `Scene`: the Mitsuba dict (without sensor film; render.py adds the one
specfilm) and the radiance spectra that can reach the camera, as lists of factors, for the
deterministic check of the hat route (spectral.projection_bias). Illuminants are
spectra/illuminants/D65.csv verbatim (≈100 at 560 nm) as an `irregular` spectrum.
Image orientation: row 0 is the top of the image, column x grows to the right; world +x is
image right and world +y image up for every camera here.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

import spectral as sp


@dataclass
class Scene:
    name: str
    description: str
    dict: dict | None  # None when built with build=False (no Mitsuba import)
    spectra: list = field(default_factory=list)  # radiance spectra as factor lists
    max_depth: int = 2


def irregular(c: sp.Curve) -> dict:
    return {
        "type": "irregular",
        "wavelengths": ", ".join(f"{w:g}" for w in c.wl),
        "values": ", ".join(f"{v:.9g}" for v in c.val),
    }


def diffuse(c: sp.Curve) -> dict:
    return {"type": "diffuse", "reflectance": irregular(c)}


def _T():
    import mitsuba as mi

    return mi.ScalarTransform4f()


def _ortho_front(half_width: float) -> dict:
    """Orthographic camera on the +z axis looking at the origin, ±half_width visible."""
    t = _T().look_at(origin=[0, 0, 10], target=[0, 0, 0], up=[0, 1, 0])
    return {"type": "orthographic", "to_world": t @ _T().scale([half_width, half_width, 1])}


def _frontal_sun(illum: sp.Curve) -> dict:
    """Directional light along the view axis: irradiance E(λ) = the illuminant CSV, so a
    Lambertian surface of reflectance r appears with radiance r·E/π."""
    return {"type": "directional", "direction": [0, 0, -1], "irradiance": irregular(illum)}


#: Chart background: flat reflectance 0.1 (not measured; distinct from every patch).
CHART_BACKGROUND = sp.Curve(np.array([sp.LO_NM, sp.HI_NM]), np.array([0.1, 0.1]))
#: Chart geometry (scene units): patch pitch, patch side, visible half width.
CHART_PITCH, CHART_SIDE, CHART_HALF = 1.0, 0.8, 3.2


def chart_patch_centre(k: int) -> tuple[float, float]:
    """World (x, y) of patch k: row k // 6 from the top, column k % 6 from the left."""
    row, col = divmod(k, 6)
    return (col - 2.5) * CHART_PITCH, (1.5 - row) * CHART_PITCH


def chart(build=True, illuminant="illuminants/D65") -> Scene:
    """ColorChecker Classic (24 measured patches, 4 rows × 6 columns, dark_skin top-left) on a
    flat 0.1 background, lit frontally by a directional D65, orthographic camera."""
    illum = sp.curve(illuminant)
    cc = sp.read_csv("reflectance/colorchecker")
    names = list(cc)
    spectra = [[illum, cc[n]] for n in names] + [[illum, CHART_BACKGROUND]]
    if not build:
        return Scene("chart", chart.__doc__.strip(), None, spectra, max_depth=2)
    d = {"type": "scene", "light": _frontal_sun(illum)}
    for k, n in enumerate(names):
        x, y = chart_patch_centre(k)
        d[f"patch{k:02d}"] = {
            "type": "rectangle",
            "to_world": _T().translate([x, y, 0]) @ _T().scale([CHART_SIDE / 2, CHART_SIDE / 2, 1]),
            "bsdf": diffuse(cc[n]),
        }
    d["background"] = {
        "type": "rectangle",
        "to_world": _T().translate([0, 0, -0.01]) @ _T().scale([10, 10, 1]),
        "bsdf": diffuse(CHART_BACKGROUND),
    }
    d["sensor"] = _ortho_front(CHART_HALF)
    return Scene("chart", chart.__doc__.strip(), d, spectra, max_depth=2)


def cornell(build=True, illuminant="illuminants/D65") -> Scene:
    """Cornell box: white (white_9.5), red and green walls (ColorChecker red/green), a blue
    sphere (ColorChecker blue) and a yellow box (ColorChecker yellow), lit by a ceiling area
    light of radiance D65 (CSV verbatim); path tracer, max_depth 5 (4 bounces)."""
    illum = sp.curve(illuminant)
    cc = sp.read_csv("reflectance/colorchecker")
    mats = {k: cc[v] for k, v in dict(white="white_9.5_.05_D", red="red", green="green",
                                      blue="blue", yellow="yellow").items()}
    m = list(mats.values())
    spectra = [[illum]] + [[illum, a] for a in m] + [[illum, a, b] for a in m for b in m]
    if not build:
        return Scene("cornell", cornell.__doc__.strip(), None, spectra, max_depth=5)
    T = _T()
    rx = lambda a: T.rotate([1, 0, 0], a)
    ry = lambda a: T.rotate([0, 1, 0], a)
    walls = {
        "floor": (T.translate([0, -1, 0]) @ rx(-90), "white"),
        "ceiling": (T.translate([0, 1, 0]) @ rx(90), "white"),
        "back": (T.translate([0, 0, -1]), "white"),
        "left": (T.translate([-1, 0, 0]) @ ry(90), "red"),
        "right": (T.translate([1, 0, 0]) @ ry(-90), "green"),
    }
    d = {"type": "scene"}
    for n, (t, m) in walls.items():
        d[n] = {"type": "rectangle", "to_world": t, "bsdf": diffuse(mats[m])}
    d["light"] = {
        "type": "rectangle",
        "to_world": T.translate([0, 0.99, 0]) @ rx(90) @ T.scale([0.3, 0.3, 1]),
        "emitter": {"type": "area", "radiance": irregular(illum)},
        "bsdf": diffuse(mats["white"]),
    }
    d["sphere"] = {"type": "sphere", "center": [-0.4, -0.6, -0.3], "radius": 0.4,
                   "bsdf": diffuse(mats["blue"])}
    d["box"] = {
        "type": "cube",
        "to_world": T.translate([0.45, -0.7, 0.3]) @ ry(25) @ T.scale(0.3),
        "bsdf": diffuse(mats["yellow"]),
    }
    d["sensor"] = {
        "type": "perspective",
        "fov": 40,
        "to_world": T.look_at(origin=[0, 0, 3.9], target=[0, 0, 0], up=[0, 1, 0]),
    }
    return Scene("cornell", cornell.__doc__.strip(), d, spectra, max_depth=5)


# --- strips: five paper strips over a printed film ---------------------------------------------

STRIPS = ["paper/a", "paper/b", "paper/c", "reflectance/colorchecker:cyan",
          "reflectance/colorchecker:magenta"]
INKS = ["reflectance/colorchecker:white_9.5_.05_D", "reflectance/colorchecker:yellow",
        "reflectance/colorchecker:cyan", "reflectance/colorchecker:magenta"]


def print_weights(u, v, xp=np):
    """Smooth spatial weights of the film's four inks at texture coordinates (u, v) ∈ [0,1]²
    (u = image right, v = image up): non-negative, summing to 1."""
    pi = 3.141592653589793
    w1 = 0.5 + 0.5 * xp.sin(2 * pi * (0.8 * u + 0.3 * v))
    w2 = 0.5 + 0.5 * xp.cos(2 * pi * (0.5 * u - 0.9 * v) + 1.0)
    w3 = xp.exp(-((u - 0.35) ** 2 + (v - 0.6) ** 2) / 0.05)
    w0 = 0.1 + 0 * u
    s = w0 + w1 + w2 + w3
    return [w0 / s, w1 / s, w2 / s, w3 / s]


def strip_index(u):
    """Strip k ∈ 0..4 covers u ∈ [0.1 + 0.16k, 0.22 + 0.16k]; -1 where the film is bare."""
    k = np.floor((np.asarray(u) - 0.1) / 0.16)
    inside = (k >= 0) & (k <= 4) & ((np.asarray(u) - 0.1 - 0.16 * k) <= 0.12)
    return np.where(inside, k, -1).astype(int)


def make_film_texture():
    """A per-pixel spectral texture: τ(u,v,λ) = t_strip(u,λ) · Σ_k w_k(u,v) r_k(λ), a custom
    mi.Texture (bitmaps over 4 channels are refused by Mitsuba)."""
    import drjit as dr
    import mitsuba as mi

    class FilmWithStrips(mi.Texture):
        def __init__(self, props):
            super().__init__(props)
            self.inks = [mi.load_dict(irregular(sp.curve(n))) for n in INKS]
            self.strips = [mi.load_dict(irregular(sp.curve(n))) for n in STRIPS]

        def eval(self, si, active=True):
            u, v = si.uv.x, si.uv.y
            w = print_weights(u, v, xp=dr)
            film = w[0] * self.inks[0].eval(si, active)
            for wk, ink in zip(w[1:], self.inks[1:]):
                film += wk * ink.eval(si, active)
            k = dr.floor((u - 0.1) / 0.16)
            inside = (k >= 0) & (k <= 4) & ((u - 0.1 - 0.16 * k) <= 0.12)
            t = dr.ones(mi.UnpolarizedSpectrum, dr.width(u))
            for j, s in enumerate(self.strips):
                t = dr.select(inside & (k == j), s.eval(si, active), t)
            return film * t

        def eval_1(self, si, active=True):
            return dr.mean(self.eval(si, active))

        def mean(self):
            return 0.3

        def traverse(self, callback):
            pass

        def to_string(self):
            return "FilmWithStrips[]"

    return FilmWithStrips(mi.Properties())


def strips(build=True, illuminant="illuminants/D65") -> Scene:
    """The paper's test object: five strips of coloured paper (paper/a, b, c and ColorChecker
    cyan, magenta as stand-ins for paper transmittance) over a printed film (four measured inks
    mixed with smooth spatial weights). Transmission is simplified to reflection: the plane's
    reflectance is τ_film·t_paper and a frontal directional D65 lights it, so the radiance is
    τ_film·t_paper·E/π — the same spectrum shape as a backlight E behind a diffuse film."""
    illum = sp.curve(illuminant)
    inks = [sp.curve(n) for n in INKS]
    ts = [sp.curve(n) for n in STRIPS]
    spectra = [[illum, r] for r in inks] + [[illum, r, t] for r in inks for t in ts]
    if not build:
        return Scene("strips", strips.__doc__.strip(), None, spectra, max_depth=2)
    d = {
        "type": "scene",
        "light": _frontal_sun(illum),
        "film_plane": {"type": "rectangle", "bsdf": {"type": "diffuse",
                                                     "reflectance": make_film_texture()}},
        "sensor": _ortho_front(1.0),
    }
    return Scene("strips", strips.__doc__.strip(), d, spectra, max_depth=2)


SCENES = {"chart": chart, "cornell": cornell, "strips": strips}
