"""Files shipped inside the package: the demo config and the bundled synthetic flight test.

They are package data under ``pyomo_heli/data`` and are found with :mod:`importlib.resources`, so
``pyomo-heli demo`` works from an installed wheel in any directory. In the source tree
``pyomo_heli/data/case1.toml`` and ``pyomo_heli/data/bo105_synthetic`` are symlinks to
``studies/case1.toml`` and ``data/bo105_synthetic`` (one copy of each in the repository); the wheel
holds real copies; the functions return the resolved path, so in the source tree they name
``studies/case1.toml`` and ``data/bo105_synthetic`` themselves. The demo config names its dataset as
``../data/bo105_synthetic``, which points at
the bundled flight test both from ``studies/`` and from ``pyomo_heli/data/``.
"""
from __future__ import annotations

from importlib.resources import files
from pathlib import Path

#: package-data names, relative to ``pyomo_heli/data``
DEMO_CONFIG = "case1.toml"
BUNDLED_FLIGHT_TEST = "bo105_synthetic"


def _data_path(name: str) -> Path:
    res = files("pyomo_heli").joinpath("data", name)
    path = Path(str(res)).resolve()  # in the source tree: the symlink's target (studies/..., data/...)
    if not path.exists():
        raise FileNotFoundError(f"package data pyomo_heli/data/{name} is missing from this installation "
                                f"of pyomo_heli ({path}); reinstall the package")
    return path


def demo_config() -> Path:
    """Path of the demo identification config (Case 1 of the paper: theta_twist and CL_alpha_HT)."""
    return _data_path(DEMO_CONFIG)


def bundled_flight_test() -> Path:
    """Folder of the bundled synthetic Bo-105 flight test (docs/data_format.md)."""
    return _data_path(BUNDLED_FLIGHT_TEST)
