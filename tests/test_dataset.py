"""Tests of the flight-test dataset format (pyomo_heli.dataset): writer, loader, validator, check-data.

The valid dataset is produced by the pandas-only example tests/data/example_dataset.py (the example
docs/data_format.md points to); every malformed case is a small mutation of it.
"""
from __future__ import annotations

import builtins
import io
import json
import math
import os
import pathlib
import shutil

import numpy as np
import pandas as pd
import pytest

from pyomo_heli.dataset import (
    DatasetError,
    FlightTest,
    Maneuver,
    Problem,
    load_flight_test,
    validate_flight_test,
    write_flight_test,
)
from pyomo_heli.dataset.cli import check_data

EXAMPLE = pathlib.Path(__file__).resolve().parent / "data" / "example_dataset.py"
KT = 1852.0 / 3600.0
DEG = math.pi / 180.0
LON = "maneuvers/lon3211_80kt.csv"
HOV = "maneuvers/col_doublet_hover.csv"
VAL = "maneuvers/lon_doublet_80kt.csv"
TRIMS = "trims.csv"
NAMES = ["lon3211_80kt", "col_doublet_hover", "lon_doublet_80kt"]


@pytest.fixture(scope="session")
def example_src(tmp_path_factory) -> pathlib.Path:
    """Run the documentation's pandas-only example (tests/data/example_dataset.py) once; it writes ./bo105_example."""
    where = tmp_path_factory.mktemp("doc_example")
    old = os.getcwd()
    os.chdir(where)
    try:
        exec(compile(EXAMPLE.read_text(), str(EXAMPLE), "exec"), {"__name__": "doc_example"})
    finally:
        os.chdir(old)
    return where / "bo105_example"


@pytest.fixture
def ds(example_src, tmp_path) -> pathlib.Path:
    """A fresh copy of the valid example dataset."""
    return pathlib.Path(shutil.copytree(example_src, tmp_path / "bo105_example"))


# ---------------------------------------------------------------- the valid dataset
def test_doc_example_is_valid_and_loads(ds):
    assert validate_flight_test(ds) == []
    ft = load_flight_test(ds)
    assert isinstance(ft, FlightTest)
    assert ft.path == ds
    assert ft.aircraft == "Bo-105 (synthetic)"
    assert (ft.mass, ft.rho, ft.g) == (2200.0, 1.225, 9.80665)
    assert list(ft.maneuvers) == NAMES  # manifest order kept
    assert [m.name for m in ft.identification()] == NAMES[:2]
    assert [m.name for m in ft.validation()] == NAMES[2:]
    for m in ft.maneuvers.values():
        assert isinstance(m, Maneuver)
        assert m.n_samples == 301
        assert m.duration == pytest.approx(6.0)
        assert m.sample_rate == pytest.approx(50.0)


def test_si_conversion_against_hand_values(ds):
    ft = load_flight_test(ds)
    lon = ft.maneuvers["lon3211_80kt"]
    assert list(lon.data.columns) == ["t", "col", "lon", "q", "theta", "n_x", "n_z", "TAS"]
    assert lon.role == "identification" and lon.inputs == ["lon"] and lon.file == LON
    assert lon.trim_speed == pytest.approx(80 * 1852 / 3600, rel=1e-12)  # 41.1556 m/s
    d = lon.data
    assert d["col"].iloc[0] == pytest.approx(5.0 * math.pi / 180, rel=1e-12)  # 0.0872665 rad
    assert d["lon"].iloc[0] == pytest.approx(1.0 * math.pi / 180, rel=1e-12)
    i = 60  # t = 1.2 s: first pulse of the 3-2-1-1, +0.5 deg on 1 deg trim
    assert d["t"].iloc[i] == pytest.approx(1.2)
    assert d["lon"].iloc[i] == pytest.approx(1.5 * math.pi / 180, rel=1e-12)
    assert d["q"].iloc[i] == pytest.approx(6.0 * math.sin(2.4) * math.pi / 180, rel=1e-12)
    assert d["theta"].iloc[0] == pytest.approx(-2.0 * math.pi / 180, rel=1e-12)
    assert d["TAS"].iloc[0] == pytest.approx(80.0 * 0.514444444444444, rel=1e-12)
    assert d["n_z"].iloc[0] == 1.0 and d["n_x"].iloc[0] == -0.035  # g stays g
    inc = lon.increments()
    assert set(inc) == {"col", "lon"}
    assert inc["lon"][0] == 0.0 and np.max(inc["lon"]) == pytest.approx(0.5 * DEG, rel=1e-12)
    assert np.all(inc["col"] == 0.0)

    hov = ft.maneuvers["col_doublet_hover"]  # file in rad and m/s: unchanged
    assert "beta_0" in hov.data and hov.trim_speed == 0.0
    assert hov.data["col"].iloc[0] == 0.15 and hov.data["TAS"].iloc[0] == 0.5
    assert hov.data["beta_0"].iloc[0] == 0.045 and hov.data["q"].iloc[0] == 0.0

    tr = ft.trims
    assert list(tr.columns) == ["V", "gamma_fp", "col", "lon", "theta", "source"]
    np.testing.assert_allclose(tr["V"], np.array([0, 40, 80, 120, 80, 0, 80]) * 1852 / 3600, rtol=1e-12)
    assert tr["theta"].iloc[3] == pytest.approx(-5.0 * math.pi / 180, rel=1e-12)
    assert tr["col"].iloc[0] == pytest.approx(8.6 * math.pi / 180, rel=1e-12)
    assert list(tr["gamma_fp"]) == [0.0] * 7
    assert list(tr["source"]) == ["level"] * 4 + NAMES



