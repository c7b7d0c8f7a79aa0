"""The notebook walk-through of docs/python.md, sections "Your own calibration frames", "Choosing
the filters and the carriers" and "Rehearsing an acquisition", as one script: run it from the
repository root (`python python/examples/walkthrough.py`) after `pip install ./python`; every
number docs/python.md quotes in those sections is printed here."""

import shutil
import tempfile
from pathlib import Path

import numpy as np

import specmux

# --- Your own calibration frames ----------------------------------------------------------
design = specmux.Experiment.from_dict({
    "scene": {"source": "shaded-objects", "size": [128, 128]},
    "rig": {"sensor": {}},                                   # a camera: frames in raw DN
    "reconstruct": {"gap": {"method": "fourier"}},
})
# The rig as built: its DMD image turned by 1° and scaled by 1.005 against the design.
rig = specmux.Experiment.from_dict({
    **design.to_dict(), "rig": {**design.to_dict()["rig"],
                                "alignment": {"rotation_deg": 1.0, "magnification": 1.005}},
})
rec = specmux.simulate(rig)                                  # what the rig records
cal = rec["calibration"]
print({k: (v.shape, str(v.dtype)) for k, v in cal.items()})
print(f"dark {cal['dark'].mean():.1f} DN, flat {cal['flat'].mean():.1f} DN, "
      f"patterns {[round(float(p.mean()), 1) for p in cal['patterns']]} DN")

frame = rec["frame"].astype(np.uint16)                       # raw DN, as a camera saves them
for label, kw in [("the design's simulated captures", {}), ("the rig's measured frames", {"calibration": cal})]:
    out = specmux.reconstruct(design, frame, full=True, **kw)
    m = specmux.metrics(rec["truth"], out["cube"])
    shift = max(np.hypot(*c["shift"]) for c in out["calibration"]["carriers"])
    print(f"{label}: {m['psnr_db']:.2f} dB, SAM {m['sam_deg']:.1f}°, "
          f"largest carrier shift found {shift * 128:.2f} bins")

try:
    specmux.reconstruct(design, frame, calibration={**cal, "flat": cal["flat"][:64]})
except specmux.SpecmuxError as e:
    print(e)

# --- Choosing the filters and the carriers -------------------------------------------------
repo = Path.cwd()
work = Path(tempfile.mkdtemp())
spectra = shutil.copytree(repo / "spectra", work / "spectra")  # generated curves go here
f = specmux.design_filters(spectra=spectra, choose=6, keep=["wheel/red", "wheel/green", "wheel/blue"],
                           scenes=["scenes/bars.toml", "scenes/shaded-objects.toml"], size=128,
                           simulate=1, out=work / "filters")
print(f"{f['report']['combinations']} sets of the {len(f['report']['catalogue'])} curves")
for criterion in ("max_corr", "predicted_rmse"):
    best = f["ranked"][criterion][0]
    s = best["scores"]
    chosen = [x for x in best["filters"] if not x.startswith("wheel/")]
    print(f"best by {criterion}: + {', '.join(chosen)} — max_corr {s['max_corr']:.3f}, "
          f"cond {s['cond']:.1f}, noise gain {s['noise_gain']:.2f}, predicted RMSE {s['predicted_rmse']:.4f}")
for s in f["simulated"]:
    print(f"{s['label']:<18}", "  ".join(f"{o['scene']} {o['cube_psnr_db']:.2f} dB" for o in s["outcomes"]))
print(f["toml"])

c = specmux.design_carriers(size=128, scenes=["scenes/shaded-objects.toml"], out=work / "carriers")
for cand in c["candidates"]:
    o = cand["ideal"][0]
    print(f"{cand['label']:<36} predicted {cand['predicted']:.3g}  {o['scene']} {o['cube_psnr_db']:.2f} dB")
print(c["toml"])
exp = specmux.Experiment.from_toml(c["experiment_toml"], "designed.toml")
print(f"designed layout, run again: {specmux.metrics(*[specmux.run(exp)[k] for k in ('truth', 'cube')])['psnr_db']:.2f} dB")

# --- Rehearsing an acquisition --------------------------------------------------------------
moving = specmux.Experiment.from_file("scenes/moving-spheres.toml")
dry = specmux.rehearse(moving, frames=5, dry_run=True)
print(f"{sum(c['ok'] for c in dry['checks'])} of {len(dry['checks'])} checks pass; passes = {dry['passes']}")
print(dry["text"].splitlines()[-1])
r = specmux.rehearse(moving, frames=5, faults=["dropped-frame@3"], cubes=True)
for row in r["frames"]:
    print(row["frame_id"], f"{row['timestamp_s']:.6f} s", f"{row['psnr_db']:.2f} dB", f"{row['reconstruction_s']:.3f} s")
print(r["outcome"]["incidents"])
print(len(r["events"]), "events; the first:", r["events"][0])
print(f"virtual {r['virtual_s']:.3f} s, wall {r['wall_s']:.2f} s, cubes {r['cubes'][0].shape}")
shutil.rmtree(work)
