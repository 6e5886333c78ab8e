"""The dataset's consistency checks (pyomo_heli.dataset.reader): inconsistencies that used to pass silently or
with a misleading message.

1. trims.csv: a maneuver's start trim (``source`` = maneuver name) must be at that maneuver's manifest
   ``trim_speed_kt`` (within the manifest-vs-airspeed tolerance max(5 kt, 20 %), not below 15 kt);
2. trims.csv: the flight-path angle must be plausible (|gamma_fp| <= 30 deg);
3. manifest ``inputs`` must not be contradicted by the record (an undeclared input channel moving more
   than twice as much as a declared one, noise excluded);
4. a duplicated or malformed maneuver name is reported alone (no follow-up error on trims.csv 'source');
5. a trim that fails says what failed (the residual), not the root finder's "The solution converged.";
6. ``report-linear`` on a corrupted, bi-objective or mismatched results folder: one line naming the file
   and column/key (or the config and the folder), exit 2, no traceback, nothing written.

Every test works on copies in tmp_path; the whole file runs in a few seconds.
"""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pyomo_heli.cli import main
from pyomo_heli.dataset import DatasetError, load_flight_test, validate_flight_test
from pyomo_heli.dataset.cli import check_data
from pyomo_heli.dataset.schema import GAMMA_FP_LIMIT_DEG, INPUT_DOMINANCE
from pyomo_heli.physics.model import HelicopterModel
from pyomo_heli.simulation.trim import TrimError, trim_float

ROOT = Path(__file__).resolve().parents[1]
BUNDLED = ROOT / "data" / "bo105_synthetic"
CLEAN = ROOT / "data" / "bo105_clean"
TRI_RESULTS = ROOT / "tests" / "results" / "case1_tri"  # a copy of the committed Case 1 tri-objective run
TRI_CONFIG = ROOT / "tests" / "configs" / "case1_tri.toml"
BI_RESULTS = ROOT / "tests" / "results" / "case1"
BI_CONFIG = ROOT / "tests" / "configs" / "case1.toml"
LON = "maneuvers/lon3211_80kt_a.csv"
TRIMS = "trims.csv"
KT = 1852.0 / 3600.0


@pytest.fixture(scope="module")
def bundled_cut(tmp_path_factory) -> Path:
    """The bundled synthetic dataset cut to its identification maneuvers (the first ten; every trim row is level or
    taken from one of them): the same manifest indices and trim rows, read in a fifth of the time (CI time: the
    validation and frequency records are 80 % of the bytes)."""
    root = tmp_path_factory.mktemp("bundled_cut") / "ds"
    (root / "maneuvers").mkdir(parents=True)
    man = json.loads((BUNDLED / "manifest.json").read_text())
    man["maneuvers"] = [m for m in man["maneuvers"] if m["role"] == "identification"]
    (root / "manifest.json").write_text(json.dumps(man, indent=2))
    for name in ("trims.csv", "truth.json", *(m["file"] for m in man["maneuvers"])):
        shutil.copy(BUNDLED / name, root / name)
    assert not validate_flight_test(root)
    return root


@pytest.fixture
def ds(tmp_path, bundled_cut) -> Path:
    """A fresh copy of the cut bundled dataset."""
    return Path(shutil.copytree(bundled_cut, tmp_path / "ds"))


def _edit_manifest(folder: Path, fn) -> None:
    p = folder / "manifest.json"
    m = json.loads(p.read_text())
    fn(m)
    p.write_text(json.dumps(m, indent=2))


def _edit_trims(folder: Path, fn) -> None:
    p = folder / TRIMS
    df = pd.read_csv(p, dtype={"source": str})
    new = fn(df)
    (df if new is None else new).to_csv(p, index=False)


def _source_row(folder: Path, name: str) -> int:
    """0-based data row of the trim whose source is ``name``."""
    df = pd.read_csv(folder / TRIMS)
    return int(np.flatnonzero(df["source"] == name)[0])


