"""Provenance and consistency (pyomo_heli.provenance and the commands' checks): nothing overwritten unasked,
results and config agree, implausible input named.

Every test runs on a tiny config or fixture and checks one guarantee of docs/robustness.md, section
"Data never overwritten, results and config agree".
"""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from pyomo_heli.cli import main

ROOT = Path(__file__).resolve().parent.parent
CONFIGS = ROOT / "tests" / "configs"

TINY_GEN = """\
[dataset]
name = "tiny"
aircraft = "Bo-105 (tiny test config)"
seed = {seed}

[truth]
parameters = {{}}

[sensors]
noise = true

[trims]
speeds_kt = [20, 60]

{maneuvers}
"""

MANEUVER = """\
[[maneuvers]]
name = "{name}"
role = "identification"
speed_kt = 80
channel = "lon"
shape = "doublet"
amplitude_deg = 0.5
step_s = 0.5
duration_s = 2
t_start_s = 0.5
"""


def _gen_config(tmp_path: Path, names, seed: int = 1, file: str = "gen.toml") -> Path:
    path = tmp_path / file
    path.write_text(TINY_GEN.format(seed=seed, maneuvers="\n".join(MANEUVER.format(name=n) for n in names)))
    return path


def _one_line(capsys, *fragments) -> str:
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err, err
    for f in fragments:
        assert f in err, (f, err)
    return err


def _tree(root: Path) -> dict:
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


# ============================================================== data never overwritten without being asked
def test_generate_data_refuses_an_existing_flight_test_and_force_leaves_no_orphans(tmp_path, capsys):
    out = tmp_path / "ft"
    old_cfg = _gen_config(tmp_path, ["a_80kt", "b_80kt"], file="old.toml")
    assert main(["generate-data", "--config", str(old_cfg), "--out", str(out)]) == 0
    before = _tree(out)
    assert {"manifest.json", "trims.csv", "truth.json", "maneuvers/a_80kt.csv", "maneuvers/b_80kt.csv"} <= set(before)
    capsys.readouterr()

    new_cfg = _gen_config(tmp_path, ["c_80kt"], seed=2, file="new.toml")
    assert main(["generate-data", "--config", str(new_cfg), "--out", str(out)]) == 2
    _one_line(capsys, str(out), "already holds a flight test", "--force")
    assert _tree(out) == before  # nothing touched

    assert main(["generate-data", "--config", str(new_cfg), "--out", str(out), "--force"]) == 0
    after = _tree(out)
    # exactly the new flight test: the old maneuver files are gone, not orphaned
    assert sorted(after) == ["maneuvers/c_80kt.csv", "manifest.json", "trims.csv", "truth.json"]
    fresh = tmp_path / "fresh"
    assert main(["generate-data", "--config", str(new_cfg), "--out", str(fresh)]) == 0
    assert after == _tree(fresh)  # and byte for byte what a new folder gets
    assert main(["check-data", str(out)]) == 0


def test_generate_data_refuses_a_folder_of_other_files_and_results(tmp_path, capsys):
    cfg = _gen_config(tmp_path, ["a_80kt"])
    other = tmp_path / "notes"
    other.mkdir()
    (other / "mine.txt").write_text("keep me\n")
    assert main(["generate-data", "--config", str(cfg), "--out", str(other)]) == 2
    _one_line(capsys, str(other), "mine.txt", "--force")
    assert sorted(_tree(other)) == ["mine.txt"]
    results = tmp_path / "results"
    results.mkdir()
    (results / "front.csv").write_text("index,kind\n")
    for extra in ([], ["--force"]):  # --force replaces data, never results
        assert main(["generate-data", "--config", str(cfg), "--out", str(results)] + extra) == 2
        _one_line(capsys, str(results), "front.csv")
    assert main(["generate-data", "--config", str(cfg), "--out", str(other), "--force"]) == 0
    assert (other / "mine.txt").read_text() == "keep me\n" and (other / "manifest.json").is_file()


