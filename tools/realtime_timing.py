"""Time `specmux.Reconstructor.realtime` on 768² prototype frames (dead-leaves, and the shaded
objects of seed 11), noiseless: medians of 30 calls after 3 warm-up calls into a kept array, and
of 10 calls returning a new array; docs/python.md, "Frame after frame".

Run (from the repository root, with a release build of the Python package in the venv):
    CARGO_TARGET_DIR=target tools/.venv-python/bin/pip install --force-reinstall --no-deps ./python
    tools/.venv-python/bin/python tools/realtime_timing.py
"""
import statistics
import time

import numpy as np
import specmux


def experiment(scene):
    """The prototype with `scene` as its source (the shaded objects with seed 11, as the bench)."""
    exp = specmux.Experiment.prototype(scene=scene)
    if scene == "shaded-objects":
        d = exp.to_dict()
        d["scene"]["seed"] = 11
        exp = specmux.Experiment.from_dict(d)
    return exp


def timed(call, count):
    """Seconds of each of `count` calls."""
    out = []
    for _ in range(count):
        t0 = time.perf_counter()
        call()
        out.append(time.perf_counter() - t0)
    return out


for scene in ("dead-leaves", "shaded-objects"):
    exp = experiment(scene)
    frame = specmux.simulate(exp)["frame"]
    recon = specmux.Reconstructor(exp)
    out = np.empty((recon.bands, *recon.shape), np.float32)
    timed(lambda: recon.realtime(frame, out=out), 3)
    kept = timed(lambda: recon.realtime(frame, out=out), 30)
    new = timed(lambda: recon.realtime(frame), 10)
    print(
        f"{scene}: realtime(frame, out=out) median {1e3 * statistics.median(kept):.1f} ms "
        f"[{1e3 * min(kept):.1f}, {1e3 * max(kept):.1f}]; "
        f"new array each call median {1e3 * statistics.median(new):.1f} ms"
    )