def _check(folder: Path, capsys) -> list[str]:
    """check-data's error lines (asserting exit code 2 and no stdout summary)."""
    rc = check_data(str(folder))
    cap = capsys.readouterr()
    assert rc == 2 and cap.out == ""
    lines = cap.err.strip().splitlines()
    assert lines and all(ln.startswith("error: ") for ln in lines)
    with pytest.raises(DatasetError):
        load_flight_test(folder)
    return lines


def test_bundled_datasets_stay_valid():
    assert validate_flight_test(BUNDLED) == []
    assert validate_flight_test(CLEAN) == []


# ============================================================== 1. start trim at its maneuver's speed
def test_start_trim_at_another_speed_is_named(ds, capsys):
    i = _source_row(ds, "lon3211_80kt_a")
    _edit_trims(ds, lambda d: d.__setitem__("speed_kt", d["speed_kt"].where(d.index != i, 20.0)))
    lines = _check(ds, capsys)
    assert len(lines) == 1, lines
    line = lines[0]
    assert line.startswith("error: trims.csv: column 'speed_kt': ")
    assert f"row {i + 1} (20 kt; source 'lon3211_80kt_a' has 80 kt, tolerance 16 kt)" in line


@pytest.mark.parametrize("name, speed, ok", [
    ("col3211_80kt_b", 95.9, True), ("col3211_80kt_b", 64.1, True), ("col3211_80kt_b", 96.1, False),
    ("col3211_80kt_b", 0.0, False), ("coldoublet_20kt", 24.9, True), ("coldoublet_20kt", 25.1, False),
    ("coldoublet_hover", 14.0, True), ("coldoublet_hover", 15.0, False)])
def test_start_trim_speed_tolerance(ds, name, speed, ok):
    """max(5 kt, 20 % of trim_speed_kt), as between the manifest and the record's airspeed; not below 15 kt."""
    i = _source_row(ds, name)
    _edit_trims(ds, lambda d: d.__setitem__("speed_kt", d["speed_kt"].where(d.index != i, speed)))
    fields = [(p.file, p.field) for p in validate_flight_test(ds)]
    assert fields == ([] if ok else [("trims.csv", "speed_kt")])


def test_trim_speed_disputed_by_the_record_is_reported_once(ds):
    """trim_speed_kt 120 for an 80 kt record and its 80 kt start trim: the manifest field is named, once."""
    _edit_manifest(ds, lambda m: m["maneuvers"][0].update(trim_speed_kt=120.0))
    assert [(p.file, p.field) for p in validate_flight_test(ds)] == [("manifest.json", "maneuvers[0].trim_speed_kt")]


@pytest.mark.parametrize("speed", [8.0, 0.0])
def test_a_trim_speed_below_the_pitot_range_for_a_record_above_it_is_named(ds, speed):
    """trim_speed_kt 8 (or 0) for an 80 kt record: the record's start speed is one the pitot reads, so the two are
    compared although the manifest's is below 15 kt (before, only a manifest speed of 15 kt or more was)."""
    _edit_manifest(ds, lambda m: m["maneuvers"][0].update(trim_speed_kt=speed))
    problems = validate_flight_test(ds)
    assert [(p.file, p.field) for p in problems] == [("manifest.json", "maneuvers[0].trim_speed_kt")]
    assert "disagrees with the start of column 'tas_kt'" in problems[0].message


@pytest.mark.parametrize("column, factor, field", [
    ("t_s", 1 / 60, "q_deg_s"),                 # time in minutes: theta moves 60 times the integral of q
    ("q_deg_s", 1 / 57.29577951308232, "q_deg_s"),  # rad/s under a deg/s name: 57.3 times
    ("q_deg_s", -1.0, "q_deg_s"),               # q of the other sign: -1 times
    ("nz_g", -1.0, "nz_g")])                    # n_z positive down: about -1 g at a trim
