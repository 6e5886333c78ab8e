"""Packaging (issue 30): version, metadata, and the package data the demo needs from an installed wheel.

The default suite checks that the package data resolves through importlib.resources and that
pyproject.toml's package-data patterns cover every file of it; the slow test builds the wheel, unpacks it
alone on the path and runs ``pyomo-heli demo`` from an empty folder.
"""
import glob
import os
import subprocess
import sys
import tomllib
import zipfile
from importlib.metadata import version as installed_version
from pathlib import Path

import pytest
from packaging.requirements import Requirement

import pyomo_heli
from pyomo_heli.config import load_identification_config
from pyomo_heli.dataset import load_flight_test
from pyomo_heli.resources import bundled_flight_test, demo_config

ROOT = Path(__file__).resolve().parent.parent
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())
PKG = ROOT / "pyomo_heli"


def _package_data_files() -> set:
    """Files under pyomo_heli/data as setuptools' package-data globs select them (symlinks followed)."""
    out = set()
    for pattern in PYPROJECT["tool"]["setuptools"]["package-data"]["pyomo_heli"]:
        for f in glob.glob(pattern, root_dir=PKG, recursive=True):
            if (PKG / f).is_file():
                out.add(f)
    return out


def test_version_has_one_source_and_the_cli_prints_it():
    assert PYPROJECT["project"]["dynamic"] == ["version"]
    assert "version" not in PYPROJECT["project"]
    assert PYPROJECT["tool"]["setuptools"]["dynamic"]["version"] == {"attr": "pyomo_heli._version.__version__"}
    proc = subprocess.run([sys.executable, "-m", "pyomo_heli", "--version"], capture_output=True, text=True,
                          cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert proc.returncode == 0 and proc.stdout.strip() == f"pyomo-heli {pyomo_heli.__version__}"


def test_metadata_license_python_and_ranges():
    proj = PYPROJECT["project"]
    assert proj["requires-python"] == ">=3.11"  # tomllib
    assert proj["license"] == "BSD-3-Clause" and proj["license-files"] == ["LICENSE"]
    assert "BSD 3-Clause License" in (ROOT / "LICENSE").read_text()
    assert (PKG / "py.typed").is_file() and "py.typed" in PYPROJECT["tool"]["setuptools"]["package-data"]["pyomo_heli"]
    assert proj["keywords"] and "Typing :: Typed" in proj["classifiers"]
    assert not any(c.startswith("License ::") for c in proj["classifiers"])  # PEP 639: the expression only
    for text in proj["dependencies"]:
        req = Requirement(text)
        specs = {s.operator for s in req.specifier}
        assert "==" not in specs and ">=" in specs and "<" in specs, f"{text}: give a compatible range"
        # the environment the committed numbers come from lies inside the range
        assert req.specifier.contains(installed_version(req.name), prereleases=True), \
            f"installed {req.name} {installed_version(req.name)} is outside {text}"


def test_package_data_resolves_and_is_the_repositorys():
    cfg = load_identification_config(demo_config())
    assert cfg.dataset == bundled_flight_test()
    # one copy in the repository: the package data are the files configs and tests use
    assert bundled_flight_test() == (ROOT / "data" / "bo105_synthetic").resolve()
    link = PKG / "data" / "case1.toml"  # in the source tree a link to the repository's Case 1 config
    assert link.is_symlink() and demo_config() == link.resolve() and link.resolve().parent != link.parent
    ft = load_flight_test(bundled_flight_test())
    assert len(ft.identification()) == 10 and len(ft.maneuvers) == 26  # + 12 validation, 4 frequency sweeps
    # the demo's dataset path, relative to the config, also holds next to the packaged copy of the config
    assert (PKG / "data" / cfg.raw["data"]["dataset"]).resolve() == bundled_flight_test()


def test_package_data_patterns_cover_every_file():
    data_files = {str(Path(d, f).relative_to(PKG)) for d, _, fs in os.walk(PKG / "data", followlinks=True) for f in fs}
    assert "data/bo105_synthetic/manifest.json" in data_files and "data/case1.toml" in data_files
    assert len(data_files) == 1 + sum(1 for p in bundled_flight_test().rglob("*") if p.is_file())
    assert data_files <= _package_data_files()


@pytest.mark.slow
def test_wheel_runs_the_demo_from_an_empty_folder(tmp_path):
    """pip builds the wheel (setuptools from PyPI); unpacked alone on the path, `demo` runs anywhere."""
    wheels = tmp_path / "wheels"
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(wheels), str(ROOT)],
                   check=True)
    (whl,) = wheels.glob("pyomo_heli-*.whl")
    names = set(zipfile.ZipFile(whl).namelist())
    assert {"pyomo_heli/py.typed", "pyomo_heli/data/case1.toml",
            "pyomo_heli/data/bo105_synthetic/manifest.json"} <= names
    assert {f"pyomo_heli/{f}" for f in _package_data_files()} <= names
    site = tmp_path / "site"
    zipfile.ZipFile(whl).extractall(site)
    empty = tmp_path / "empty"
    empty.mkdir()
    env = {**os.environ, "PYTHONPATH": str(site), "OMP_NUM_THREADS": "1"}
    proc = subprocess.run([sys.executable, "-c", "import pyomo_heli.resources as r; print(r.demo_config())"],
                          cwd=empty, env=env, capture_output=True, text=True, check=True)
    assert Path(proc.stdout.strip()).is_relative_to(site)
    proc = subprocess.run([sys.executable, "-m", "pyomo_heli", "demo"], cwd=empty, env=env, capture_output=True,
                          text=True)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert (empty / "demo_out" / "chosen.json").is_file() and (empty / "demo_out" / "report.md").is_file()
