"""The dataset reader's checks (pyomo_heli.dataset.reader, schema) and the generator config's
(pyomo_heli.flighttest.config): bad input gives one clear line naming the file, column/field, row or key.

1. numeric CSV cells must be plain ASCII decimals: ``1_0`` and non-ASCII digits (``٥``), which Python's
   float() accepts, are rejected by check-data and the loader (maneuver tables and the trim table);
2. the manifest's mass and atmosphere must be plausible, and
   ``check_model_matches_manifest`` compares them with the model's m, rho, g;
3. the generator config is checked up front (durations, steps, amplitudes, start times, speeds,
   unknown keys ...): a ConfigError naming file, maneuver and key, before anything is simulated.

Every test works on copies in tmp_path and runs in well under a second.
"""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from pyomo_heli.cli import main
from pyomo_heli.dataset import DatasetError, load_flight_test, validate_flight_test
from pyomo_heli.dataset.cli import check_data
from pyomo_heli.dataset.reader import check_model_matches_manifest
from pyomo_heli.dataset.schema import (G_RANGE_M_S2, MASS_RANGE_KG, MODEL_MATCH_RTOL, RHO_RANGE_KG_M3,
                                       SPEED_RANGE_KT)
from pyomo_heli.flighttest.config import ConfigError, load_config
from pyomo_heli.physics.model import HelicopterModel

ROOT = Path(__file__).resolve().parents[1]
BUNDLED = ROOT / "data" / "bo105_synthetic"
LON = "maneuvers/lon3211_80kt_a.csv"
TRIMS = "trims.csv"


@pytest.fixture(scope="module")
def bundled_cut(tmp_path_factory) -> Path:
    """The bundled synthetic dataset cut to the maneuver the tests edit (``LON``) and the trims that are level or
    taken from it: the same files, rows and numbering, read in a fifth of the time (CI time: 99 tests read it)."""
    root = tmp_path_factory.mktemp("bundled_cut") / "ds"
    (root / "maneuvers").mkdir(parents=True)
    man = json.loads((BUNDLED / "manifest.json").read_text())
    man["maneuvers"] = [m for m in man["maneuvers"] if m["file"] == LON]
    (root / "manifest.json").write_text(json.dumps(man, indent=2))
    lines = (BUNDLED / TRIMS).read_text().splitlines(keepends=True)
    keep = ("level", man["maneuvers"][0]["name"])
    (root / TRIMS).write_text("".join([lines[0]] + [x for x in lines[1:] if x.rstrip("\n").rsplit(",", 1)[1] in keep]))
    for name in ("truth.json", LON):
        shutil.copy(BUNDLED / name, root / name)
    assert not validate_flight_test(root)
    return root


@pytest.fixture
def ds(tmp_path, bundled_cut) -> Path:
    """A fresh copy of the cut bundled dataset."""
    return Path(shutil.copytree(bundled_cut, tmp_path / "ds"))


def _set_cell(path: Path, row: int, column: str, text: str) -> str:
    """Replace the cell of data row ``row`` (1-based, as in the messages) in ``column``; return the old text."""
    lines = path.read_text(encoding="utf-8").split("\n")
    header = lines[0].split(",")
    j = header.index(column)
    cells = lines[row].split(",")
    old, cells[j] = cells[j], text
    lines[row] = ",".join(cells)
    path.write_text("\n".join(lines), encoding="utf-8")
    return old


# ============================================================== 1. plain ASCII decimals only
BAD_CELLS = {
    "underscore": "1_0",  # float() reads 10
    "underscore in the mantissa": "8_1.5",
    "arabic-indic digit": "\u0665",  # '٥', float() reads 5
    "fullwidth digit": "\uff11.5",  # '１.5'
    "mixed digits": "1\u0665",
    "underscore in the exponent": "1e1_0",
}


@pytest.mark.parametrize("table, column, row", [(LON, "tas_kt", 2), (LON, "t_s", 5), (TRIMS, "gamma_fp_deg", 1),
                                                (TRIMS, "speed_kt", 3)])