def test_a_unit_or_sign_the_limits_cannot_see_is_named_by_kinematics(ds, column, factor, field):
    """The plausible limits pass each of these; the pitch attitude against the time integral of q (slope 1.04 on
    this record, a least-squares fit of theta - theta(t0)) and n_z at the record's start (+1 g) name the column,
    with the slope or start value that gives it away."""
    import re

    path = ds / LON
    df = pd.read_csv(path)
    df[column] = df[column] * factor
    df.to_csv(path, index=False)
    problems = validate_flight_test(ds)
    assert [(p.file, p.field) for p in problems] == [(LON, field)], problems
    msg = problems[0].message
    if column == "nz_g":
        assert msg.startswith("starts at -1 g (mean over the first 1 s)"), msg
    else:
        slope = float(re.search(r"moves (\S+) times the time integral", msg).group(1))
        assert slope * factor == pytest.approx(1.04, abs=0.02), msg


@pytest.mark.parametrize("name, words", [("trims\x00.csv", "(embedded null byte)"),
                                         ("a" * 3000 + ".csv", "(File name too long)")])
def test_a_path_the_file_system_cannot_take_is_a_problem_of_the_manifest(ds, capsys, name, words):
    """A NUL byte or a 3000-character name in trim_file: one line naming the manifest's field (before, the reader
    raised, and check-data printed the exception as if the data could not be checked)."""
    _edit_manifest(ds, lambda m: m.update(trim_file=name))
    line, = _check(ds, capsys)
    assert line.startswith("error: manifest.json: field 'trim_file': path ") and line.endswith(
        f"cannot be used as a file name {words}"), line[-200:]


