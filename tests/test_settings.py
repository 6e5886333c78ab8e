"""One settings system (pyomo_heli.settings): every error of a file in one pass, the JSON Schema of each
config kind (committed under schemas/ as `pyomo-heli schema --out-dir schemas` writes it, and every bundled
config valid under it), and the declarations' defaults equal to the objects the loaders build."""
from __future__ import annotations

import json
import tomllib
from pathlib import Path

import pytest

from pyomo_heli.cli import main
from pyomo_heli.settings import KINDS, ConfigError, schema, schema_text

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "data" / "bo105_synthetic"


def _kind(path: Path) -> str:
    text = path.read_text()
    if "[[maneuvers]]" in text:
        return "generate"
    if "holdout_every" in text or "flight_trims" in path.name:
        return "trim-loop"
    return "identify"


BUNDLED = sorted([*ROOT.glob("studies/*.toml"), *ROOT.glob("tests/configs/*.toml"), *ROOT.glob("data/*.toml")])


# ------------------------------------------------------------------ every error in one pass
def test_identification_config_with_several_errors_names_all_of_them(tmp_path):
    from pyomo_heli.config import load_identification_config

    path = tmp_path / "bad.toml"
    path.write_text(f'''[data]
dataset = "{DATA}"
resample_hz = -25
resample_hzz = 3

[parameters.theta_twist]
initial = -2.0
scale = 0

[objectives]
time_outputs = ["q", "q"]

[pareto]
points = 1
cold_check = "yes"

[solver]
name = "snopt"
''')
    with pytest.raises(ConfigError) as err:
        load_identification_config(path)
    lines = str(err.value).splitlines()
    assert err.value.problems == lines
    expected = [
        "[data]: field 'resample_hz' must be a positive number",
        "[data]: unknown key(s) resample_hzz; use",
        "[parameters.theta_twist]: field 'scale' must be a number > 0, got 0",
        "[objectives]: field 'time_outputs' names ['q'] more than once",
        "[pareto]: field 'points': the epsilon grid needs 2 (the anchors) to 1000 points, got 1",
        "[pareto]: field 'cold_check' must be bool, got 'yes'",
        "[solver]: field 'name': unknown solver 'snopt'; choose from casadi-ipopt, pounce, ipopt",
    ]
    assert len(lines) == len(expected)
    for e in expected:
        assert sum(line.startswith(f"{path} {e}") for line in lines) == 1, (e, lines)


def test_cross_field_errors_are_collected_too(tmp_path):
    """Once every field is valid, the rules across fields and tables report all their errors together."""
    from pyomo_heli.config import load_identification_config

    path = tmp_path / "cross.toml"
    path.write_text(f'''[data]
dataset = "{DATA}"
maneuvers = ["lon3211_80kt_a"]
validation = ["lon3211_80kt_a"]

[model]
parameters = {{ mass = 2200 }}

[parameters.theta_twist]
unit = "furlong"

[objectives]
noise_sigma = {{ col_deg = 0.02 }}
''')
    with pytest.raises(ConfigError) as err:
        load_identification_config(path)
    text = str(err.value)
    assert len(text.splitlines()) == 5, text
    for needle in ("[objectives.noise_sigma]: no sigma for ['q', 'theta', 'n_x', 'n_z', 'TAS']",
                   "[data]: maneuver(s) lon3211_80kt_a listed in both", "[model.parameters]: unknown parameter name "
                   "'mass'", "[parameters.theta_twist]: unit 'furlong' not recognised",
                   "[objectives]: noise_sigma is only used with input_errors"):
        assert f"{path} {needle}" in text, (needle, text)


