"""Calibration frames as numpy arrays: simulate returns them, reconstruct(calibration=...) uses them."""

import numpy as np
import pytest

import specmux

SIZE = 64
FOURIER = {"reconstruct": {"gap": {"method": "fourier"}}}


def experiment(size=SIZE, **rig):
    """The prototype at size² on the shaded objects, Fourier only, with these rig sections."""
    return specmux.Experiment.from_dict(
        {"scene": {"source": "shaded-objects", "size": [size, size]}, "rig": rig, **FOURIER}
    )


@pytest.fixture(scope="module")
def camera():
    """An experiment with a camera model: raw DN frames, dark and flat captures."""
    exp = experiment(sensor={})
    return exp, specmux.simulate(exp)


def test_simulate_returns_the_calibration_frames(camera):
    exp, sim = camera
    cal = sim["calibration"]
    assert sim["raw"] is True
    assert cal["dark"].shape == cal["flat"].shape == (SIZE, SIZE)
    assert cal["patterns"].shape == (6, SIZE, SIZE)
    for a in (cal["dark"], cal["flat"], cal["patterns"]):
        assert a.dtype == np.float32 and np.isfinite(a).all()
    # The flat is brighter than the dark everywhere; each pattern capture lies between them on
    # average and carries its carrier: a strong peak away from DC in its spectrum.
    assert (cal["flat"] > cal["dark"]).all()
    for p in cal["patterns"]:
        assert cal["dark"].mean() < p.mean() < cal["flat"].mean()
        spectrum = np.abs(np.fft.fft2(p - p.mean()))
        assert spectrum.max() > 20 * np.median(spectrum)
    # Without a camera model the frames are linear: no dark, no flat.
    plain = specmux.simulate(experiment())["calibration"]
    assert plain["dark"] is None and plain["flat"] is None
    assert plain["patterns"].shape == (6, SIZE, SIZE)
    oracle = experiment()
    oracle = specmux.Experiment.from_dict({**oracle.to_dict(), "calibration": {"source": "oracle"}})
    assert specmux.simulate(oracle)["calibration"] is None


def test_a_second_simulate_on_the_same_rig_reads_its_captures_back():
    # The module keeps the last rig's captures (in memory without $SPECMUX_PATTERN_CACHE).
    exp = experiment(sensor={"seed": 77})
    first, second = specmux.simulate(exp), specmux.simulate(exp)
    names = [[name for name, _ in s["stages"]] for s in (first, second)]
    assert "calibration-captures" not in names[1] and "calibration-cache" in names[1], names
    for key in ("dark", "flat", "patterns"):
        np.testing.assert_array_equal(first["calibration"][key], second["calibration"][key])
    np.testing.assert_array_equal(first["frame"], second["frame"])


def test_calibration_arrays_round_trip_to_the_same_cube(camera):
    exp, sim = camera
    built_in = specmux.reconstruct(exp, sim["frame"], full=True)
    given = specmux.reconstruct(exp, sim["frame"], calibration=sim["calibration"], full=True)
    # The same frames, through the core's Calibration::from_frames either way: the same cube.
    np.testing.assert_array_equal(given["cube"], built_in["cube"])
    assert "simulated captures" in built_in["calibration"]["source"]
    assert given["calibration"]["source"] == "arrays given to reconstruct(calibration=…)"
    assert len(given["calibration"]["carriers"]) == 6
    # A list of 2-D pattern frames is the same as one 3-D array.
    cal = dict(sim["calibration"], patterns=list(sim["calibration"]["patterns"]))
    np.testing.assert_array_equal(specmux.reconstruct(exp, sim["frame"], calibration=cal), given["cube"])
    # Raw DN as a camera delivers them (uint16) give the same cube as their float32 copy.
    dn = sim["frame"].astype(np.uint16)
    np.testing.assert_array_equal(dn, sim["frame"])
    np.testing.assert_array_equal(specmux.reconstruct(exp, dn, calibration=cal), given["cube"])


def test_an_integer_frame_needs_the_experiments_camera(camera):
    _, sim = camera
    with pytest.raises(specmux.SpecmuxError) as e:
        specmux.reconstruct(experiment(), sim["frame"].astype(np.uint16))
    assert "rig.sensor" in str(e.value) and "raw DN" in str(e.value)


