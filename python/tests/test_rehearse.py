"""The controller's rehearsal from Python: the plan, its checks, every frame's error and the event log."""

import json
import math

import numpy as np
import pytest

import specmux
from conftest import REPO

SIZE = 64


@pytest.fixture(scope="module")
def moving(tmp_path_factory):
    """scenes/moving-spheres.toml at SIZE² (an experiment file, so the CLI can run it too)."""
    text = (REPO / "scenes" / "moving-spheres.toml").read_text()
    assert "size = [256, 256]" in text
    path = tmp_path_factory.mktemp("moving") / "moving.toml"
    path.write_text(text.replace("size = [256, 256]", f"size = [{SIZE}, {SIZE}]"))
    return path


@pytest.fixture(scope="module")
def rehearsal(moving, tmp_path_factory):
    out = tmp_path_factory.mktemp("rehearsal") / "py"
    return specmux.rehearse(specmux.Experiment.from_file(moving), frames=3, cubes=True, out=out)


def test_rehearse_returns_frames_cubes_checks_and_events(rehearsal):
    r = rehearsal
    assert r["passes"] and all(c["ok"] for c in r["checks"]) and r["checks"]
    assert r["outcome"]["completed"] and r["outcome"]["incidents"] == []
    assert len(r["frames"]) == len(r["cubes"]) == len(r["outcome"]["frames"]) == 3
    for f, cube in zip(r["frames"], r["cubes"]):
        assert math.isfinite(f["psnr_db"]) and f["psnr_db"] > 15.0, f
        assert 0.0 < f["ssim"] <= 1.0 and f["flags"] == 0 and f["reconstruction_s"] > 0.0
        assert cube.shape == (31, SIZE, SIZE) and np.isfinite(cube).all()
    # One frame period apart on the virtual clock, which ran past the last frame.
    times = [f["timestamp_s"] for f in r["frames"]]
    period = np.diff(times)
    assert np.allclose(period, period[0]) and period[0] > 0
    assert r["virtual_s"] > times[-1]
    # The devices' log: time-ordered, from the wheel, the DMD and the camera.
    events = r["events"]
    assert {e["device"] for e in events} >= {"wheel", "dmd", "camera"}
    assert [e["t_ns"] for e in events] == sorted(e["t_ns"] for e in events)
    assert [p["what"] for p in r["timeline"]][-1] == "stop"
    assert "acquired 3 frames (0 marked)" in r["text"]


def test_rehearse_gives_the_clis_errors(rehearsal, moving, cli, tmp_path):
    cli("rehearse", moving, "--frames", 3, "--out", tmp_path / "cli")
    frames = json.loads((tmp_path / "cli" / "rehearsal.json").read_text())["frames"]
    assert [f["psnr_db"] for f in frames] == [f["psnr_db"] for f in rehearsal["frames"]]
    assert [f["timestamp_s"] for f in frames] == [f["timestamp_s"] for f in rehearsal["frames"]]


def test_a_fault_is_reported_and_a_refused_plan_raises(moving):
    exp = specmux.Experiment.from_file(moving)
    r = specmux.rehearse(exp, frames=4, faults=["dropped-frame@2"])
    # The third exposure never arrives: four frames are kept, the incident names the lost id.
    ids = [f["frame_id"] for f in r["frames"]]
    assert ids == [ids[0], ids[0] + 1, ids[0] + 3, ids[0] + 4] and r["cubes"] is None
    [incident] = r["outcome"]["incidents"]
    assert incident["kind"] == "dropped-frame" and incident["frame_ids"] == [ids[0] + 2]
    with pytest.raises(specmux.SpecmuxError) as e:
        specmux.rehearse(exp, faults=["no-such-fault@1"])
    # The argument is named as Python spells it, not as the CLI does.
    assert "no-such-fault" in str(e.value) and "`faults`" in str(e.value)
    dry = specmux.rehearse(exp, frames=10**7, dry_run=True)
    assert not dry["passes"] and "REFUSE" in dry["text"] and "frames" not in dry
    with pytest.raises(specmux.SpecmuxError):
        specmux.rehearse(exp, frames=10**7)
