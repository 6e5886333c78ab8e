"""The package's imports point down: every module imports only from its own layer or the layers below.

The layers, lowest first (a top-level module or subpackage of pyomo_heli per name):

0. vocabulary and process plumbing (standard library only): ``_version``, ``units``, ``channels``,
   ``tomlfile``, ``resources``, ``interrupts``, ``ioerrors``, ``log`` (logging, progress, provenance),
   ``parallel`` (tasks on Dask)
1. ``physics``: the model's equations
1a. ``settings``: the declarations of every settings file (pydantic tables); below everything that reads one
2. ``simulation``, ``dataset``, ``solvers``: the float model in time, the data files, the NLP solvers
3. ``nlp``: the Pyomo problem
4. ``pareto``: the fronts and their results
5. ``diagnosis``: residuals, tests and the candidate effects
6. ``config``, ``linear_settings``: the settings files read into the objects above (the
   identification config names candidate effects of the diagnosis as model extensions)
7. ``uncertainty``: Cramer-Rao bounds and Monte Carlo (whose spawned workers rebuild the problem
   from its config file)
8. ``flighttest``: the synthetic flight-test generator, with the truth effects; nothing of the
   analysis below may import it (the truth must not reach the identification or the diagnosis)
9. ``report``: figures and tables of results; it formats, it runs nothing above it
10. ``workflows``: ``identify``, ``identify_linear``, ``close_loop``, ``trim_loop``, ``multistart``, ``benchmark``
11. the front doors: ``cli``, ``__main__``, the Python ``api`` and the package's ``__init__`` (it
    re-exports the API and registers the Pyomo solver plugin)
12. ``studies``: the reusable studies run by ``studies/*.py`` (they drive the command line and the workflows)

Every import counts, also those inside functions; only imports under ``if TYPE_CHECKING:``
(annotations, never executed) are exempt.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "pyomo_heli"

LAYERS = [
    {"_version", "units", "channels", "tomlfile", "resources", "interrupts", "ioerrors", "log", "parallel"},
    {"physics"},
    {"settings"},
    {"simulation", "dataset", "solvers"},
    {"nlp"},
    {"pareto"},
    {"diagnosis"},
    {"config", "linear_settings", "provenance"},
    {"uncertainty"},
    {"flighttest"},
    {"report"},
    {"workflows"},
    {"cli", "__main__", "api", ""},
    {"studies"},
]
LAYER_OF = {name: k for k, names in enumerate(LAYERS) for name in names}


def _modules() -> list[tuple[str, Path]]:
    out = []
    for f in sorted(PACKAGE.rglob("*.py")):
        parts = list(f.relative_to(PACKAGE.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out.append((".".join(parts), f))
    return out


def _is_package(dotted: str) -> bool:
    return (PACKAGE.parent / Path(*dotted.split("."))).is_dir()


def _exists(dotted: str) -> bool:
    p = PACKAGE.parent / Path(*dotted.split("."))
    return p.is_dir() or p.with_suffix(".py").is_file()


def _type_checking_nodes(tree: ast.AST) -> set[int]:
    """ids of the import nodes under ``if TYPE_CHECKING:``."""
    skip = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If):
            test = node.test
            name = test.id if isinstance(test, ast.Name) else test.attr if isinstance(test, ast.Attribute) else None
            if name == "TYPE_CHECKING":
                skip |= {id(n) for stmt in node.body for n in ast.walk(stmt)}
    return skip


def imports_of(module: str, path: Path) -> list[tuple[int, str]]:
    """(line, imported pyomo_heli module) of every import in a module, function-level ones included."""
    tree = ast.parse(path.read_text(), filename=str(path))
    skip = _type_checking_nodes(tree)
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    out = []
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names if a.name.split(".")[0] == "pyomo_heli"]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.split(".")[0] != "pyomo_heli":
                continue
            subs = [f"{target}.{a.name}" for a in node.names if _is_package(target) and _exists(f"{target}.{a.name}")]
            out += [(node.lineno, t) for t in subs] or [(node.lineno, target)]
    return out


def layer(dotted: str) -> int:
    parts = dotted.split(".")
    return LAYER_OF[parts[1] if len(parts) > 1 else ""]


def test_every_module_has_a_layer():
    unknown = sorted({m.split(".")[1] for m, _ in _modules() if "." in m} - set(LAYER_OF))
    assert not unknown, f"give these a layer in {Path(__file__).name}: {unknown}"


def test_imports_point_down():
    upward = []
    for module, path in _modules():
        own = layer(module)
        for line, target in imports_of(module, path):
            if layer(target) > own:
                upward.append(f"{path.relative_to(PACKAGE.parent)}:{line} imports {target} "
                              f"(layer {layer(target)} above {own})")
    assert not upward, "imports that point up:\n" + "\n".join(upward)


@pytest.mark.parametrize("source, expected", [
    # a relative import, resolved
    ("from ..workflows.identify import build_problem\n", ["pyomo_heli.workflows.identify"]),
    ("def f():\n    from pyomo_heli.workflows.close_loop import load_loop\n",
     ["pyomo_heli.workflows.close_loop"]),  # in a function
    ("from .. import report\n", ["pyomo_heli.report"]),  # a subpackage named in the import list
    ("from .. import __version__\n", ["pyomo_heli"]),  # a name of the package itself
    ("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from ..config import X\n", []),  # annotation only
])
def test_the_checker_sees_every_kind_of_import(tmp_path, source, expected):
    """The checker itself: relative, function-level and package-level imports are found."""
    f = tmp_path / "mod.py"
    f.write_text(source)
    assert [t for _, t in imports_of("pyomo_heli.nlp.mod", f)] == expected
