"""Every settings file declared once (pydantic v2): tables, fields, defaults, domains, units, documentation.

One module per config kind; :data:`KINDS` names them for ``pyomo-heli schema KIND`` (the JSON Schema editors
use). The loaders (pyomo_heli.config, pyomo_heli.flighttest.config, pyomo_heli.workflows.trim_loop) validate a
file against its declaration, report every error of the file in one pass (:class:`ConfigError`, one line per
error) and then apply the rules that compare fields. docs/settings.md says why pydantic.
"""
from .base import ConfigError, Problems, Table, read_settings, validate

__all__ = ["ConfigError", "KINDS", "Problems", "Table", "read_settings", "schema", "schema_text", "validate",
           "write_schemas"]


def _identification():
    from .identification import identification_schema

    return identification_schema()


def _generator():
    from .generator import GeneratorFile

    return GeneratorFile.model_json_schema()


def _trim_loop():
    from .trim_loop import TrimLoopFile

    return TrimLoopFile.model_json_schema()


def _loop():
    from .identification import LoopTable

    return LoopTable.model_json_schema()


def _manifest():
    from .manifest import Manifest

    return Manifest.model_json_schema()


#: config kind -> (what it is, its JSON Schema)
KINDS = {
    "identify": ("identification config (identify, close-loop, diagnose, uncertainty, multistart)", _identification),
    "generate": ("flight-test generator config (generate-data)", _generator),
    "trim-loop": ("trim-loop config (trim-loop)", _trim_loop),
    "loop": ("the [loop] table of an identification config (close-loop)", _loop),
    "manifest": ("manifest.json of a flight-test folder (check-data; docs/data_format.md)", _manifest),
}


def schema(kind: str) -> dict:
    """The JSON Schema (draft 2020-12) of a config kind of :data:`KINDS`."""
    if kind not in KINDS:
        raise ConfigError(f"unknown config kind {kind!r}; choose from {', '.join(KINDS)}")
    out = KINDS[kind][1]()
    out["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    out["title"] = out.get("title", kind)
    return out


def schema_text(kind: str) -> str:
    """The JSON Schema of ``kind`` as the text ``pyomo-heli schema KIND`` prints (and schemas/ holds)."""
    import json

    return json.dumps(schema(kind), indent=2) + "\n"


def write_schemas(folder) -> list:
    """Write every kind's schema to ``folder/<kind>.schema.json`` (``pyomo-heli schema --out-dir schemas``)."""
    from pathlib import Path

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    for kind in KINDS:
        path = folder / f"{kind}.schema.json"
        path.write_text(schema_text(kind), encoding="utf-8")
        out.append(path)
    return out
