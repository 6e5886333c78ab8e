"""The machinery every settings table shares: the one error type, the base table and the error wording.

A config file is checked in one pass: pydantic validates every table against its declaration and collects
every error; :func:`validate` turns them into one line each, in the form ``file [table]: field 'x' ...``.
Cross-field rules (those that compare two fields or look at the data) stay as code in the loaders; they
add their lines to the same :class:`Problems` list, so a file with several mistakes names all of them.
"""
from __future__ import annotations

from typing import Any, ClassVar

from pydantic import BaseModel, ConfigDict, ValidationError, ValidationInfo
from pydantic_core import PydanticCustomError

#: the error type of a custom check whose message is complete (everything after "file [table]: ")
CUSTOM = "config"


class ConfigError(ValueError):
    """A bad settings file (identification, generator, trim-loop config): one line per error, each naming the
    file, the table and the field. ``problems``: the lines."""

    def __init__(self, message: str, problems: list[str] | None = None):
        super().__init__(message)
        self.problems = list(problems) if problems else [message]


class Table(BaseModel):
    """A TOML table: strict types (a TOML string is never a number, a bool never an integer), unknown keys
    refused. Class variables set the wording of the table's messages (kept as the loaders wrote them)."""

    model_config = ConfigDict(extra="forbid", strict=True, frozen=True, populate_by_name=True)

    #: how a message names a field: "field 'x'" or "key 'x'"
    word: ClassVar[str] = "field"
    #: the wording of an unknown key: "keys" ("unknown key(s) a, b; use ..."), "fields" ("unknown field(s)
    #: ['a']; expected [...]"), "tables" ("unknown table(s) [...]"), or one line per key: "key" ("unknown key 'a';
    #: recognised keys: ..."), "key-use" ("unknown key 'a'; use ..."), "channel" ("unknown channel 'a'; use ...")
    unknown_style: ClassVar[str] = "keys"
    #: the words of a bool type error
    bool_words: ClassVar[str] = "bool"
    #: the words of a number's type error ("a number" or "a finite number")
    number_words: ClassVar[str] = "a number"
    #: field -> the message (after "file [table]: ") of any error of the field, or a pair (message of a wrong
    #: type or None, message of a value outside the field's domain); ``{v!r}`` is the value, ``{name}`` the field.
    #: "" -> the message when the table itself is not a table
    messages: ClassVar[dict[str, object]] = {}


def fail(info: ValidationInfo | None, message: str):
    """Raise a check's error with ``message`` complete (after "file [table]: ")."""
    raise PydanticCustomError(CUSTOM, message.replace("{", "{{").replace("}", "}}"))


class Problems:
    """The error lines of one file, collected while checking it; :meth:`raise_if_any` raises them together."""

    def __init__(self, where: str, error: type[ConfigError] = ConfigError):
        self.where, self.error, self.lines = where, error, []

    def add(self, table: str | None, message: str) -> None:
        """One error of ``[table]`` (None: the file itself)."""
        if not table:
            self.lines.append(f"{self.where}: {message}")
        else:  # a table of an array of tables is written as the file writes it: [[maneuvers]] #1
            self.lines.append(f"{self.where} {table if table.startswith('[') else f'[{table}]'}: {message}")

    def add_text(self, text: str) -> None:
        """One error whose text names its table itself ("[solver] options: ...")."""
        self.lines.append(f"{self.where} {text}")

    def __bool__(self) -> bool:
        return bool(self.lines)

    def raise_if_any(self) -> None:
        if self.lines:
            lines = list(dict.fromkeys(self.lines))
            raise self.error("\n".join(lines), lines)


def validate(cls: type[Table], raw: dict, problems: Problems, table: str | None = None):
    """``raw`` checked against ``cls``: the model, or None with every error added to ``problems``.

    ``table``: the name of the table ``raw`` is in the file (None: ``raw`` is the whole file)."""
    try:
        return cls.model_validate(raw)
    except ValidationError as exc:
        for sub, line in error_lines(cls, exc.errors(), raw):
            problems.add(f"{table}.{sub}" if table and sub else table or sub, line)
        return None


