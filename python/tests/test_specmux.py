"""Tests of the specmux Python package (pip install ./python; see docs/python.md)."""

import os
import re
import subprocess

import numpy as np
import pytest

import specmux

SIZE = 64


@pytest.fixture(scope="module")
def exp():
    e = specmux.Experiment.prototype()
    e.size = (SIZE, SIZE)
    return e


@pytest.fixture(scope="module")
def sim(exp):
    return specmux.simulate(exp)


@pytest.fixture(scope="module")
def cube(exp, sim):
    return specmux.reconstruct(exp, sim["frame"])


def cli_psnr(tmp_path):
    """The final cube's PSNR that `specmux demo --size 64` prints (row `unmix  r (true cube)`)."""
    binary = os.environ.get("SPECMUX_BIN")
    if not binary:
        pytest.skip("SPECMUX_BIN not set (.ci/python-check.sh sets it to the built CLI)")
    out = subprocess.run(
        [binary, "demo", "--size", str(SIZE), "--out", str(tmp_path / "demo")],
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    for line in out.splitlines():
        m = re.match(r"unmix\s+r \(true cube\)\s+(-?[0-9.]+)", line)
        if m:
            return float(m.group(1))
    raise AssertionError(f"no 'unmix r (true cube)' row in:\n{out}")


def test_shapes_and_dtypes(exp, sim, cube):
    bands = sim["truth"].shape[0]
    assert sim["frame"].shape == (SIZE, SIZE)
    assert sim["truth"].shape == (bands, SIZE, SIZE)
    assert sim["channels"].shape == (6, SIZE, SIZE)
    assert cube.shape == (bands, SIZE, SIZE)
    for a in (sim["frame"], sim["truth"], sim["channels"], cube):
        assert a.dtype == np.float32
        assert np.isfinite(a).all()
    assert exp.size == (SIZE, SIZE)
    assert exp.file == "<built-in prototype>"


def test_reconstruction_psnr_matches_run_and_cli(exp, sim, cube, tmp_path):
    m = specmux.metrics(sim["truth"], cube)
    r = specmux.run(exp)
    rows = {row["stage"]: row for row in r["report"]["results"]}
    # The same run: simulate + reconstruct here and the twin's run give the same cube.
    assert round(m["psnr_db"], 2) == round(rows["unmix"]["psnr_db"], 2)
    np.testing.assert_array_equal(r["cube"], cube)
    np.testing.assert_array_equal(r["frame"], sim["frame"])
    assert r["cube"].shape == r["truth"].shape
    assert r["xhat"].shape == (6, SIZE, SIZE)
    print(f"PSNR of the reconstructed cube at {SIZE}x{SIZE}: {m['psnr_db']:.2f} dB")
    # ... and equal, to the printed 2 decimals, to what `specmux demo --size 64` prints.
    assert f"{m['psnr_db']:.2f}" == f"{cli_psnr(tmp_path):.2f}"


def test_full_reconstruction_and_metrics(exp, sim):
    out = specmux.reconstruct(exp, sim["frame"].astype(np.float64), full=True)
    assert set(out) >= {"cube", "xhat", "xgap", "unmix", "gap", "seconds"}
    assert out["xhat"].shape == (6, SIZE, SIZE)
    same = specmux.metrics(sim["truth"], sim["truth"])
    assert same["exact_planes"] == sim["truth"].shape[0]
    with pytest.raises(specmux.SpecmuxError):
        specmux.metrics(sim["truth"], sim["truth"][:, :10, :10])


def test_the_reconstruction_runs_on_the_experiments_device(exp, sim):
    """`[compute] device` names where `reconstruct` and a `Reconstructor` run, and the result says
    it; this wheel has no GPU backend, so "gpu" is refused by its key and "auto" stays on the CPU."""
    full = specmux.reconstruct(exp, sim["frame"], full=True)
    assert full["device"].startswith("CPU"), full["device"]
    assert specmux.Reconstructor(exp).device.startswith("CPU")
    d = exp.to_dict()
    d["compute"] = {"device": "auto"}
    auto = specmux.Experiment.from_dict(d)
    assert specmux.reconstruct(auto, sim["frame"], full=True)["device"].startswith("CPU")
    d["compute"] = {"device": "gpu"}
    gpu = specmux.Experiment.from_dict(d)
    for call in (lambda: specmux.reconstruct(gpu, sim["frame"]), lambda: specmux.Reconstructor(gpu)):
        with pytest.raises(specmux.SpecmuxError, match=r"compute\.device.*--features gpu"):
            call()


def test_a_reconstructor_built_once_gives_what_reconstruct_gives(exp, sim, cube):
    recon = specmux.Reconstructor(exp)
    assert recon.shape == (SIZE, SIZE)
    assert recon.bands == cube.shape[0]
    # Frame after frame, the experiment's method: the cube `reconstruct` gives.
    for _ in range(2):
        np.testing.assert_array_equal(recon(sim["frame"]), cube)
    assert set(recon(sim["frame"], full=True)) >= {"cube", "xhat", "unmix", "seconds"}
    # The real-time path is the Fourier method's cube, into a kept array when given one.
    d = exp.to_dict()
    d["reconstruct"]["gap"] = {"method": "fourier"}
    fourier = specmux.reconstruct(specmux.Experiment.from_dict(d), sim["frame"])
    np.testing.assert_array_equal(recon.realtime(sim["frame"]), fourier)
    out = np.full(fourier.shape, np.nan, dtype=np.float32)
    assert recon.realtime(sim["frame"], out=out) is out
    np.testing.assert_array_equal(out, fourier)
    with pytest.raises(specmux.SpecmuxError, match=f"built for {SIZE}×{SIZE}"):
        recon(np.zeros((SIZE // 2, SIZE), np.float32))
    with pytest.raises(specmux.SpecmuxError, match="out is"):
        recon.realtime(sim["frame"], out=np.zeros((fourier.shape[0], SIZE, 3), np.float32))
    strided = np.zeros((fourier.shape[0], SIZE, 2 * SIZE), np.float32)[:, :, ::2]
    with pytest.raises(specmux.SpecmuxError, match="C-contiguous"):
        recon.realtime(sim["frame"], out=strided)
    with pytest.raises(specmux.SpecmuxError, match="float32 array .* this one is float64"):
        recon.realtime(sim["frame"], out=np.zeros(fourier.shape, np.float64))
    with pytest.raises(specmux.SpecmuxError, match="this one is a list"):
        recon.realtime(sim["frame"], out=[])
    with pytest.raises(specmux.SpecmuxError, match="rig.sensor"):
        recon(sim["frame"].astype(np.uint16))
    bad = sim["frame"].copy()
    bad[3, 5] = np.nan
    with pytest.raises(specmux.SpecmuxError, match=r"pixel \(5, 3\)"):
        recon.realtime(bad)
    # Finite but beyond what f32 squares hold: refused by value, with what to do.
    bad[3, 5] = 3e38
    with pytest.raises(specmux.SpecmuxError, match=r"pixel \(5, 3\) is 3e38.*scale the frame"):
        recon(bad)


def test_bad_toml_names_the_key():
    with pytest.raises(specmux.SpecmuxError) as e:
        specmux.Experiment.from_toml("[scene]\nsize = [64, 64]\nno_such_key = 3\n", "bad.toml")
    assert "no_such_key" in str(e.value)
    assert "bad.toml" in str(e.value)
    with pytest.raises(specmux.SpecmuxError) as e:
        specmux.Experiment.from_toml("[scene]\nsize = [0, 64]\n", "bad.toml")
    assert "scene.size" in str(e.value)
    assert issubclass(specmux.SpecmuxError, Exception)


def test_from_file_and_dict(tmp_path):
    p = tmp_path / "exp.toml"
    p.write_text("[scene]\nsize = [32, 32]\n")
    e = specmux.Experiment.from_file(str(p))
    assert e.size == (32, 32)
    assert e.file == str(p)
    d = specmux.Experiment.from_dict({"scene": {"size": [32, 32]}})
    assert d.to_dict()["scene"]["size"] == [32, 32]
    with pytest.raises(specmux.SpecmuxError):
        specmux.Experiment.from_file(str(tmp_path / "missing.toml"))


def test_a_dict_is_read_as_the_toml_file_would_be():
    # numpy values are numbers and lists; NaN reaches the key's own check, as in a file.
    e = specmux.Experiment.from_dict({"scene": {"size": np.array([48, 48]), "seed": np.int64(3)},
                                      "reconstruct": {"eta": np.float32(5.0)}})
    assert e.size == (48, 48) and e.to_dict()["reconstruct"]["eta"] == 5.0
    for d, words in [
        ({"reconstruct": {"eta": float("nan")}}, ["<dict>: `reconstruct.eta` = NaN", "finite"]),
        ({"scene": {"seed": object()}}, ["<dict>: `scene.seed` = <object", "not a value a TOML file holds"]),
        ({"scene": {"seed": 2**80}}, ["`scene.seed` = 1208925819614629174706176", "64 bits"]),
        ({"scene": {"size": [64, None]}}, ["`scene.size[1]` = None", "cannot hold None"]),
        ({1: {}}, ["<dict>: the key 1 is not a string"]),
    ]:
        with pytest.raises(specmux.SpecmuxError) as err:
            specmux.Experiment.from_dict(d)
        for w in words:
            assert w in str(err.value), (w, str(err.value))
        assert "SpecmuxError" not in str(err.value) and "\n" not in str(err.value)


def test_to_dict_reads_back_to_the_same_experiment():
    # The prototype's method is "auto": the counts it chooses are not written back.
    for e in (specmux.Experiment.prototype(size=32), specmux.Experiment.from_dict({"rig": {"sensor": {}}})):
        again = specmux.Experiment.from_dict(e.to_dict())
        assert again.to_dict() == e.to_dict()
        # ... and as a file's text, which from_toml (and the CLI) read back.
        assert specmux.Experiment.from_toml(e.to_toml(), "saved.toml").to_dict() == e.to_dict()


def test_size_takes_a_pair_or_one_int_for_a_square():
    e = specmux.Experiment.prototype(size=32)
    e.size = 48
    assert e.size == (48, 48)
    e.size = (64, 32)
    assert e.size == (64, 32)
    for bad in ("big", (1, 2, 3), -4):
        with pytest.raises(specmux.SpecmuxError, match="one int for a square"):
            e.size = bad
    with pytest.raises(specmux.SpecmuxError, match=r"scene.size\[0\]"):
        e.size = 0
    assert e.size == (64, 32)