@pytest.mark.parametrize("case", list(BAD_CELLS))
def test_non_plain_decimal_cell_is_rejected_naming_file_column_row(ds, case, table, column, row, capsys):
    text = BAD_CELLS[case]
    _set_cell(ds / table, row, column, text)
    problems = validate_flight_test(ds)
    assert len(problems) == 1, problems
    p = problems[0]
    assert (p.file, p.field) == (table, column)
    msg = str(p)
    assert f"row {row} ({text!r})" in msg and "not written as a plain decimal number" in msg, msg
    with pytest.raises(DatasetError, match="plain decimal"):
        load_flight_test(ds)
    assert check_data(str(ds)) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"error: {table}: column '{column}': "), err


def test_several_bad_cells_are_listed_in_one_line(ds):
    for row, text in ((3, "1_0"), (7, "\u0665"), (9, "2_5")):
        _set_cell(ds / LON, row, "q_deg_s", text)
    (p,) = validate_flight_test(ds)
    assert str(p).startswith(f"{LON}: column 'q_deg_s': 3 values not written as a plain decimal number "
                              "(rows 3 ('1_0'), 7 ('٥'), 9 ('2_5'))")


@pytest.mark.parametrize("text, value", [("+1.5", 1.5), ("-.5", -0.5), ("5.", 5.0), ("2E+1", 20.0),
                                         ("-2.5e-3", -2.5e-3), (" 7 ", 7.0), ("0012", 12.0)])
def test_plain_decimal_forms_still_load(ds, text, value):
    _set_cell(ds / TRIMS, 1, "gamma_fp_deg", text)
    ft = load_flight_test(ds)
    assert ft.trims["gamma_fp"].iloc[0] == pytest.approx(value * 3.141592653589793 / 180.0, rel=1e-12)


@pytest.mark.parametrize("text, words", [("inf", "1 infinite value (row 4)"), ("-Infinity", "1 infinite value (row 4)"),
                                         ("nan", "1 NaN value (row 4)"), ("", "1 empty value (row 4)"),
                                         ("1,5", "non-numeric value"), ("abc", "1 non-numeric value (row 4 ('abc'))")])
def test_other_bad_cells_keep_their_own_message(ds, text, words):
    if text == "1,5":
        text = '"1,5"'  # one quoted CSV field
    _set_cell(ds / LON, 4, "theta_deg", text)
    problems = validate_flight_test(ds)
    assert len(problems) == 1, problems
    assert words in str(problems[0]) and "plain decimal" not in str(problems[0])


# ============================================================== 2. manifest mass and atmosphere
def _edit_manifest(ds: Path, edit) -> None:
    path = ds / "manifest.json"
    man = json.loads(path.read_text())
    edit(man)
    path.write_text(json.dumps(man, indent=2, sort_keys=True) + "\n")


@pytest.mark.parametrize("field, value", [("mass_kg", 1.0), ("mass_kg", 2.2e6), ("atmosphere.rho_kg_m3", 0.1),
                                          ("atmosphere.rho_kg_m3", 12.25), ("atmosphere.g_m_s2", 98.1),
                                          ("atmosphere.g_m_s2", 1.0)])
def test_implausible_mass_or_atmosphere_is_rejected(ds, field, value, capsys):
    def edit(man):
        if field.startswith("atmosphere."):
            man["atmosphere"][field.split(".")[1]] = value
        else:
            man[field] = value

    _edit_manifest(ds, edit)
    (p,) = validate_flight_test(ds)
    assert (p.file, p.field) == ("manifest.json", field)
    assert f"{value:g}" in p.message and "outside the plausible range" in p.message
    assert check_data(str(ds)) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"error: {p}"]


def test_plausible_ranges_hold_the_bundled_and_standard_values():
    assert MASS_RANGE_KG[0] <= 2200.0 <= MASS_RANGE_KG[1]
    assert RHO_RANGE_KG_M3[0] <= 1.225 <= RHO_RANGE_KG_M3[1]
    assert G_RANGE_M_S2[0] <= 9.80665 <= G_RANGE_M_S2[1] and G_RANGE_M_S2[0] <= 9.81 <= G_RANGE_M_S2[1]