def read_settings(path, cls: type[Table], error: type[ConfigError] = ConfigError) -> tuple[Table, Problems]:
    """The TOML file ``path`` checked against its declaration ``cls``: every error of its fields raised at once
    (``error``, one line each); else the validated tables and the file's :class:`Problems`, to which the loader
    adds the errors of its rules across fields before it raises them in turn."""
    from ..tomlfile import read_toml

    raw = read_toml(path, error)
    problems = Problems(str(path), error)
    s = validate(cls, raw, problems)
    problems.raise_if_any()
    return s, problems


def _sub_table(annotation) -> tuple[type[Table] | None, str]:
    """(the Table type an annotation holds, how: "" a table, "dict" a table per key, "list" a list of tables)."""
    import typing

    args = [a for a in typing.get_args(annotation) if a is not type(None)]
    if isinstance(annotation, type) and issubclass(annotation, Table):
        return annotation, ""
    origin = typing.get_origin(annotation)
    if origin is dict and len(args) == 2 and isinstance(args[1], type) and issubclass(args[1], Table):
        return args[1], "dict"
    if origin is list and args and isinstance(args[0], type) and issubclass(args[0], Table):
        return args[0], "list"
    for a in args:  # Optional[Table]
        if isinstance(a, type) and issubclass(a, Table):
            return a, ""
    return None, ""


def _got(v) -> str:
    return f", got {v!r}"


def _type_words(kind: str, cls: type[Table]) -> str | None:
    """The words of a type error (None: not a type error)."""
    return {"bool_type": cls.bool_words, "int_type": "int", "int_from_float": "int", "string_type": "str",
            "float_type": cls.number_words, "finite_number": "a finite number", "list_type": "a list",
            "dict_type": "a table", "model_type": "a table", "model_attributes_type": "a table",
            "tuple_type": "a list"}.get(kind)


#: pydantic error type -> (words, context key) of a domain error
_DOMAIN_WORDS = {"greater_than": ("> {}", "gt"), "greater_than_equal": (">= {}", "ge"), "less_than": ("< {}", "lt"),
                 "less_than_equal": ("<= {}", "le"), "literal_error": ("one of {}", "expected"),
                 "too_short": ("at least {} long", "min_length"), "too_long": ("at most {} long", "max_length")}


def _domain_words(e: dict) -> str:
    ctx = {k: f"{v:g}" if isinstance(v, float) else v for k, v in e.get("ctx", {}).items()}
    if e["type"] not in _DOMAIN_WORDS:
        return e["msg"]
    words, key = _DOMAIN_WORDS[e["type"]]
    return words.format(ctx.get(key))


