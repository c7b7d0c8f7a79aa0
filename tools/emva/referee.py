"""The EMVA 1288 reference analysis (PyPI `emva1288`) as the referee of specmux's camera model:
it analyses the raw frames of `specmux ptc --emva` on its own and must find the camera the
experiment describes, and the same figures as specmux's own measurement.

usage: referee.py PTC_OUT [--check]   (PTC_OUT written by `specmux ptc --emva --out PTC_OUT`)
Prints one line per quantity; --check also asserts the agreement (exit 1 on a failure).
"""

import json
import logging
import math
import sys
from pathlib import Path

from emva1288.process import Data1288, LoadImageData, ParseEmvaDescriptorFile, Results1288

# The photon counts in the descriptor are electrons / this QE (crates/report/src/ptc.rs).
DESCRIPTOR_QE_PERCENT = 50.0


def emva_results(descriptor: Path) -> dict:
    """K, dark noise, saturation capacity, QE, DSNU and PRNU as the reference code finds them."""
    quiet = logging.WARNING
    parser = ParseEmvaDescriptorFile(str(descriptor), loglevel=quiet)
    images = LoadImageData(parser.images, loglevel=quiet)
    data = Data1288(images.data, loglevel=quiet)
    r = Results1288(data.data, loglevel=quiet)
    return {
        "K (DN/e-)": float(r.K),
        "dark noise (e-)": float(r.sigma_d),
        "saturation (e-)": float(r.u_e_sat),
        "QE (%)": float(r.QE),
        "DSNU (e-)": float(r.DSNU1288),
        "PRNU (%)": float(r.PRNU1288),
    }


def specmux_figures(ptc: dict) -> tuple[dict, dict]:
    """specmux's measured figures and the camera's given ones, under the referee's names."""
    m, c = ptc["measured"], ptc["camera"]
    measured = {
        "K (DN/e-)": m["k_dn_per_e"],
        "dark noise (e-)": m["read_noise_e"],
        "saturation (e-)": m["full_well_e"],
        "QE (%)": DESCRIPTOR_QE_PERCENT,
        "DSNU (e-)": m["dsnu_e"],
        "PRNU (%)": 100 * m["prnu_fraction"],
    }
    dark_e = ptc["dark_electrons_per_exposure"]
    given = {
        "K (DN/e-)": c["gain_dn_per_e"],
        "dark noise (e-)": math.hypot(c["read_noise_e"], math.sqrt(dark_e)),
        "saturation (e-)": c["full_well_e"],
        "QE (%)": DESCRIPTOR_QE_PERCENT,
        "DSNU (e-)": c["dsnu_e"],
        "PRNU (%)": 100 * c["prnu_fraction"],
    }
    return measured, given


# Relative bounds, referee against specmux's own figures (same frames, so only the two codes'
# choices differ: fit range, saturation point) and against the camera as given (sampling error
# of 65 536 pixels: K 0.3 % at 1 σ, dark noise 0.3 %, DSNU/PRNU about 1 %; the saturation
# capacity sits 2–3 σ of the pixel spread below the full well, docs/sensor.md).
BOUNDS = {
    "K (DN/e-)": (0.005, 0.015),
    "dark noise (e-)": (0.01, 0.015),
    "saturation (e-)": (0.01, 0.06),
    "QE (%)": (0.01, 0.01),
    "DSNU (e-)": (0.02, 0.05),
    "PRNU (%)": (0.02, 0.05),
}


def main() -> int:
    out = Path(sys.argv[1])
    ref = emva_results(out / "emva1288" / "emva1288.txt")
    measured, given = specmux_figures(json.loads((out / "ptc.json").read_text()))
    failed = 0
    print(f"{'':<16} {'emva1288':>10} {'specmux':>10} {'given':>10}")
    for key, value in ref.items():
        d_ours = abs(value / measured[key] - 1)
        d_given = abs(value / given[key] - 1)
        b_ours, b_given = BOUNDS[key]
        bad = d_ours > b_ours or d_given > b_given
        failed += bad
        flag = "  FAIL" if bad else ""
        print(f"{key:<16} {value:>10.5g} {measured[key]:>10.5g} {given[key]:>10.5g}{flag}")
    if "--check" in sys.argv and failed:
        print(f"{failed} quantities outside their bounds", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