# ============================================================== results and config must agree
TINY_ID = """\
# tiny identification for the results-against-config checks
[data]
dataset = "data"
maneuvers = [{maneuver}]
validation = []
max_duration_s = 2.0
resample_hz = 25
{model}
[parameters.theta_twist]
unit = "deg/m"
initial = -2.1228
lower = -10.0
upper = 0.0
scale = 1.0

[parameters.CL_alpha_HT]
unit = "1/rad"
initial = 4.3516
lower = 0.1
upper = 10.0
scale = 5.0

[pareto]
points = 2
"""


def _id_config(folder: Path, name: str = "tiny.toml", maneuver: str = "lon3211_80kt_a", model: str = "") -> Path:
    path = folder / name
    path.write_text(TINY_ID.format(maneuver=f'"{maneuver}"', model=model))
    return path


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    """A real identification (2 front points, one 2 s record) on a copy of the bundled flight test, with the
    config given by a relative name, as a user in a checkout does; the folder is copied per test."""
    root = tmp_path_factory.mktemp("checkout")
    shutil.copytree(ROOT / "data" / "bo105_synthetic", root / "data")
    _id_config(root)
    import os

    cwd = os.getcwd()
    os.chdir(root)
    try:
        assert main(["identify", "tiny.toml", "--out", "res", "--no-report", "--uncertainty", "none"]) == 0
    finally:
        os.chdir(cwd)
    return root


@pytest.fixture
def checkout(fitted, tmp_path, monkeypatch):
    """A private copy of the fitted checkout (data, config, results), the current folder."""
    root = tmp_path / "checkout"
    shutil.copytree(fitted, root)
    monkeypatch.chdir(root)
    return root


def test_results_record_the_config_by_content_and_the_data_and_model(checkout):
    info = json.loads((checkout / "res" / "chosen.json").read_text())["info"]
    text = (checkout / "tiny.toml").read_text()
    import hashlib

    assert info["config"] == "tiny.toml" and info["config_text"] == text
    assert info["config_sha256"] == hashlib.sha256(text.encode()).hexdigest()
    assert info["maneuvers"] == ["lon3211_80kt_a"]
    assert len(info["dataset_sha256"]) == 64 and len(info["model_fingerprint"]) == 64
    # the folder agrees with its own config: no refusal, no note
    from pyomo_heli.config import load_result_config

    notes = []
    cfg = load_result_config(checkout / "res", warn=notes.append)
    assert [f.name for f in cfg.free] == ["theta_twist", "CL_alpha_HT"] and notes == []
    # only a comment changed: accepted, with a note that the file is not the one recorded
    (checkout / "tiny.toml").write_text(text + "# a comment\n")
    load_result_config(checkout / "res", warn=notes.append)
    assert len(notes) == 1 and "info.config_text" in notes[0]


def test_diagnose_refuses_a_config_name_that_resolves_to_another_maneuver(checkout, tmp_path, capsys):
    """A results folder read from another checkout: its relative config name finds a file fitting another maneuver."""
    other = tmp_path / "other_checkout"
    other.mkdir()
    (other / "data").symlink_to(checkout / "data")
    _id_config(other, maneuver="lon3211_80kt_b")
    shutil.copytree(checkout / "res", other / "res")
    import os

    os.chdir(other)
    assert main(["diagnose", "res", "--out", str(tmp_path / "d")]) == 2
    _one_line(capsys, "res", "lon3211_80kt_a", "lon3211_80kt_b", "info.config_text")
    assert not (tmp_path / "d").exists()


@pytest.mark.parametrize("command", ["diagnose", "uncertainty"])
def test_an_explicit_config_with_other_maneuvers_is_refused(checkout, tmp_path, command, capsys):
    cfg = _id_config(checkout, "other.toml", maneuver="col3211_80kt_a")
    argv = (["diagnose", "res", "--config", str(cfg), "--out", str(tmp_path / "o")] if command == "diagnose" else
            ["uncertainty", str(cfg), "--results", "res", "--out", str(tmp_path / "o"), "--points", "chosen"])
    assert main(argv) == 2
    _one_line(capsys, "lon3211_80kt_a", "col3211_80kt_a", "other.toml")
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("command", ["diagnose", "uncertainty"])
def test_edited_data_is_refused(checkout, tmp_path, command, capsys):
    """The same config on data edited since the fit (one sample of the fitted record)."""
    f = checkout / "data" / "maneuvers" / "lon3211_80kt_a.csv"
    lines = f.read_text().splitlines(keepends=True)
    lines[5] = lines[5].replace(",", ",1", 1)  # col_deg of the 5th sample gains a leading 1 (still plausible)
    f.write_text("".join(lines))
    assert main(["check-data", "data"]) == 0  # valid data, only not the data of the fit
    capsys.readouterr()
    argv = (["diagnose", "res", "--out", str(tmp_path / "o")] if command == "diagnose" else
            ["uncertainty", "tiny.toml", "--results", "res", "--out", str(tmp_path / "o"), "--points", "chosen"])
    assert main(argv) == 2
    _one_line(capsys, "dataset", "content", "res")