def error_lines(cls: type[Table], errors: list[dict], raw) -> list[tuple[str | None, str]]:
    """(table, message) of every pydantic error, in today's wording; unknown keys of one table on one line."""
    out, unknown = [], {}
    for e in errors:
        table_cls, path, field, value, rest = cls, [], None, raw, list(e["loc"])
        # walk the location down the tables: [a.b], [[maneuvers]] #i, a key of a free table, then the field
        while rest:
            part = rest.pop(0)
            if field is None and isinstance(part, str) and part in table_cls.model_fields:
                sub, how = _sub_table(table_cls.model_fields[part].annotation)
                value = value.get(part) if isinstance(value, dict) else None
                if sub is not None and rest and how == "":
                    table_cls, path = sub, path + [part]
                    continue
                if sub is not None and how == "" and e["type"] == CUSTOM:  # the table's own check across its fields
                    table_cls, path = sub, path + [part]
                    break
                if sub is not None and rest and how in ("dict", "list"):
                    key = rest.pop(0)
                    value = value[key] if isinstance(value, (dict, list)) else None
                    if how == "dict":
                        path = path + [f"{part}.{key}"]
                    else:
                        named = (f" ('{value['name']}')" if isinstance(value, dict) and isinstance(value.get("name"),
                                                                                                    str) else "")
                        path = path + [f"[[{part}]] #{key + 1}{named}"]
                    table_cls = sub
                    continue
                field = part
                continue
            if field is None:  # an unknown key (extra_forbidden) or the table itself
                field = part
                value = value.get(part) if isinstance(value, dict) else None
                continue
            if isinstance(part, int) and isinstance(value, list) and part < len(value):  # an item of a list field
                field, value = f"{field}[{part}]", value[part]
                continue
            if isinstance(value, dict) and isinstance(part, str) and part in value:  # a key of a free table
                path, field, value = path + [field], part, value[part]
                continue
            break  # a union's branch tag: the field is named
        table = ".".join(path) if path else None
        if e["type"] == "extra_forbidden":
            unknown.setdefault((table, table_cls), []).append(field)
            continue
        for line in _message(table_cls, e, field, value, table).split("\n"):
            out.append((table, line))
    for (table, table_cls), keys in unknown.items():
        allowed = [f.alias or n for n, f in table_cls.model_fields.items()]
        style = table_cls.unknown_style
        if style == "fields":
            out.append((table, f"unknown field(s) {sorted(keys)}; expected {sorted(allowed)}"))
        elif style == "key":
            out += [(table, f"unknown key '{k}'; recognised keys: {', '.join(allowed)}") for k in keys]
        elif style == "channel":
            out += [(table, f"unknown channel '{k}'; use {', '.join(allowed)}") for k in keys]
        elif style == "key-use":
            out += [(table, f"unknown key '{k}'; use {', '.join(allowed)}") for k in keys]
        elif style == "tables":
            out.append((table, f"unknown table(s) {sorted(keys)}; expected {sorted(allowed)}"))
        else:
            out.append((table, f"unknown key(s) {', '.join(sorted(keys))}; use {', '.join(sorted(allowed))}"))
    return out


def _message(table_cls: type[Table], e: dict, field, value, table) -> str:
    t = e["type"]
    if t == CUSTOM:
        return e["msg"]
    if field is None:  # the table itself is not a table
        return table_cls.messages.get("", f"must be a table, got {value!r}")
    name = str(field)
    base = name.split("[")[0]
    if t == "missing":
        return f"missing {table_cls.word} '{name}'"
    if table is None and t in ("dict_type", "model_type", "model_attributes_type") and base == name:
        return f"'{name}' must be a table [{name}], got {value!r}"
    words = _type_words(t, table_cls)
    m = table_cls.messages.get(base)
    if isinstance(m, tuple):
        m = m[0] if words is not None else m[1]
    if m:
        return m.format(v=value, name=name)
    if words is not None:
        return f"{table_cls.word} '{name}' must be {words}{_got(value)}"
    return f"{table_cls.word} '{name}' must be {_domain_words(e)}{_got(value)}"


def names_check(values: list, info: ValidationInfo, *, choices=None, what: str = "name", allow_empty: bool = False,
                unknown: str | None = None, empty: str | None = None) -> list:
    """A list of distinct names: empty only with ``allow_empty``, each of ``choices`` if given.

    ``unknown``: the message of names not among ``choices`` (``{bad}`` the names, ``{one}`` the first, ``{field}``,
    ``{choices}``); ``empty``: the message of an empty list (``{field}``)."""
    key = info.field_name
    if not values and not allow_empty:
        fail(info, (empty or "field '{field}' is empty").format(field=key))
    dup = sorted({x for x in values if values.count(x) > 1})
    if dup:
        fail(info, f"field '{key}' names {dup} more than once")
    if choices is not None:
        bad = [x for x in values if x not in choices]
        if bad:
            fail(info, (unknown or "field '{field}': unknown {what}(s) {bad}; choose from {choices}").format(
                bad=bad, field=key, what=what, choices=", ".join(choices), one=bad[0]))
    return values


def schema_of(cls: type[BaseModel]) -> dict[str, Any]:
    """The JSON Schema of a settings file (draft 2020-12), for editors (``pyomo-heli schema``)."""
    return cls.model_json_schema(mode="validation")
