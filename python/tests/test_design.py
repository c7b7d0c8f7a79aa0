"""The design tools from Python: the same options, defaults and results as `specmux design`."""

import re
import shutil

import numpy as np
import pytest

import specmux
from conftest import REPO

CRITERIA = ["max_corr", "cond", "noise_gain", "library_rmse", "predicted_rmse"]


@pytest.fixture(scope="module")
def catalogue(tmp_path_factory):
    """Eight transmittances: the prototype's six wheel curves and two Gaussian band-passes."""
    d = tmp_path_factory.mktemp("catalogue")
    for name in ["wheel/red", "wheel/green", "wheel/blue", "paper/a", "paper/b", "paper/c"]:
        shutil.copy(REPO / "spectra" / f"{name}.csv", d / f"{name.replace('/', '-')}.csv")
    wl = np.arange(380, 781)
    for centre in (450, 600):
        t = 0.02 + 0.88 * np.exp(-0.5 * ((wl - centre) / 25.0) ** 2)
        rows = "\n".join(f"{w:.1f},{v:.6f}" for w, v in zip(wl, t))
        (d / f"gauss-{centre}.csv").write_text(
            f"# provenance: test curve, Gaussian band-pass at {centre} nm, sigma 25 nm\n"
            f"wavelength_nm,transmittance\n{rows}\n"
        )
    return d


def filter_options(catalogue):
    """A small search: C(8, 6) = 28 sets, the best of two criteria simulated on bars at 32²."""
    return dict(catalog=catalogue, no_families=True, choose=6, top=3, simulate=1,
                scenes=[REPO / "scenes" / "bars.toml"], size=32)


def cli_args(options):
    """The same options as the CLI's arguments."""
    args = []
    for k, v in options.items():
        flag = "--" + k.replace("_", "-")
        if v is True:
            args.append(flag)
        else:
            for item in v if isinstance(v, list) else [v]:
                args += [flag, str(item)]
    return args


def best_sets(text):
    """The rank-1 set of every criterion in the text `specmux design filters` prints."""
    best, criterion = {}, None
    for line in text.splitlines():
        m = re.match(r"best by (\w+)", line)
        if m:
            criterion = m.group(1)
        m = re.match(r"\s+1(\s+[0-9.]+){5}\s+(.*)$", line)
        if m and criterion:
            best[criterion], criterion = m.group(2).split(", "), None
    return best


@pytest.fixture(scope="module")
def filters(catalogue):
    return specmux.design_filters(**filter_options(catalogue))


def test_design_filters_ranks_every_criterion(filters, catalogue):
    r = filters
    assert r["report"]["combinations"] == 28
    assert len(r["report"]["catalogue"]) == 8
    assert list(r["ranked"]) == CRITERIA
    for criterion, sets in r["ranked"].items():
        assert 1 <= len(sets) <= 3
        values = [s["value"] for s in sets]
        assert values == sorted(values), criterion
        for s in sets:
            assert len(s["filters"]) == 6 and len(set(s["filters"])) == 6
            assert s["value"] == pytest.approx(s["scores"][criterion], rel=1e-9)
    # The chosen set is a simulated one, written as the [rig.wheel] section.
    labels = [s["label"] for s in r["simulated"]]
    assert labels == ["base wheel", "max_corr #1", "predicted_rmse #1"]
    chosen = next(s for s in r["simulated"] if s["label"] == r["chosen"])
    assert "[rig.wheel]" in r["toml"]
    assert all(f'"{f}"' in r["toml"] for f in chosen["filters"])
    assert r["out"] is None and r["provenance"]["schema_version"] >= 1
    # The temporary folder is gone on return, so the text does not name it.
    assert "specmux-design-filters-" not in r["text"]
    assert "(a temporary folder, removed; pass out= to keep the files)" in r["text"]


def test_design_filters_matches_the_cli(filters, catalogue, cli, tmp_path):
    options = filter_options(catalogue)
    text = cli("design", "filters", *cli_args(options), "--out", tmp_path / "cli")
    best = best_sets(text)
    assert list(best) == CRITERIA
    for criterion in CRITERIA:
        assert filters["ranked"][criterion][0]["filters"] == best[criterion], criterion
    assert filters["toml"] == (tmp_path / "cli" / "wheel.toml").read_text()


def test_design_options_are_checked_as_on_the_command_line(catalogue):
    with pytest.raises(specmux.SpecmuxError) as e:
        specmux.design_filters(chose=3)
    assert str(e.value) == "design filters: unexpected argument '--chose' found"
    with pytest.raises(specmux.SpecmuxError) as e:
        specmux.design_filters(catalog=catalogue, no_families=True, choose=9)
    assert "`choose` = 9" in str(e.value) and "catalogue's 8" in str(e.value)


def test_design_carriers_is_never_worse_than_the_papers_layout(cli, tmp_path):
    options = dict(size=64, scenes=[REPO / "scenes" / "bars.toml"], restarts=2, candidates=1)
    r = specmux.design_carriers(out=tmp_path / "py", **options)
    cands, chosen = r["candidates"], r["chosen"]
    # Here (seed 1) a designed layout wins; the paper's would be chosen if none gained everywhere.
    assert cands[0]["label"].startswith("paper") and cands[chosen]["label"].startswith("designed")
    paper, best = cands[0]["ideal"], cands[chosen]["ideal"]
    assert [o["scene"] for o in best] == ["bars"]
    assert all(b["cube_psnr_db"] >= p["cube_psnr_db"] for b, p in zip(best, paper))
    bins = cands[chosen]["layout"]["bins"]
    assert "[rig.carriers]" in r["toml"] and str([tuple(b) for b in bins]) in r["toml"]
    assert r["out"] == str(tmp_path / "py")
    # The CLI with the same options writes the same section.
    cli("design", "carriers", *cli_args(options), "--out", tmp_path / "cli")
    assert r["toml"] == (tmp_path / "cli" / "carriers.toml").read_text()
    # The experiment it writes runs as it is and gives the chosen layout's simulated error.
    exp = specmux.Experiment.from_toml(r["experiment_toml"], "experiment.toml")
    run = specmux.run(exp)["report"]["results"]
    unmix = next(row for row in run if row["stage"] == "unmix")
    assert unmix["psnr_db"] == pytest.approx(best[0]["cube_psnr_db"], abs=1e-9)