def test_sed_reproduction_mass_1_kg_fails_check_data(ds, capsys):
    path = ds / "manifest.json"
    path.write_text(path.read_text().replace('"mass_kg": 2200.0', '"mass_kg": 1.0'))
    assert check_data(str(ds)) == 2
    assert "manifest.json: field 'mass_kg': 1 kg is outside" in capsys.readouterr().err


@pytest.fixture(scope="module")
def bundled():
    return load_flight_test(BUNDLED)


def test_model_matching_the_manifest_passes(bundled):
    params = HelicopterModel().parameters  # m 2200 kg, rho 1.225, g 9.81: the bundled manifest's values
    assert check_model_matches_manifest(bundled, params, "case.toml [model]") is None
    inside = dict(params, m=2200.0 * (1 + 0.9 * MODEL_MATCH_RTOL), rho=1.225 * (1 - 0.9 * MODEL_MATCH_RTOL))
    check_model_matches_manifest(bundled, inside, "case.toml [model]")


@pytest.mark.parametrize("name, field, value", [("m", "mass_kg", 2200.0 * (1 + 1.1 * MODEL_MATCH_RTOL)),
                                                ("m", "mass_kg", 1.0), ("rho", "atmosphere.rho_kg_m3", 1.0),
                                                ("g", "atmosphere.g_m_s2", 9.7)])
def test_model_differing_from_the_manifest_raises_naming_file_field_and_parameter(bundled, name, field, value):
    params = dict(HelicopterModel().parameters, **{name: value})
    with pytest.raises(ValueError) as info:
        check_model_matches_manifest(bundled, params, "case.toml [model]")
    msg = str(info.value)
    assert "\n" not in msg
    assert msg.startswith(str(BUNDLED / "manifest.json"))
    assert f"field '{field}'" in msg and f"model parameter {name} = {value:g}" in msg
    assert "case.toml [model]" in msg and "[model] parameters" in msg
    assert f"{name} = " in msg.split("[model] parameters")[1]  # the value to set


def test_model_check_lists_every_difference_and_needs_m_rho_g(bundled):
    params = dict(HelicopterModel().parameters, m=3000.0, g=9.7)
    with pytest.raises(ValueError, match=r"'mass_kg'.*'atmosphere.g_m_s2'.*m = 2200, g = 9.81"):
        check_model_matches_manifest(bundled, params, "x.toml")
    with pytest.raises(ValueError, match="rho missing"):
        check_model_matches_manifest(bundled, {"m": 2200.0, "g": 9.81}, "x.toml")


# ============================================================== 3. generator config
TINY = """\
[dataset]
name = "tiny"
aircraft = "Bo-105 (tiny test config)"
seed = 1

[truth]
parameters = {}

[sensors]
noise = true

[trims]
speeds_kt = [20, 80]

[[maneuvers]]
name = "lon3211_80kt"
role = "identification"
speed_kt = 80
channel = "lon"
shape = "3211"
amplitude_deg = 0.5
step_s = 0.5
duration_s = 4
"""
MAN = "[[maneuvers]] #1 ('lon3211_80kt')"


def _sub(old, new):
    def edit(s):
        assert old in s
        return s.replace(old, new, 1)
    return edit