def test_measured_frames_of_a_misaligned_rig_find_its_carriers():
    """A rig whose DMD image is rotated by 1° and scaled by 1.005 records a frame and its
    calibration frames; reconstructed with the design (no misalignment), the design's own
    simulated captures miss the moved carriers, the rig's recorded frames find them: the cube
    the rig itself gives."""
    size = 128
    rig = experiment(sensor={}, alignment={"rotation_deg": 1.0, "magnification": 1.005}, size=size)
    design = experiment(sensor={}, size=size)
    rec = specmux.simulate(rig)
    without = specmux.reconstruct(design, rec["frame"])
    with_frames = specmux.reconstruct(design, rec["frame"], calibration=rec["calibration"])
    own = specmux.reconstruct(rig, rec["frame"])
    psnr = {k: specmux.metrics(rec["truth"], c)["psnr_db"] for k, c in
            [("without", without), ("with", with_frames), ("own", own)]}
    print(f"misaligned rig at {size}²: {psnr}")
    np.testing.assert_array_equal(with_frames, own)
    assert psnr["with"] > psnr["without"] + 3.0, psnr


@pytest.mark.parametrize(
    "change, words",
    [
        (lambda c: dict(c, flat=c["flat"][:32, :32]), ['calibration["flat"]', "(32, 32)", "(64, 64)"]),
        (lambda c: dict(c, patterns=np.where(np.arange(6)[:, None, None] == 2, np.nan, c["patterns"])),
         ['calibration["patterns"][2]', "pixel (0, 0)", "NaN", "finite"]),
        (lambda c: dict(c, dark=c["dark"] * np.float32(1e-40)), ['calibration["dark"]', "under 1e-30"]),
        (lambda c: dict(c, patterns=list(c["patterns"][:5])), ["5 pattern captures for 6 carriers", "calibration"]),
        (lambda c: dict(c, dark=None), ["dark frame needs a flat frame"]),
        (lambda c: dict(c, darkk=c["dark"]), ['"darkk"', "dark, flat and patterns"]),
        (lambda c: {"dark": c["dark"], "flat": c["flat"]}, ['no "patterns"']),
        (lambda c: dict(c, patterns=c["patterns"][:, None]), ['calibration["patterns"]', "shape"]),
        (lambda c: [c["patterns"]], ["expected a dict"]),
    ],
)
def test_a_bad_calibration_array_is_refused_by_name(camera, change, words):
    exp, sim = camera
    with pytest.raises(specmux.SpecmuxError) as e:
        specmux.reconstruct(exp, sim["frame"], calibration=change(sim["calibration"]))
    msg = str(e.value)
    assert "\n" not in msg
    for w in words:
        assert w in msg, msg


def test_a_bad_frame_is_refused_by_name(camera):
    exp, sim = camera
    frame = sim["frame"].copy()
    frame[3, 5] = np.inf
    with pytest.raises(specmux.SpecmuxError) as e:
        specmux.reconstruct(exp, frame)
    assert "frame: pixel (5, 3) is inf" in str(e.value)


def test_a_frame_under_its_noise_warns_and_reports_its_snr(camera):
    exp, sim = camera
    given = specmux.reconstruct(exp, sim["frame"], calibration=sim["calibration"], full=True)
    assert given["mean_snr"] > 10
    # The dark frame itself as the frame: no signal above dark, a UserWarning that says so.
    dark = sim["calibration"]["dark"]
    with pytest.warns(UserWarning, match="times its noise"):
        out = specmux.reconstruct(exp, dark, calibration=sim["calibration"], full=True)
    assert abs(out["mean_snr"]) < 1
    # Without a camera there is no noise model: no SNR, no warning.
    plain = experiment()
    assert specmux.reconstruct(plain, specmux.simulate(plain)["frame"], full=True)["mean_snr"] is None


def test_a_frame_of_another_size_than_the_experiment_writes_warns():
    frame = specmux.simulate(experiment(32))["frame"]
    with pytest.warns(UserWarning, match=r"scene.size = \[64, 64\], but the frame is 32×32"):
        cube = specmux.reconstruct(experiment(64), frame)
    assert cube.shape[1:] == (32, 32)