def test_increments_refer_to_the_lead_in_mean_when_asked(ds):
    """input_reference_s > 0: inputs minus their mean over the quiet lead-in, not minus one noisy sample."""
    import dataclasses

    from pyomo_heli.nlp.identification import prepare_data

    lon = load_flight_test(ds).maneuvers["lon3211_80kt"]
    d = lon.data.copy()
    lead = d["t"] <= d["t"].iloc[0] + 0.5
    noise = np.where(np.arange(lead.sum()) % 2 == 0, 0.02, -0.02) * DEG   # +-0.02 deg, mean 0 over 26 samples
    d.loc[lead, "lon"] = d.loc[lead, "lon"] + noise
    noisy = dataclasses.replace(lon, data=d)
    first = noisy.increments()["lon"]
    assert first[0] == 0.0 and first[-1] == pytest.approx(-0.02 * DEG, rel=1e-9)  # that sample's noise, held
    ref = dataclasses.replace(noisy, input_reference_s=0.5).increments()["lon"]
    assert ref[-1] == pytest.approx(0.0, abs=1e-15) and np.max(ref) == pytest.approx(0.5 * DEG, rel=1e-12)
    # prepare_data passes the setting on; the default stays the first sample
    ft = load_flight_test(ds)
    assert prepare_data(ft, ["lon3211_80kt"]).maneuvers[0].input_reference_s == 0.0
    assert prepare_data(ft, ["lon3211_80kt"], input_reference_s=0.5).maneuvers[0].input_reference_s == 0.5

def test_gamma_fp_defaults_to_zero(ds):
    df = pd.read_csv(ds / "trims.csv").drop(columns=["gamma_fp_deg"])
    df.to_csv(ds / "trims.csv", index=False)
    assert list(load_flight_test(ds).trims["gamma_fp"]) == [0.0] * 7