BAD_CONFIGS = {
    # case: (edit, words the message must contain)
    "negative duration": (_sub("duration_s = 4", "duration_s = -4"), [MAN, "'duration_s'", "> 0"]),
    "zero duration": (_sub("duration_s = 4", "duration_s = 0"), [MAN, "'duration_s'"]),
    "nan duration": (_sub("duration_s = 4", "duration_s = nan"), [MAN, "'duration_s'", "finite"]),
    "too short duration": (_sub("duration_s = 4", "duration_s = 0.01"), [MAN, "'duration_s'", "3 samples"]),
    "zero step": (_sub("step_s = 0.5", "step_s = 0"), [MAN, "'step_s'", "> 0"]),
    "negative step": (_sub("step_s = 0.5", "step_s = -0.5"), [MAN, "'step_s'"]),
    "inf amplitude": (_sub("amplitude_deg = 0.5", "amplitude_deg = inf"), [MAN, "'amplitude_deg'", "finite"]),
    "huge amplitude": (_sub("amplitude_deg = 0.5", "amplitude_deg = -60"), [MAN, "'amplitude_deg'", "45 deg"]),
    "string amplitude": (_sub("amplitude_deg = 0.5", 'amplitude_deg = "0.5"'), [MAN, "'amplitude_deg'"]),
    "negative t_start": (_sub("duration_s = 4", "duration_s = 4\nt_start_s = -1"), [MAN, "'t_start_s'", ">= 0"]),
    "t_start after the record": (_sub("duration_s = 4", "duration_s = 4\nt_start_s = 4.5"),
                                 [MAN, "'t_start_s'", "duration_s = 4"]),
    "default t_start after a short record": (_sub("duration_s = 4", "duration_s = 1.5"), [MAN, "'t_start_s'"]),
    # a record whose declared input never moves: check-data refuses it (issue 32), so the generator does too
    "t_start at the end of the record": (_sub("duration_s = 4", "duration_s = 4\nt_start_s = 4"),
                                         [MAN, "'t_start_s'", "at the end"]),
    "zero amplitude": (_sub("amplitude_deg = 0.5", "amplitude_deg = 0"), [MAN, "'amplitude_deg'", "never move"]),
    "record rate in kHz": (_sub("[sensors]", "[sensors]\nrecord_rate_hz = 50000"), ["'record_rate_hz'", "plausible"]),
    "negative ramp": (_sub("duration_s = 4", "duration_s = 4\nramp_s = -0.1"), [MAN, "'ramp_s'"]),
    "maneuver speed 300 kt": (_sub("speed_kt = 80", "speed_kt = 300"),
                              [MAN, "'speed_kt'", "300", f"{SPEED_RANGE_KT[0]:g}..{SPEED_RANGE_KT[1]:g} kt"]),
    "negative maneuver speed": (_sub("speed_kt = 80", "speed_kt = -5"), [MAN, "'speed_kt'"]),
    "trim speed 300 kt": (_sub("speeds_kt = [20, 80]", "speeds_kt = [20, 300]"),
                          ["[trims]", "'speeds_kt[1]'", "300", f"{SPEED_RANGE_KT[1]:g} kt"]),
    "negative trim speed": (_sub("speeds_kt = [20, 80]", "speeds_kt = [-1, 80]"), ["[trims]", "'speeds_kt[0]'"]),
    "string trim speed": (_sub("speeds_kt = [20, 80]", 'speeds_kt = [20, "80"]'), ["[trims]", "'speeds_kt[1]'"]),
    "unknown channel": (_sub('channel = "lon"', 'channel = "lat"'), [MAN, "'channel'", "lat"]),
    "unknown shape": (_sub('shape = "3211"', 'shape = "3212"'), [MAN, "'shape'", "3212"]),
    "bad maneuver name": (_sub('name = "lon3211_80kt"', 'name = "lon 3211"'), ["#1", "'name'", "lon 3211"]),
    "negative seed": (_sub("seed = 1", "seed = -1"), ["[dataset]", "'seed'"]),
    "zero sim rate": (_sub("noise = true", "noise = true\nsim_rate_hz = 0"), ["[sensors]", "'sim_rate_hz'"]),
    "rates that do not fit": (_sub("noise = true", "noise = true\nrecord_rate_hz = 30.0"),
                              ["[sensors]", "record_rate"]),
    "negative sigma": (_sub("noise = true", "noise = true\nsigma = { q_deg_s = -0.2 }"),
                       ["[sensors.sigma]", "'q_deg_s'"]),
    "negative trim offset": (_sub("speeds_kt = [20, 80]", "speeds_kt = [20, 80]\noffset_col_deg = -0.1"),
                             ["[trims]", "'offset_col_deg'"]),
    "implausible truth mass": (_sub("parameters = {}", "parameters = { m = 1.0 }"), ["[truth.parameters]", "m = 1"]),
    "nan truth parameter": (_sub("parameters = {}", "parameters = { Iyy = nan }"), ["[truth.parameters]", "'Iyy'"]),
    "effect that is not a table": (_sub("parameters = {}", "parameters = {}\neffects = { wake_on_tail = 1.5 }"),
                                   ["[truth.effects]", "wake_on_tail"]),
    "no identification maneuver": (_sub('role = "identification"', 'role = "validation"'), ["identification"]),
    # misspelt keys are rejected in every table
    "unknown key in [dataset]": (_sub("seed = 1", "seed = 1\nseeed = 2"), ["[dataset]", "'seeed'"]),
    "unknown key in [truth]": (_sub("parameters = {}", "parameters = {}\nparameter = {}"), ["[truth]", "'parameter'"]),
    "unknown key in [sensors]": (_sub("noise = true", "noise = true\nrecord_hz = 50.0"), ["[sensors]", "'record_hz'"]),
    "unknown key in [trims]": (_sub("speeds_kt = [20, 80]", "speeds_kt = [20, 80]\nsigma_col = 0.05"),
                               ["[trims]", "'sigma_col'"]),
    "unknown key in [[maneuvers]]": (_sub("duration_s = 4", "duration_s = 4\nt_start = 1.0"), [MAN, "'t_start'"]),
    "unknown top-level table": (lambda s: "[sensor]\nnoise = true\n\n" + s, ["'sensor'"]),
    "unknown sensor channel with noise off": (_sub("noise = true", "noise = false\nsigma = { qq_deg_s = 0.2 }"),
                                              ["[sensors.sigma]", "qq_deg_s"]),
    # found by a review: accepted although meaningless
    "sensor sigma in the wrong unit": (_sub("noise = true", "noise = true\nsigma = { q_deg_s = 5000.0 }"),
                                       ["[sensors.sigma]", "'q_deg_s' = 5000.0 is not a sensor noise sigma"]),
    "ramp longer than a pulse": (_sub("duration_s = 4", "duration_s = 4\nramp_s = 5"),
                                 [MAN, "key 'ramp_s' = 5 s is longer than a pulse (step_s = 0.5 s)"]),
}


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "gen.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize("case", list(BAD_CONFIGS))
def test_bad_generator_config_raises_config_error_naming_file_and_key(case, tmp_path):
    edit, words = BAD_CONFIGS[case]
    path = _write(tmp_path, edit(TINY))
    with pytest.raises(ConfigError) as info:
        load_config(path)
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith(str(path)), msg
    for w in words:
        assert w in msg, f"{case}: {w!r} not in {msg!r}"


@pytest.mark.parametrize("extra", ["", "t_start_s = 3.9", "t_start_s = 0\nramp_s = 0", "amplitude_deg = -0.5"])
def test_edge_values_are_accepted(extra, tmp_path):
    text = TINY if not extra else TINY.replace("amplitude_deg = 0.5\n", "") + extra + "\n"
    if "amplitude_deg" not in text:
        text += "amplitude_deg = 0.5\n"
    cfg = load_config(_write(tmp_path, text))
    assert cfg.maneuvers[0].duration == 4.0


@pytest.mark.parametrize("case", ["negative duration", "maneuver speed 300 kt", "unknown key in [dataset]"])
def test_cli_reports_bad_generator_config_in_one_line_before_simulating(case, tmp_path, capsys):
    path = _write(tmp_path, BAD_CONFIGS[case][0](TINY))
    out = tmp_path / "out"
    assert main(["generate-data", "--config", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err
    assert err.startswith("pyomo-heli generate-data: error: " + str(path))
    assert not out.exists()  # nothing simulated, nothing written