def test_a_bug_of_the_reader_is_an_internal_error_not_a_problem_of_the_data(ds, capsys, monkeypatch):
    """An exception inside the reader is reported by check-data as an internal error (exit 1), never as bad data
    (exit 2, 'error: ...')."""
    from pyomo_heli.dataset import reader

    def broken(self, *a, **k):
        raise ZeroDivisionError("a bug")

    monkeypatch.setattr(reader._Reader, "check_kinematics", broken)
    assert main(["check-data", str(ds)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("pyomo-heli check-data: internal error: ZeroDivisionError: a bug"), err


def test_start_trim_of_a_maneuver_with_a_bad_trim_speed_reports_the_manifest_only(ds):
    _edit_manifest(ds, lambda m: m["maneuvers"][0].update(trim_speed_kt="80"))
    assert [(p.file, p.field) for p in validate_flight_test(ds)] == [("manifest.json", "maneuvers[0].trim_speed_kt")]


def test_level_rows_may_be_at_any_speed(ds):
    _edit_trims(ds, lambda d: d.__setitem__("speed_kt", d["speed_kt"].where(d["source"] != "level", 33.0)))
    assert validate_flight_test(ds) == []


# ============================================================== 2. flight-path angle range
@pytest.mark.parametrize("column, value, ok", [
    ("gamma_fp_deg", 90.0, False), ("gamma_fp_deg", 60.0, False), ("gamma_fp_deg", -31.0, False),
    ("gamma_fp_deg", GAMMA_FP_LIMIT_DEG, True), ("gamma_fp_deg", -12.0, True),
    ("gamma_fp_rad", 0.2, True), ("gamma_fp_rad", 1.0, False), ("gamma_fp_rad", 10.0, False)])
def test_flight_path_angle_range(ds, capsys, column, value, ok):
    def edit(d):
        d = d.rename(columns={"gamma_fp_deg": column}).astype({column: float})
        d.loc[3, column] = value
        return d

    _edit_trims(ds, edit)
    if ok:
        assert validate_flight_test(ds) == []
        return
    lines = _check(ds, capsys)
    assert len(lines) == 1, lines
    assert lines[0].startswith(f"error: trims.csv: column '{column}': 1 value beyond the plausible limit 30 deg")
    assert "row 4" in lines[0] and "vertical climb" in lines[0]
    assert ("the column would be 'gamma_fp_deg'" in lines[0]) == (column == "gamma_fp_rad")  # degrees-in-rad hint


def test_bundled_trims_are_level():
    """The identification trims the model in level flight (gamma_fp is used by diagnose only): the bundled
    data have only gamma_fp = 0."""
    for folder in (BUNDLED, CLEAN):
        assert (load_flight_test(folder).trims["gamma_fp"] == 0).all()


# ============================================================== 3. declared inputs against the record
def test_declared_input_that_does_not_move_is_named(ds, capsys):
    _edit_manifest(ds, lambda m: m["maneuvers"][0].update(inputs=["col"]))
    lines = _check(ds, capsys)
    assert len(lines) == 1, lines
    line = lines[0]
    assert line.startswith("error: manifest.json: field 'maneuvers[0].inputs': ['col'], but in "
                           f"{LON} the undeclared input column 'lon_deg' moves ")
    assert "as much as the declared 'col_deg'" in line and "noise" in line


def test_declared_input_on_noise_free_data(tmp_path):
    ds = Path(shutil.copytree(CLEAN, tmp_path / "clean"))
    _edit_manifest(ds, lambda m: m["maneuvers"][2].update(inputs=["lon"]))  # col3211_80kt_a
    probs = validate_flight_test(ds)
    assert [(p.file, p.field) for p in probs] == [("manifest.json", "maneuvers[2].inputs")]
    assert "'col_deg' moves (std over the record 0.349 deg) while the declared 'lon_deg' is constant" in str(probs[0])


def test_both_inputs_declared_is_accepted(ds):
    _edit_manifest(ds, lambda m: m["maneuvers"][0].update(inputs=["col", "lon"]))
    assert validate_flight_test(ds) == []


def test_noise_only_record_is_named(ds, capsys):
    """A record whose declared channel holds only noise, like the undeclared one: it excites nothing it declares
    (issue 32: a declared input that never moves; no undeclared channel is blamed)."""
    p = ds / LON
    d = pd.read_csv(p)
    d["lon_deg"] = d["lon_deg"].iloc[0] + (d["col_deg"] - d["col_deg"].mean()).to_numpy()[::-1]
    d.to_csv(p, index=False)
    lines = _check(ds, capsys)
    assert len(lines) == 1, lines
    assert lines[0].startswith(f"error: manifest.json: field 'maneuvers[0].inputs': ['lon'], but in {LON} the "
                               f"declared input column 'lon_deg' (std over the record ")
    assert "never moves beyond noise" in lines[0] and "col_deg" not in lines[0]


def test_off_axis_movement_below_the_dominance_ratio_is_accepted(ds):
    """An undeclared channel moving, but less than INPUT_DOMINANCE x the declared one, is accepted."""
    p = ds / LON
    d = pd.read_csv(p)
    lon = d["lon_deg"] - d["lon_deg"].iloc[0]
    d["col_deg"] = d["col_deg"] + 0.8 * INPUT_DOMINANCE * lon  # std 1.6 x the declared one
    d.to_csv(p, index=False)
    assert validate_flight_test(ds) == []
    d["col_deg"] = d["col_deg"] + 1.0 * INPUT_DOMINANCE * lon  # now 3.6 x
    d.to_csv(p, index=False)
    assert [p.field for p in validate_flight_test(ds)] == ["maneuvers[0].inputs"]


# ============================================================== 4. one problem, not its echo
def test_duplicate_maneuver_name_is_reported_alone(ds, capsys):
    _edit_manifest(ds, lambda m: m["maneuvers"][1].update(name=m["maneuvers"][0]["name"]))
    lines = _check(ds, capsys)
    assert lines == ["error: manifest.json: field 'maneuvers[1].name': duplicate maneuver name 'lon3211_80kt_a' "
                     "(also maneuvers[0].name)"]


def test_malformed_maneuver_name_is_reported_alone(ds):
    _edit_manifest(ds, lambda m: m["maneuvers"][4].update(name="londoublet 20kt"))
    assert [(p.file, p.field) for p in validate_flight_test(ds)] == [("manifest.json", "maneuvers[4].name")]


def test_source_typo_still_named_when_the_names_are_sound(ds):
    i = _source_row(ds, "coldoublet_hover")
    _edit_trims(ds, lambda d: d.__setitem__("source", d["source"].where(d.index != i, "coldoublet_hovr")))
    probs = validate_flight_test(ds)
    assert [(p.file, p.field) for p in probs] == [("trims.csv", "source")]
    assert "'coldoublet_hovr'" in str(probs[0])


# ============================================================== 5. trim failure message
def test_trim_failure_names_the_residual_not_a_converged_status():
    model = HelicopterModel().with_parameters(Iyy=1e-9)
    with pytest.raises(TrimError) as exc:
        trim_float(model, 80 * KT)
    msg = str(exc.value)
    assert "did not converge: The solution converged" not in msg
    assert msg.startswith("trim at V = 41.156 m/s failed: the trim equations are not satisfied")
    assert "largest residual 10 dq/dt = " in msg and "\n" not in msg


def test_linearize_command_with_an_unbalanceable_model(capsys):
    assert main(["linearize", "--speeds-kt", "80", "--param", "Iyy=1e-9"]) == 2
    cap = capsys.readouterr()
    err = cap.err.strip()
    assert err.startswith("pyomo-heli linearize: error: trim at V = 41.156 m/s failed") and "\n" not in err
    assert "Traceback" not in err and "dq/dt" in err


# ============================================================== 6. report-linear on bad folders
@pytest.fixture
def tri(tmp_path) -> Path:
    return Path(shutil.copytree(TRI_RESULTS, tmp_path / "tri",
                                ignore=shutil.ignore_patterns("*.png", "report_linear.md", "band_errors.csv",
                                                              "parameters_tri.csv")))


def _csv_cell(path: Path, row: int, column: str, text: str) -> None:
    lines = path.read_text().split("\n")
    j = lines[0].split(",").index(column)
    cells = lines[row].split(",")
    cells[j] = text
    lines[row] = ",".join(cells)
    path.write_text("\n".join(lines))


def _report_error(folder: Path, capsys, config: Path = TRI_CONFIG) -> str:
    before = sorted(q.name for q in folder.iterdir()) if folder.is_dir() else None
    rc = main(["report-linear", str(config), "--out", str(folder)])
    cap = capsys.readouterr()
    assert rc == 2, cap
    err = cap.err.strip()
    assert err.startswith("pyomo-heli report-linear: error: ") and "\n" not in err and "Traceback" not in err
    if before is not None:
        assert sorted(q.name for q in folder.iterdir()) == before  # no report written
    return err


def _drop_column(path: Path, column: str) -> None:
    pd.read_csv(path).drop(columns=[column]).to_csv(path, index=False)


FR = "frequency_responses.csv"
CASES = [
    ("non-numeric-coherence", lambda f: _csv_cell(f / FR, 7, "coherence", "abc"),
     [FR, "column 'coherence'", "non-numeric", "row 7 ('abc')"]),
    ("non-numeric-T", lambda f: _csv_cell(f / FR, 3, "T_re", "x1"), [FR, "column 'T_re'", "row 3 ('x1')"]),
    ("empty-omega", lambda f: _csv_cell(f / FR, 3, "omega", ""), [FR, "column 'omega'", "empty or non-finite"]),
    ("missing-column", lambda f: _drop_column(f / FR, "input"), [FR, "column 'input' missing"]),
    ("empty-file", lambda f: (f / FR).write_text(""), [FR, "empty file"]),
    ("header-only", lambda f: (f / FR).write_text((f / FR).read_text().split("\n")[0] + "\n"),
     [FR, "no data rows (header only)"]),
    ("no-file", lambda f: (f / FR).unlink(), [FR, "file not found"]),
    ("coherent-not-bool", lambda f: _csv_cell(f / FR, 2, "coherent", "perhaps"),
     [FR, "column 'coherent'", "'perhaps'"]),
    ("unknown-output", lambda f: _csv_cell(f / FR, 2, "output", "r"), [FR, "column 'output'", "not a model output"]),
    ("negative-speed", lambda f: _csv_cell(f / FR, 2, "speed", "-3"), [FR, "column 'speed'", "negative"]),
    ("front-header-only", lambda f: (f / "front.csv").write_text((f / "front.csv").read_text().split("\n")[0] + "\n"),
     ["front.csv", "no data rows (header only)"]),
    ("front-success-maybe", lambda f: _csv_cell(f / "front.csv", 2, "success", "maybe"),
     ["front.csv", "column 'success'", "neither True nor False", "row 2 ('maybe')"]),
    ("front-J_linear-text", lambda f: _csv_cell(f / "front.csv", 2, "J_linear", "oops"),
     ["front.csv", "column 'J_linear'", "non-numeric"]),
    ("front-no-J_linear", lambda f: _drop_column(f / "front.csv", "J_linear"),
     ["front.csv", "column 'J_linear' missing"]),
    ("chosen-no-bi-objective", lambda f: _edit_chosen(f, lambda c: c["info"].pop("bi_objective")),
     ["chosen.json", "info.bi_objective.chosen"]),
    ("chosen-null", lambda f: _edit_chosen(f, lambda c: c.update(chosen=None)),
     ["chosen.json", "key 'chosen' is null"]),
    ("chosen-no-J_linear", lambda f: _edit_chosen(f, lambda c: c["chosen"].pop("J_linear")),
     ["chosen.json", "key 'chosen.J_linear'"]),
]


def _edit_chosen(folder: Path, fn) -> None:
    p = folder / "chosen.json"
    c = json.loads(p.read_text())
    fn(c)
    p.write_text(json.dumps(c))


@pytest.mark.parametrize("mutate, needles", [pytest.param(m, n, id=i) for i, m, n in CASES])
def test_report_linear_on_a_corrupted_folder(tri, capsys, mutate, needles):
    mutate(tri)
    err = _report_error(tri, capsys)
    assert all(n in err for n in needles), err


def test_report_linear_on_a_bi_objective_folder(tmp_path, capsys):
    bi = Path(shutil.copytree(BI_RESULTS, tmp_path / "bi", ignore=shutil.ignore_patterns("*.png", "*.md")))
    err = _report_error(bi, capsys)
    assert "not a tri-objective results folder" in err and "chosen.json key 'info.objectives'" in err


def test_report_linear_with_a_bi_objective_config(tri, capsys):
    err = _report_error(tri, capsys, BI_CONFIG)
    assert f"config {BI_CONFIG}" in err and "not tri-objective" in err and str(tri) in err


def test_report_linear_with_other_free_parameters(tri, capsys, tmp_path):
    cfg = tmp_path / "other.toml"
    text = TRI_CONFIG.read_text().replace('dataset = "../../data/bo105_synthetic"', f'dataset = "{BUNDLED}"')
    cfg.write_text(text.replace("[parameters.CL_alpha_HT]", "[parameters.Iyy]\n# was CL_alpha_HT", 1)
                   .replace('unit = "1/rad"\ninitial = 4.3516\nlower = 0.1\nupper = 10.0\nscale = 5.0',
                            "unit = \"kg m^2\"\ninitial = 4000.0\nlower = 1000.0\nupper = 9000.0\nscale = 1000.0", 1))
    err = _report_error(tri, capsys, cfg)
    assert "frees theta_twist, Iyy" in err and "holds theta_twist, CL_alpha_HT" in err


def test_report_linear_still_reports_the_committed_folder(tri, capsys):
    assert main(["report-linear", str(TRI_CONFIG), "--out", str(tri)]) == 0
    assert (tri / "report_linear.md").is_file() and (tri / "bode.png").is_file()
    assert pd.read_csv(tri / "band_errors.csv").equals(pd.read_csv(TRI_RESULTS / "band_errors.csv"))