def _files(folder: pathlib.Path) -> dict[str, bytes]:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_rewrite_is_byte_identical(ds, tmp_path):
    ft = load_flight_test(ds)
    a, b, c = tmp_path / "a", tmp_path / "b", tmp_path / "c"
    write_flight_test(a, ft)
    write_flight_test(b, ft)
    fa = _files(a)
    assert set(fa) == {"manifest.json", "trims.csv", LON, HOV, VAL}
    assert fa == _files(b)  # same data twice: identical bytes
    write_flight_test(c, load_flight_test(a))
    assert fa == _files(c)  # load + write is idempotent
    assert b"\r" not in b"".join(fa.values())
    head = fa[HOV].decode().splitlines()[0]
    assert head == "t_s,col_deg,lon_deg,q_deg_s,theta_deg,nx_g,nz_g,tas_kt,beta0_deg"
    assert fa["trims.csv"].decode().splitlines()[0] == "speed_kt,gamma_fp_deg,col_deg,lon_deg,theta_deg,source"
    man = json.loads(fa["manifest.json"])
    assert man["format"] == "pyomo_heli-flighttest" and man["format_version"] == 1
    assert [m["trim_speed_kt"] for m in man["maneuvers"]] == [80.0, 0.0, 80.0]
    back = load_flight_test(a)
    for name in NAMES:
        pd.testing.assert_frame_equal(back.maneuvers[name].data, ft.maneuvers[name].data, rtol=1e-9, atol=1e-12)
    pd.testing.assert_frame_equal(back.trims, ft.trims, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("as_type", [float, np.float32, np.int64])
def test_a_trim_speed_held_as_a_numpy_scalar_is_written_in_knots(ds, tmp_path, as_type):
    """Maneuver.trim_speed [m/s] as numpy float32 or int64 (not Python float subclasses) was written to the
    manifest's trim_speed_kt unconverted, 1.94 times too low (below 15 kt no check caught it)."""
    from pyomo_heli.units import KT

    ft = load_flight_test(ds)
    mv = ft.maneuvers[next(iter(ft.maneuvers))]
    v = round(mv.trim_speed)  # 41 m/s = 79.7 kt, the record's 80 kt within the check's 5 kt
    mv.trim_speed = as_type(v)
    write_flight_test(tmp_path / "w", ft)  # before: 41 "kt" in the manifest, refused by the speed check
    entry = next(e for e in json.loads((tmp_path / "w" / "manifest.json").read_text())["maneuvers"]
                 if e["name"] == mv.name)
    assert entry["trim_speed_kt"] == pytest.approx(v / KT, rel=1e-9)
    assert load_flight_test(tmp_path / "w").maneuvers[mv.name].trim_speed == pytest.approx(v, rel=1e-9)


def test_write_from_manifest_dict_and_si_frames(ds, tmp_path):
    ft = load_flight_test(ds)
    manifest = {"aircraft": "Bo-105 (synthetic)", "atmosphere": {"rho_kg_m3": 1.225, "g_m_s2": 9.80665},
                "mass_kg": 2200.0,
                "maneuvers": [{"name": m.name, "role": m.role, "trim_speed_kt": round(m.trim_speed / KT, 6),
                               "inputs": m.inputs} for m in ft.maneuvers.values()]}
    out = write_flight_test(tmp_path / "d", manifest, {n: m.data for n, m in ft.maneuvers.items()}, ft.trims)
    back = load_flight_test(out)
    assert list(back.maneuvers) == NAMES
    assert back.maneuvers["col_doublet_hover"].file == "maneuvers/col_doublet_hover.csv"
    write_flight_test(tmp_path / "e", ft)
    assert _files(tmp_path / "d")[HOV] == _files(tmp_path / "e")[HOV]


def test_writer_rejects_bad_si_frames(ds, tmp_path):
    ft = load_flight_test(ds)
    ft.maneuvers["lon3211_80kt"].data = ft.maneuvers["lon3211_80kt"].data.drop(columns=["q"]).assign(pitch=0.0)
    with pytest.raises(DatasetError) as exc:
        write_flight_test(tmp_path / "x", ft)
    msg = str(exc.value)
    assert "maneuvers/lon3211_80kt.csv: column 'q'" in msg and "column 'pitch'" in msg
    assert not (tmp_path / "x").exists()


def test_writer_validates_what_it_wrote(ds, tmp_path):
    ft = load_flight_test(ds)
    ft.mass = -1.0
    with pytest.raises(DatasetError, match=r"field 'mass_kg'"):
        write_flight_test(tmp_path / "x", ft)


def test_summary_lists_maneuvers_and_trims(ds):
    s = load_flight_test(ds).summary()
    for text in NAMES + ["identification", "validation", "Bo-105 (synthetic)", "80.0", "6.00", "50.0", "301",
                         "beta_0", "7 trim points", "0.0 .. 120.0 kt"]:
        assert text in s, text


# ---------------------------------------------------------------- truth.json is never read
def test_loads_without_truth_json(ds):
    assert not (ds / "truth.json").exists()
    assert load_flight_test(ds).maneuvers


def test_truth_json_is_never_opened(ds, tmp_path, monkeypatch, capsys):
    (ds / "truth.json").write_text("{ this is not json, and must never be read")
    before = (ds / "truth.json").read_bytes()
    opened = []

    def guard(real):
        def wrapper(file, *args, **kwargs):
            if "truth.json" in str(file):
                opened.append(str(file))
                raise AssertionError(f"truth.json opened: {file}")
            return real(file, *args, **kwargs)
        return wrapper

    def guard_method(real):
        def wrapper(self, *args, **kwargs):
            if self.name == "truth.json":
                opened.append(str(self))
                raise AssertionError(f"truth.json opened: {self}")
            return real(self, *args, **kwargs)
        return wrapper

    monkeypatch.setattr(builtins, "open", guard(builtins.open))
    monkeypatch.setattr(io, "open", guard(io.open))
    monkeypatch.setattr(os, "open", guard(os.open))
    for meth in ("open", "read_text", "read_bytes"):
        monkeypatch.setattr(pathlib.Path, meth, guard_method(getattr(pathlib.Path, meth)))

    assert validate_flight_test(ds) == []
    ft = load_flight_test(ds)
    assert check_data(str(ds)) == 0
    write_flight_test(ds, ft)  # rewriting in place leaves truth.json alone
    monkeypatch.undo()
    assert opened == []
    assert (ds / "truth.json").read_bytes() == before


# ---------------------------------------------------------------- the check-data command
def test_check_data_ok(ds, capsys):
    assert check_data(str(ds)) == 0
    out, err = capsys.readouterr()
    assert all(n in out for n in NAMES) and err == ""


def test_check_data_reports_every_problem(ds, capsys):
    (ds / VAL).unlink()
    _edit_manifest(ds, lambda m: m["atmosphere"].update(rho_kg_m3=0))
    _edit_csv(ds, LON, lambda d: d.rename(columns={"q_deg_s": "q_rpm"}))
    assert check_data(str(ds)) == 2
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert len(lines) == len(validate_flight_test(ds)) >= 3
    assert all(line.startswith("error: ") for line in lines)
    assert "Traceback" not in out + err
    assert "atmosphere.rho_kg_m3" in err and "maneuvers[2].file" in err and "column 'q_rpm'" in err


def test_check_data_missing_folder(tmp_path, capsys):
    assert check_data(str(tmp_path / "nope")) == 2
    assert "error: " in capsys.readouterr().err


def test_all_problems_reported_one_per_line(ds):
    _edit_manifest(ds, lambda m: (m.update(mass_kg="heavy"), m["maneuvers"][1].update(role="ident")))
    _edit_csv(ds, LON, lambda d: _set(d, "q_deg_s", [4, 5, 6], np.nan), na_rep="NaN")
    _edit_csv(ds, "trims.csv", lambda d: _set(d, "speed_kt", [2], -10.0))
    problems = validate_flight_test(ds)
    with pytest.raises(DatasetError) as exc:
        load_flight_test(ds)
    assert isinstance(exc.value, ValueError)
    assert exc.value.problems == problems
    lines = str(exc.value).splitlines()
    assert len(lines) == 1 + len(problems) == 5
    assert lines[1:] == [str(p) for p in problems]
    assert "manifest.json: field 'mass_kg'" in lines[1]
    assert "manifest.json: field 'maneuvers[1].role'" in lines[2]
    assert lines[3] == f"{LON}: column 'q_deg_s': 3 NaN values (rows 5, 6, 7)"
    assert lines[4].startswith("trims.csv: column 'speed_kt': 1 negative speed (row 3)")


def test_problem_str():
    assert str(Problem("maneuvers/x.csv", "q_deg_s", "3 NaN values (rows 5, 6, 7)")) == \
        "maneuvers/x.csv: column 'q_deg_s': 3 NaN values (rows 5, 6, 7)"
    assert str(Problem("manifest.json", "maneuvers[3].role", "bad")) == "manifest.json: field 'maneuvers[3].role': bad"
    assert str(Problem("trims.csv", None, "file is empty")) == "trims.csv: file is empty"


def test_low_speed_skips_pitot_check(ds):
    # hover record (TAS about 0.5 m/s) declared at 10 kt: below 15 kt the check is skipped
    _edit_manifest(ds, lambda m: m["maneuvers"][1].update(trim_speed_kt=10.0))
    assert validate_flight_test(ds) == []
    # ... but at 30 kt it is a problem
    _edit_manifest(ds, lambda m: m["maneuvers"][1].update(trim_speed_kt=30.0))
    assert [p.field for p in validate_flight_test(ds)] == ["maneuvers[1].trim_speed_kt"]


def test_pitot_tolerance(ds):
    _edit_manifest(ds, lambda m: m["maneuvers"][0].update(trim_speed_kt=95.0))  # 80 kt record, tol 19 kt
    assert validate_flight_test(ds) == []


# ---------------------------------------------------------------- catalogue of malformed datasets
def _edit_manifest(folder, fn):
    p = folder / "manifest.json"
    m = json.loads(p.read_text())
    fn(m)
    p.write_text(json.dumps(m, indent=2))


def _edit_csv(folder, rel, fn, **to_csv):
    p = folder / rel
    df = fn(pd.read_csv(p))
    df.to_csv(p, index=False, **to_csv)


def _set(df, col, rows, value):
    df[col] = df[col].astype(object) if isinstance(value, str) else df[col].astype(float)
    df.loc[rows, col] = value
    return df


def _text(folder, rel, fn):
    p = folder / rel
    p.write_text(fn(p.read_text()))


def _mutation(name, fn, *expected):
    return pytest.param(fn, expected, id=name)


m = _edit_manifest
M0 = lambda **kw: (lambda f: m(f, lambda d: d["maneuvers"][0].update(**kw)))  # noqa: E731

CASES = [
    _mutation("missing-folder", lambda f: shutil.rmtree(f), "bo105_example", "dataset folder does not exist"),
    _mutation("folder-is-a-file", lambda f: (shutil.rmtree(f), f.write_text("x")), "is not a folder"),
    _mutation("manifest-missing", lambda f: (f / "manifest.json").unlink(), "manifest.json: manifest file not found"),
    _mutation("manifest-unparseable", lambda f: _text(f, "manifest.json", lambda s: s.replace("}", "", 1)),
              "manifest.json: not valid JSON", "line"),
    _mutation("manifest-not-object", lambda f: (f / "manifest.json").write_text("[1, 2]"),
              "manifest.json: top level must be a JSON object"),
    _mutation("wrong-format", lambda f: m(f, lambda d: d.update(format="csv-thing")),
              "manifest.json: field 'format'", "pyomo_heli-flighttest"),
    _mutation("wrong-version", lambda f: m(f, lambda d: d.update(format_version=2)),
              "field 'format_version'", "unsupported version 2"),
    _mutation("missing-mass", lambda f: m(f, lambda d: d.pop("mass_kg")), "field 'mass_kg'", "missing"),
    _mutation("missing-maneuvers-key", lambda f: m(f, lambda d: d.pop("maneuvers")), "field 'maneuvers'", "missing"),
    _mutation("unknown-key-typo", lambda f: m(f, lambda d: d.update(mass=d.pop("mass_kg"))),
              "field 'mass'", "unknown key"),
    _mutation("mass-negative", lambda f: m(f, lambda d: d.update(mass_kg=-2200)), "field 'mass_kg'", "positive"),
    _mutation("rho-string", lambda f: m(f, lambda d: d["atmosphere"].update(rho_kg_m3="1.225")),
              "field 'atmosphere.rho_kg_m3'", "positive number"),
    _mutation("g-zero", lambda f: m(f, lambda d: d["atmosphere"].update(g_m_s2=0)), "field 'atmosphere.g_m_s2'"),
    # an empty maneuver list is a trim-only flight test; its trim rows may then not name maneuvers
    _mutation("empty-maneuver-list", lambda f: m(f, lambda d: d.update(maneuvers=[])),
              "trims.csv: column 'source'", "neither 'level' nor a maneuver name"),
    _mutation("duplicate-name", lambda f: m(f, lambda d: d["maneuvers"][2].update(name="lon3211_80kt")),
              "field 'maneuvers[2].name'", "duplicate maneuver name 'lon3211_80kt'"),
    _mutation("bad-name-chars", M0(name="lon 3211/80kt"), "field 'maneuvers[0].name'", "not a valid name"),
    _mutation("bad-role", lambda f: m(f, lambda d: d["maneuvers"][1].update(role="ident")),
              "field 'maneuvers[1].role'", "'ident' is not a role"),
    _mutation("no-identification", lambda f: m(f, lambda d: [e.update(role="validation") for e in d["maneuvers"]]),
              "field 'maneuvers'", "no maneuver has role 'identification'"),
    _mutation("bad-inputs", M0(inputs=["pitch"]), "field 'maneuvers[0].inputs'", "'col'"),
    _mutation("maneuver-file-absent", lambda f: (f / LON).unlink(),
              "field 'maneuvers[0].file'", "'maneuvers/lon3211_80kt.csv' does not exist"),
    _mutation("path-escapes-folder", M0(file="../lon3211_80kt.csv"),
              "field 'maneuvers[0].file'", "outside the dataset folder"),
    _mutation("absolute-path", M0(file="/etc/passwd.csv"), "field 'maneuvers[0].file'", "relative"),
    _mutation("truth-json-referenced", lambda f: m(f, lambda d: d.update(trim_file="truth.json")),
              "field 'trim_file'", "truth.json is evaluation-only"),
    _mutation("same-file-twice", lambda f: m(f, lambda d: d["maneuvers"][2].update(file=LON)),
              "field 'maneuvers[2].file'", "same file"),
    _mutation("same-file-by-another-path", lambda f: m(f, lambda d: d["maneuvers"][2].update(
        file="maneuvers/../" + LON)), "field 'maneuvers[2].file'", "same file"),
    _mutation("trim-file-missing", lambda f: (f / "trims.csv").unlink(), "field 'trim_file'", "does not exist"),
    _mutation("missing-required-column", lambda f: _edit_csv(f, LON, lambda d: d.drop(columns=["q_deg_s"])),
              f"{LON}: column 'q'", "missing required column", "'q_deg_s', 'q_rad_s'"),
    _mutation("unknown-column", lambda f: _edit_csv(f, LON, lambda d: d.assign(pitchrate_deg_s=0.0)),
              f"{LON}: column 'pitchrate_deg_s'", "unknown column", "recognised columns: t_s, col_deg"),
    _mutation("misnamed-case", lambda f: _edit_csv(f, LON, lambda d: d.rename(columns={"nz_g": "NZ_g"})),
              f"{LON}: column 'NZ_g'", "did you mean 'nz_g'"),
    _mutation("no-unit-suffix", lambda f: _edit_csv(f, LON, lambda d: d.rename(columns={"theta_deg": "theta"})),
              f"{LON}: column 'theta'", "no unit suffix"),
    _mutation("two-unit-variants", lambda f: _edit_csv(f, LON, lambda d: d.assign(theta_rad=d["theta_deg"] * DEG)),
              f"{LON}: column 'theta_rad'", "'theta_deg'", "exactly one"),
    _mutation("unit-not-recognised", lambda f: _edit_csv(f, LON, lambda d: d.rename(columns={"q_deg_s": "q_rpm"})),
              f"{LON}: column 'q_rpm'", "unit 'rpm' not recognised", "'q_deg_s'"),
    _mutation("duplicated-column", lambda f: _text(f, LON, lambda s: s.replace("nx_g,nz_g", "nz_g,nz_g", 1)),
              f"{LON}: column 'nz_g'", "appears 2 times"),
    _mutation("nan-values", lambda f: _edit_csv(f, LON, lambda d: _set(d, "q_deg_s", [4, 5, 6], np.nan),
                                                na_rep="NaN"),
              f"{LON}: column 'q_deg_s': 3 NaN values (rows 5, 6, 7)"),
    _mutation("empty-cells", lambda f: _edit_csv(f, HOV, lambda d: _set(d, "beta0_rad", [0], np.nan)),
              f"{HOV}: column 'beta0_rad': 1 empty value (row 1)"),
    _mutation("inf-values", lambda f: _edit_csv(f, VAL, lambda d: _set(d, "theta_deg", [10, 11], np.inf)),
              f"{VAL}: column 'theta_deg': 2 infinite values (rows 11, 12)"),
    _mutation("non-numeric", lambda f: _edit_csv(f, LON, lambda d: _set(d, "nz_g", [7], "1,5")),
              f"{LON}: column 'nz_g': 1 non-numeric value", "'1,5'"),
    _mutation("ragged-row", lambda f: _text(f, LON, lambda s: s.replace("\n0.02,", "\n0.02,1,", 1)),
              LON, "row 2", "fields but the header has 8"),
    _mutation("not-utf8", lambda f: (f / VAL).write_bytes((f / VAL).read_bytes() + "é".encode("latin-1")),
              VAL, "not UTF-8"),
    _mutation("empty-file", lambda f: (f / VAL).write_text(""), VAL, "file is empty"),
    _mutation("header-only", lambda f: _edit_csv(f, LON, lambda d: d.iloc[:0]), LON, "no data rows (header only)"),
    _mutation("too-few-samples", lambda f: _edit_csv(f, LON, lambda d: d.iloc[:2]), LON, "only 2 samples"),
    _mutation("time-duplicated", lambda f: _edit_csv(f, LON, lambda d: _set(d, "t_s", [100], d["t_s"][99])),
              f"{LON}: column 't_s'", "not strictly increasing",
              "1 duplicated time stamp (same time as the previous row at row 101)"),
    _mutation("time-decreasing", lambda f: _edit_csv(f, LON, lambda d: d.iloc[::-1]),
              f"{LON}: column 't_s'", "decreases"),
    _mutation("sample-rate-inconsistent", lambda f: _edit_csv(f, LON, lambda d: d.drop(index=[150, 151])),
              f"{LON}: column 't_s'", "inconsistent sample rate", "more than 1%"),
    _mutation("trim-speed-out-of-range", M0(trim_speed_kt=180.0),
              "field 'maneuvers[0].trim_speed_kt'", "outside the model range 0..150 kt"),
    _mutation("trim-speed-negative", M0(trim_speed_kt=-5.0), "field 'maneuvers[0].trim_speed_kt'", "negative"),
    _mutation("trim-speed-not-number", M0(trim_speed_kt="80"), "field 'maneuvers[0].trim_speed_kt'", "number"),
    _mutation("trim-speed-inconsistent-with-tas", M0(trim_speed_kt=120.0),
              "field 'maneuvers[0].trim_speed_kt'", "column 'tas_kt' in maneuvers/lon3211_80kt.csv", "80.0 kt"),
    _mutation("trim-table-speed-out-of-range", lambda f: _edit_csv(f, TRIMS, lambda d: _set(d, "speed_kt", [3], 180.0)),
              "trims.csv: column 'speed_kt'", "outside the model range", "row 4"),
    _mutation("trim-table-speed-negative", lambda f: _edit_csv(f, TRIMS, lambda d: _set(d, "speed_kt", [1], -40.0)),
              "trims.csv: column 'speed_kt'", "negative speed (row 2)"),
    _mutation("trim-table-missing-column", lambda f: _edit_csv(f, "trims.csv", lambda d: d.drop(columns=["lon_deg"])),
              "trims.csv: column 'lon'", "missing required column"),
    _mutation("trim-table-bad-source", lambda f: _edit_csv(f, "trims.csv", lambda d: _set(d, "source", [5], "hover")),
              "trims.csv: column 'source'", "row 6 ('hover')"),
    _mutation("trim-table-unknown-column", lambda f: _edit_csv(f, "trims.csv", lambda d: d.assign(speed_mph=1.0)),
              "trims.csv: column 'speed_mph'", "unit 'mph' not recognised"),
    _mutation("theta-deg-beyond-90", lambda f: _edit_csv(f, LON, lambda d: _set(d, "theta_deg", [3], 120.0)),
              f"{LON}: column 'theta_deg'", "90 deg", "wrong unit"),
    _mutation("theta-rad-holds-degrees",
              lambda f: _edit_csv(f, HOV, lambda d: d.assign(theta_rad=d["theta_rad"] / DEG)),
              f"{HOV}: column 'theta_rad'", "look like degrees", "theta_deg"),
    _mutation("q-rad-s-holds-deg-s", lambda f: _edit_csv(f, HOV, lambda d: _set(d, "q_rad_s", [9], 25.0)),
              f"{HOV}: column 'q_rad_s'", "look like degrees", "q_deg_s"),
    _mutation("nz-in-m-s2", lambda f: _edit_csv(f, LON, lambda d: d.assign(nz_g=d["nz_g"] * 9.80665)),
              f"{LON}: column 'nz_g'", "m/s^2"),
    _mutation("tas-strongly-negative", lambda f: _edit_csv(f, HOV, lambda d: _set(d, "tas_m_s", [0], -30.0)),
              f"{HOV}: column 'tas_m_s'", "negative"),
]


@pytest.mark.parametrize("mutate, expected", CASES)
def test_malformed_dataset(ds, mutate, expected):
    mutate(ds)
    problems = validate_flight_test(ds)
    assert problems, "mutation not detected"
    texts = [str(p) for p in problems]
    assert any(all(e in t for e in expected) for t in texts), "\n".join(texts)
    for p in problems:  # every problem names its file; CSV/manifest problems a column or field where one exists
        assert p.file and p.message
        assert isinstance(p, Problem)
    with pytest.raises(DatasetError) as exc:
        load_flight_test(ds)
    assert str(exc.value).splitlines()[1:] == texts


def test_catalogue_size():
    assert len(CASES) >= 18