def test_another_model_is_refused(checkout, tmp_path, capsys):
    cfg = _id_config(checkout, "heavier.toml", model="[model]\nparameters = { Iyy = 5500.0 }\n")
    assert main(["diagnose", "res", "--config", str(cfg), "--out", str(tmp_path / "o")]) == 2
    _one_line(capsys, "model differs", "Iyy", "5500")


def test_another_noise_model_or_discretisation_is_refused(checkout, tmp_path, capsys):
    """The standard errors rest on the noise model and the discretisation: a config that differs there only (three
    collocation points instead of two) is refused by uncertainty and diagnose, naming the setting."""
    info = json.loads((checkout / "res" / "chosen.json").read_text())["info"]
    assert info["noise_model"]["ncp"] == 2 and info["noise_model"]["noise_sigma"] is None
    cfg = _id_config(checkout, "ncp3.toml", model="[discretization]\nncp = 3\n")
    assert main(["uncertainty", str(cfg), "--results", "res", "--points", "chosen"]) == 2
    _one_line(capsys, "noise model differs", "ncp (results 2, config 3)")
    assert main(["diagnose", "res", "--config", str(cfg), "--out", str(tmp_path / "o")]) == 2
    _one_line(capsys, "noise model differs", "ncp")


def test_an_extra_parameter_in_chosen_json_is_refused(checkout, tmp_path, capsys):
    path = checkout / "res" / "chosen.json"
    doc = json.loads(path.read_text())
    doc["chosen"]["parameters"]["Iyy"] = 6000.0  # applied to the model, it would change the diagnosis silently
    path.write_text(json.dumps(doc))
    assert main(["diagnose", "res", "--out", str(tmp_path / "o")]) == 2
    _one_line(capsys, "chosen.json", "chosen.parameters", "Iyy")


def test_a_folder_without_the_records_is_checked_for_what_it_has(checkout):
    """Folders written before the records existed (docs/results): maneuvers and free parameters still checked, the
    rest named as not checked."""
    from pyomo_heli.config import load_result_config
    from pyomo_heli.provenance import ResultsMismatchError

    path = checkout / "res" / "chosen.json"
    doc = json.loads(path.read_text())
    for k in ("dataset_sha256", "model", "model_fingerprint", "config_sha256", "config_text"):
        del doc["info"][k]
    path.write_text(json.dumps(doc))
    notes = []
    load_result_config(checkout / "res", warn=notes.append)
    assert len(notes) == 1 and "no dataset content, no model" in notes[0] and "not checked" in notes[0]
    other = _id_config(checkout, "other.toml", maneuver="col3211_80kt_a")
    with pytest.raises(ResultsMismatchError, match="col3211_80kt_a"):
        load_result_config(checkout / "res", other, warn=notes.append)


def test_close_loop_does_not_reuse_an_iteration_fitted_to_other_data(checkout):
    """A finished identification without checkpoint.json (a copy, as under docs/results) on edited data is
    identified again, not reused."""
    from pyomo_heli.workflows.close_loop import _finished
    from pyomo_heli.config import load_identification_config

    (checkout / "res" / "checkpoint.json").unlink()
    cfg = load_identification_config("tiny.toml")
    path = checkout / "res" / "chosen.json"  # as if identified in this copy (the loop compares the data's path)
    doc = json.loads(path.read_text())
    doc["info"]["dataset"] = str(cfg.dataset)
    path.write_text(json.dumps(doc))
    assert _finished(cfg, checkout / "res") is not None  # same data: reused
    lines = (checkout / "data" / "maneuvers" / "lon3211_80kt_a.csv").read_text().splitlines(keepends=True)
    lines[5] = lines[5].replace(",", ",1", 1)
    (checkout / "data" / "maneuvers" / "lon3211_80kt_a.csv").write_text("".join(lines))
    assert _finished(cfg, checkout / "res") is None