def test_generator_config_with_several_errors_names_all_of_them(tmp_path):
    from pyomo_heli.flighttest.config import load_config

    text = (ROOT / "data" / "bo105_clean.toml").read_text()
    assert "sim_rate_hz = 400.0" in text
    text = text.replace("seed =", "seeed = 1\nseed =", 1).replace("sim_rate_hz = 400.0", "sim_rate_hz = 0", 1)
    text = text.replace('role = "identification"', 'role = "training"', 1)
    path = tmp_path / "gen.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as err:
        load_config(path)
    lines = str(err.value).splitlines()
    assert len(lines) == 3, lines
    assert any(line.startswith(f"{path} [dataset]: unknown key 'seeed'") for line in lines)
    assert any(line.startswith(f"{path} [sensors]: key 'sim_rate_hz' must be > 0, got 0") for line in lines)
    assert any(line.startswith(f"{path} [[maneuvers]] #1 (") and "role must be identification or validation, got "
               "'training'" in line for line in lines)


def test_cli_prints_each_error_on_its_own_line_exit_2(tmp_path, capsys):
    path = tmp_path / "two.toml"
    path.write_text(f'[data]\ndataset = "{DATA}"\nmax_duration_s = 0\n\n[parameters.Iyy]\ninitial = 5000.0\n\n'
                    f'[discretization]\nncp = 9\n')
    assert main(["identify", str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"pyomo-heli identify: error: {path} [data]: field 'max_duration_s' must be a positive number",
                   f"pyomo-heli identify: error: {path} [discretization]: field 'ncp' must be 1..5"]
    assert not (tmp_path / "o").exists()


def test_trim_loop_config_errors_in_one_pass(tmp_path):
    from pyomo_heli.workflows.trim_loop import TrimLoopError, load_trim_loop_config

    text = (ROOT / "studies" / "bo105_flight_trims.toml").read_text().replace(
        "../data/", str(ROOT / "data") + "/")
    path = tmp_path / "trims.toml"
    path.write_text(text + "\n[solver]\nname = 5\nbogus = 1\n")
    with pytest.raises(TrimLoopError) as err:
        load_trim_loop_config(path)
    assert isinstance(err.value, ConfigError)  # one error type
    lines = str(err.value).splitlines()
    assert any("[solver]: field 'name'" in line for line in lines) and any("[solver]: unknown key(s) bogus" in line
                                                                        for line in lines), lines


def test_one_error_type():
    import pyomo_heli
    from pyomo_heli import config
    from pyomo_heli.flighttest import config as gen_config

    assert config.ConfigError is gen_config.ConfigError is ConfigError is pyomo_heli.ConfigError


# ------------------------------------------------------------------ JSON Schema
@pytest.mark.parametrize("kind", list(KINDS))
def test_committed_schema_is_the_generated_one(kind):
    """schemas/<kind>.schema.json is what `pyomo-heli schema --out-dir schemas` writes (regenerate with it)."""
    assert (ROOT / "schemas" / f"{kind}.schema.json").read_text() == schema_text(kind)


def test_cli_schema_prints_json(capsys, tmp_path):
    assert main(["schema", "generate"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["$schema"].endswith("2020-12/schema") and set(doc["required"]) == {"dataset", "trims", "maneuvers"}
    # a kind and --out-dir (which writes every kind): one line, nothing written
    assert main(["schema", "identify", "--out-dir", str(tmp_path / "s")]) == 2
    assert capsys.readouterr().err.strip() == ("pyomo-heli schema: error: give a config kind (identify) or --out-dir "
                                               "(every kind), not both") and not (tmp_path / "s").exists()


def _resolve(node: dict, root: dict) -> dict:
    while "$ref" in node:
        node = root["$defs"][node["$ref"].rsplit("/", 1)[-1]]
    return node


def _check(value, node: dict, root: dict, where: str) -> list[str]:
    """A small JSON Schema check (the keywords the settings schemas use) when jsonschema is not installed."""
    node = _resolve(node, root)
    if "anyOf" in node:
        tries = [_check(value, n, root, where) for n in node["anyOf"]]
        return [] if any(not t for t in tries) else [f"{where}: no branch of anyOf fits: {tries}"]
    errs = []
    types = {"object": dict, "array": list, "string": str, "boolean": bool, "integer": int, "number": (int, float),
             "null": type(None)}
    t = node.get("type")
    if t and not (isinstance(value, types[t]) and not (t in ("integer", "number") and isinstance(value, bool))):
        return [f"{where}: {value!r} is not {t}"]
    if "enum" in node and value not in node["enum"]:
        errs.append(f"{where}: {value!r} not in {node['enum']}")
    if "const" in node and value != node["const"]:
        errs.append(f"{where}: {value!r} != {node['const']!r}")
    for key, op in (("minimum", "__ge__"), ("maximum", "__le__"), ("exclusiveMinimum", "__gt__"),
                    ("exclusiveMaximum", "__lt__")):
        if key in node and not getattr(value, op)(node[key]):
            errs.append(f"{where}: {value!r} violates {key} {node[key]}")
    if isinstance(value, dict):
        props = node.get("properties", {})
        errs += [f"{where}: missing {k}" for k in node.get("required", []) if k not in value]
        for k, v in value.items():
            if k in props:
                errs += _check(v, props[k], root, f"{where}.{k}")
            elif node.get("additionalProperties") is False:
                errs.append(f"{where}: unknown key {k}")
            elif isinstance(node.get("additionalProperties"), dict):
                errs += _check(v, node["additionalProperties"], root, f"{where}.{k}")
    if isinstance(value, list):
        for i, v in enumerate(value):
            if "prefixItems" in node and i < len(node["prefixItems"]):
                errs += _check(v, node["prefixItems"][i], root, f"{where}[{i}]")
            elif "items" in node:
                errs += _check(v, node["items"], root, f"{where}[{i}]")
        if "minItems" in node and len(value) < node["minItems"]:
            errs.append(f"{where}: fewer than {node['minItems']} items")
    return errs


@pytest.mark.parametrize("path", BUNDLED, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_bundled_config_is_valid_under_its_schema(path):
    raw = tomllib.loads(path.read_text())
    doc = schema(_kind(path))
    try:
        import jsonschema
    except ImportError:
        assert _check(raw, doc, doc, path.name) == []
    else:
        jsonschema.validate(raw, doc)


@pytest.mark.parametrize("raw, needle", [
    ({"data": {"dataset": "x"}, "parameters": {}, "paretto": {}}, "unknown key paretto"),
    ({"data": {"dataset": "x", "resample_inputs": "nearest"}, "parameters": {}},
     "not in ['sample', 'project', 'record']"),
    ({"data": {"dataset": 3}, "parameters": {}}, "3 is not string"),
    ({"parameters": {}}, "missing data"),
])
def test_the_schema_refuses_what_the_loader_refuses(raw, needle):
    """The small checker above is a real check: the schema rejects bad files (and pydantic agrees)."""
    from pydantic import ValidationError

    from pyomo_heli.settings.identification import IdentificationFile

    doc = schema("identify")
    assert any(needle in e for e in _check(raw, doc, doc, "f")), _check(raw, doc, doc, "f")
    with pytest.raises(ValidationError):
        IdentificationFile.model_validate(raw)


# ------------------------------------------------------------------ defaults and vocabularies
def test_identification_defaults_are_the_objects_defaults():
    from pyomo_heli.nlp.identification import NLPOptions
    from pyomo_heli.pareto.front import PREDICTORS, WARM_STARTS, ParetoSettings
    from pyomo_heli.settings import identification as ident
    from pyomo_heli.solvers import SOLVER_NAMES

    obj, disc, par, sol = (ident.ObjectivesTable(), ident.DiscretizationTable(), ident.ParetoTable(),
                           ident.IdentificationSolverTable())
    nlp = NLPOptions()
    assert (tuple(obj.time_outputs), tuple(obj.trim_outputs), obj.covariance, disc.ncp, tuple(obj.input_errors)) == \
        (nlp.time_outputs, nlp.trim_outputs, nlp.covariance, nlp.ncp, tuple(nlp.input_errors))
    p = ParetoSettings()
    assert (par.points, par.spacing, par.warm_start, par.cold_check, par.predictor, sol.name) == \
        (p.points, p.spacing, p.warm_start, p.cold_check, p.predictor, p.solver)
    assert ident.WARM_STARTS == WARM_STARTS and ident.PREDICTORS == PREDICTORS
    from pyomo_heli.settings.common import SOLVER_NAMES as declared

    assert declared == SOLVER_NAMES


def test_loop_and_linear_defaults_are_the_objects_defaults():
    from pyomo_heli.dataset.frequency_response import DEFAULT_PAIRS
    from pyomo_heli.linear_settings import LinearSettings
    from pyomo_heli.settings.identification import DEFAULT_PAIRS as declared_pairs, LoopTable
    from pyomo_heli.settings.trim_loop import TrimLoopTable
    from pyomo_heli.workflows.close_loop import LoopSettings
    from pyomo_heli.workflows.trim_loop import TrimLoopConfig

    assert LoopSettings(**LoopTable().model_dump()) == LoopSettings()
    assert LinearSettings.from_table({}) == LinearSettings() and declared_pairs == DEFAULT_PAIRS
    t, c = TrimLoopTable(), TrimLoopConfig(path=Path("x"), dataset=Path("y"))
    assert (t.max_iterations, t.candidates, t.alpha, t.ratio, t.confound_corr) == \
        (c.max_iterations, c.candidates, c.alpha, c.ratio, c.confound_corr)


def test_generator_defaults_and_vocabularies():
    from pyomo_heli.dataset.schema import ROLES
    from pyomo_heli.flighttest.config import ManeuverPlan
    from pyomo_heli.settings import generator as gen
    from pyomo_heli.simulation.inputs import SHAPES

    assert gen.ROLES == ROLES and gen.SHAPES == tuple(SHAPES)
    fields = gen.ManeuverTable.model_fields
    plan = ManeuverPlan("x", "identification", 0.0, "col", "step", 0.1, 1.0, 5.0)
    assert (fields["t_start_s"].default, fields["ramp_s"].default) == (plan.t_start, plan.ramp)


# ------------------------------------------------------------------ the flight-test manifest
MANIFESTS = sorted([*ROOT.glob("data/*/manifest.json"), *ROOT.glob("tests/data/*/manifest.json")])


@pytest.mark.parametrize("path", MANIFESTS, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_bundled_manifest_fits_its_declaration(path):
    from pyomo_heli.settings.manifest import Manifest

    raw = json.loads(path.read_text())
    Manifest.model_validate(raw)
    doc = schema("manifest")
    assert _check(raw, doc, doc, path.name) == []


def test_manifest_declaration_is_the_readers():
    """The reader takes its key tables from the declaration; format name and version agree with the format's."""
    from pyomo_heli.dataset import tables as reader  # the reader's key tables
    from pyomo_heli.dataset.schema import FORMAT_NAME, FORMAT_VERSION
    from pyomo_heli.settings import manifest

    assert (manifest.FORMAT_NAME, manifest.FORMAT_VERSION) == (FORMAT_NAME, FORMAT_VERSION)
    assert reader.MANIFEST_KEYS == {"format": True, "format_version": True, "aircraft": True, "description": False,
                                    "atmosphere": True, "mass_kg": True, "trim_file": True, "maneuvers": True,
                                    "conventions": False, "source": False, "accuracy": False, "assumptions": False}
    assert reader.MANEUVER_KEYS == {"name": True, "file": True, "role": True, "trim_speed_kt": True, "inputs": True,
                                    "description": False}
    assert reader.ATMOSPHERE_KEYS == ("rho_kg_m3", "g_m_s2")