# ============================================================== plausibility checks, one line each
SMALL = ROOT / "tests" / "data" / "m0_noise_small"
LON = "maneuvers/lon3211_80kt.csv"


@pytest.fixture
def small(tmp_path):
    return Path(shutil.copytree(SMALL, tmp_path / "ds"))


def _check_data_line(ds, capsys, *fragments) -> str:
    assert main(["check-data", str(ds)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    for f in fragments:
        assert f in err[0], (f, err[0])
    return err[0]


@pytest.mark.parametrize("sep, word", [(";", "semicolons"), ("\t", "tabs")])
@pytest.mark.parametrize("file", [LON, "trims.csv"])
def test_a_separator_other_than_comma_is_named(small, capsys, sep, word, file):
    p = small / file
    p.write_text(p.read_text().replace(",", sep))
    _check_data_line(small, capsys, file, word, "not commas")


def _edit_time(ds, f):
    import pandas as pd

    d = pd.read_csv(ds / LON)
    d["t_s"] = f(d["t_s"])
    d.to_csv(ds / LON, index=False, float_format="%.10g")


@pytest.mark.parametrize("factor, rate", [(1000.0, "0.05 Hz"), (1e300, "5e-299 Hz"), (1e-4, "500000 Hz")])
def test_a_sample_rate_outside_1_to_10000_hz_is_refused(small, capsys, factor, rate):
    """Time in ms, time stamps 1e300 s apart, time in units of 0.1 ms: the data's 50 Hz become implausible."""
    _edit_time(small, lambda t: t * factor)
    _check_data_line(small, capsys, LON, "sample rate " + rate, "1..10,000 Hz")


def test_a_declared_input_that_never_moves_is_refused(small, capsys):
    import pandas as pd

    from pyomo_heli.dataset import DatasetError, load_flight_test

    d = pd.read_csv(small / LON)
    d["lon_deg"] = d["lon_deg"].iloc[0]  # the 3211 was never flown: the stick held at trim
    d.to_csv(small / LON, index=False, float_format="%.10g")
    _check_data_line(small, capsys, "maneuvers[0].inputs", "'lon_deg'", "never moves")
    with pytest.raises(DatasetError, match="never moves"):  # loading refuses it too
        load_flight_test(small)


def test_a_bom_in_a_config_is_named(tmp_path, capsys):
    text = (CONFIGS / "m0_noise_small.toml").read_text().replace('"../data/', f'"{ROOT / "tests" / "data"}/')
    cfg = tmp_path / "bom.toml"
    cfg.write_bytes(b"\xef\xbb\xbf" + text.encode())
    assert main(["inspect", str(cfg), "--no-diagnostics"]) == 2
    _one_line(capsys, str(cfg), "byte-order mark", "BOM")
    gen = tmp_path / "gen_bom.toml"
    gen.write_bytes(b"\xef\xbb\xbf" + _gen_config(tmp_path, ["a_80kt"]).read_bytes())
    assert main(["generate-data", "--config", str(gen), "--out", str(tmp_path / "ft")]) == 2
    _one_line(capsys, str(gen), "BOM")


def _small_config(tmp_path, data: str = "", tol: str = "1e-8") -> Path:
    text = (CONFIGS / "m0_noise_small.toml").read_text().replace('"../data/', f'"{ROOT / "tests" / "data"}/')
    assert "tol = 1e-8," in text
    text = text.replace("[data]\n", "[data]\n" + data, 1).replace("tol = 1e-8,", f"tol = {tol},")
    path = tmp_path / "small.toml"
    path.write_text(text)
    return path


def test_a_record_listed_for_fitting_and_validation_is_refused(tmp_path, capsys):
    cfg = _small_config(tmp_path, 'maneuvers = ["lon3211_80kt", "londoublet_20kt"]\n'
                                  'validation = ["londoublet_80kt_val", "londoublet_20kt"]\n')
    assert main(["identify", str(cfg), "--out", str(tmp_path / "r")]) == 2
    _one_line(capsys, str(cfg), "londoublet_20kt", "both", "'validation'")
    assert not (tmp_path / "r").exists()


def test_a_record_used_for_fitting_and_validation_by_role_is_refused(tmp_path):
    """Fitted by its role in the manifest, validation by name (and the converse)."""
    from pyomo_heli.config import load_identification_config
    from pyomo_heli.nlp.identification import identification_data

    for data in ('validation = ["coldoublet_hover"]\n', 'maneuvers = ["lon3211_80kt", "londoublet_80kt_val"]\n'):
        cfg = load_identification_config(_small_config(tmp_path, data))
        with pytest.raises(ValueError, match=r"small.toml \[data\]: maneuver\(s\) "
                                             r"(coldoublet_hover|londoublet_80kt_val) both fitted"):
            identification_data(cfg)


@pytest.mark.parametrize("tol", ["1e300", "0.5", "1e-20"])
def test_a_solver_tolerance_outside_a_sane_range_is_refused(tmp_path, capsys, tol):
    cfg = _small_config(tmp_path, tol=tol)
    assert main(["identify", str(cfg), "--out", str(tmp_path / "r")]) == 2
    _one_line(capsys, str(cfg), "[solver]", "'tol'", "sane range")
    assert not (tmp_path / "r").exists()


# ============================================================== results never written among someone else's files
@pytest.mark.parametrize("command", ["identify", "multistart", "close-loop"])
def test_a_run_refuses_an_out_holding_a_flight_test_or_other_files(tmp_path, capsys, command):
    cfg = _small_config(tmp_path)
    data = Path(shutil.copytree(SMALL, tmp_path / "data"))
    before = _tree(data)
    extra = ["--starts", "1"] if command == "multistart" else []
    assert main([command, str(cfg), "--out", str(data)] + extra) == 2
    _one_line(capsys, str(data), "flight-test folder")
    assert _tree(data) == before
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "thesis.tex").write_text("x")
    assert main([command, str(cfg), "--out", str(mine)] + extra) == 2
    _one_line(capsys, str(mine), "thesis.tex", "not results of pyomo-heli")
    assert sorted(_tree(mine)) == ["thesis.tex"]


def test_diagnose_and_uncertainty_out_refuse_other_results_and_files(checkout, tmp_path, capsys):
    other = tmp_path / "other_results"
    shutil.copytree(checkout / "res", other)
    doc = json.loads((other / "time_domain.json").read_text())
    doc["J_time"] += 1.0  # another run
    (other / "time_domain.json").write_text(json.dumps(doc))
    before = _tree(other)
    assert main(["diagnose", "res", "--out", str(other)]) == 2
    _one_line(capsys, str(other), "another results folder")
    assert main(["uncertainty", "tiny.toml", "--results", "res", "--out", str(other), "--points", "chosen"]) == 2
    _one_line(capsys, str(other), "other results", "not a copy of res")
    assert _tree(other) == before
    notes = tmp_path / "notes"
    notes.mkdir()
    (notes / "a.txt").write_text("x")
    for argv in (["diagnose", "res", "--out", str(notes)],
                 ["uncertainty", "tiny.toml", "--results", "res", "--out", str(notes), "--points", "chosen"]):
        assert main(argv) == 2
        _one_line(capsys, str(notes), "a.txt")
    assert sorted(_tree(notes)) == ["a.txt"]


def test_reruns_into_their_own_output_are_accepted(checkout, tmp_path):
    """What the refusals must not catch: an earlier copy of the same results (uncertainty --out), a folder holding
    a diagnosis (diagnose --out), a run's own results folder."""
    from pyomo_heli.cli import _check_copy_out, _check_diagnosis_out, _check_out_not_foreign

    shutil.copytree(checkout / "res", tmp_path / "copy")
    _check_copy_out(tmp_path / "copy", "res")
    (tmp_path / "diag").mkdir()
    (tmp_path / "diag" / "diagnosis.json").write_text("{}")
    (tmp_path / "diag" / "diagnosis.md").write_text("")
    _check_diagnosis_out(tmp_path / "diag", "res")
    _check_diagnosis_out("res", "res")
    _check_out_not_foreign("res", "identification")
