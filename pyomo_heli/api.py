"""The Python API: configs, identification, results and flight tests without the command line.

A thin layer over the modules the command line uses (docs/api.md)::

    import pyomo_heli as ph

    cfg = ph.load_config("studies/case1.toml")          # or a dict of the TOML's tables
    res = ph.identify(cfg, out="results/case1")          # Pareto front, choice, standard errors
    res.estimates()                                      # DataFrame, display units, with standard errors
    res = ph.load_results("results/case1")               # the same from disk

Values inside are SI; :meth:`Results.estimates` converts to each parameter's display unit (e.g. deg/m for
the blade twist), labelled in its ``unit`` column.
"""
from __future__ import annotations

import math
import tempfile
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from .config import ConfigError, IdentificationConfig, load_identification_config
from .dataset import FlightTest, load_flight_test, write_flight_test
from .pareto.result import IdentificationResult

__all__ = ["ConfigError", "FlightTest", "Results", "identify", "load_config", "load_flight_test", "load_results",
           "write_flight_test"]

#: the estimates a results folder holds: label -> attribute of IdentificationResult
POINTS = {"A": "time_domain", "C": "chosen", "direct": "direct"}


def load_config(path_or_dict, base_dir: str | Path | None = None) -> IdentificationConfig:
    """An identification config from a TOML file or from a dict of its tables (checked the same way).

    For a dict, relative paths (``[data] dataset``) are relative to ``base_dir`` (default: the current
    folder), and messages name the config ``<dict config>``. ConfigError names the table and field at fault.
    """
    if isinstance(path_or_dict, IdentificationConfig):
        return path_or_dict
    if isinstance(path_or_dict, dict):
        base = Path.cwd() if base_dir is None else Path(base_dir)
        return load_identification_config(base / "<dict config>", raw=path_or_dict)
    if isinstance(path_or_dict, (str, Path)):
        return load_identification_config(path_or_dict)
    raise TypeError(f"load_config takes a path or a dict, got {type(path_or_dict).__name__}")


@dataclass
class Results:
    """An identification results folder: the front, the estimates A, C and the direct Eq. 11 solve.

    ``result`` is the :class:`~pyomo_heli.pareto.result.IdentificationResult` (SI); ``folder`` where it is.
    """

    result: IdentificationResult
    folder: Path

    @property
    def front(self) -> pd.DataFrame:
        """The Pareto front (front.csv), one row per point, parameters in SI."""
        return self.result.front

    @property
    def parameters(self) -> list:
        return list(self.result.parameters)

    def _display(self, name: str) -> tuple[str, float]:
        """(unit, SI -> display factor) of a free parameter, candidate strengths of a closed loop included."""
        from .physics.model import HelicopterModel

        model = HelicopterModel()
        if name not in model.parameters:
            from .diagnosis.candidates import model_with_candidates

            model = model_with_candidates(model, self.result.info.get("extensions", []))
        spec = model.parameters.spec(name)
        return spec.display if spec.display is not None else (spec.unit, 1.0)

    def estimates(self) -> pd.DataFrame:
        """One row per estimate and parameter, in display units.

        Columns: ``point`` (A: time-domain anchor; C: chosen front point; direct: the direct Eq. 11
        solve), ``parameter``, ``unit``, ``estimate``, ``standard_error`` (Cramer-Rao, one sigma; NaN
        where the folder has none, e.g. ``uncertainty="none"``, or the parameter is at a bound),
        ``relative_se_percent``, ``at_bound`` ("", "lower" or "upper"), ``J_time``, ``J_trim``, and the solve's
        ``success`` and ``status`` (a point whose solve did not converge, e.g. a failed direct solve, keeps its last
        iterate as ``estimate``: not an estimate to use).
        """
        rows = []
        for label, attr in POINTS.items():
            point = getattr(self.result, attr)
            if not point or not point.get("parameters"):
                continue
            unc = point.get("uncertainty") or {}
            for n in self.parameters:
                unit, f = self._display(n)
                v = float(point["parameters"][n])
                se = (unc.get("se") or {}).get(n)
                se = float("nan") if se is None or not math.isfinite(se) else float(se)
                rows.append({"point": label, "parameter": n, "unit": unit, "estimate": v * f,
                             "standard_error": se * abs(f),
                             "relative_se_percent": 100 * se / abs(v) if v != 0 else float("nan"),
                             "at_bound": (unc.get("at_bound") or {}).get(n, ""),
                             "J_time": point.get("J_time"), "J_trim": point.get("J_trim"),
                             "success": bool(point.get("success", True)), "status": point.get("status", "")})
        return pd.DataFrame(rows, columns=["point", "parameter", "unit", "estimate", "standard_error",
                                           "relative_se_percent", "at_bound", "J_time", "J_trim", "success",
                                           "status"])

    def __str__(self) -> str:
        return str(self.result)


def load_results(folder: str | Path) -> Results:
    """A results folder of ``identify`` (``pyomo-heli identify --out FOLDER`` or :func:`identify`)."""
    return Results(IdentificationResult.load(folder), Path(folder))


def identify(config, out: str | Path | None = None, *, uncertainty: str = "all", report: bool = False,
             restart: bool = False, progress=None) -> Results:
    """Run the multi-objective identification of a config (path, dict or IdentificationConfig).

    out: results folder (as ``pyomo-heli identify --out``); None: a new temporary folder (``Results.folder``).
    A folder holding finished points of the same config is resumed; ``restart`` discards them.
    uncertainty: "all" (standard errors of every front point), "chosen" (A, C and the direct solve) or "none".
    report: also write the figures and report.md, as the command line does.
    progress: a function taking one line of text (default: the package logger "pyomo_heli", docs/running.md).
    """
    if uncertainty not in ("all", "chosen", "none"):
        raise ValueError(f"uncertainty must be 'all', 'chosen' or 'none', got {uncertainty!r}")
    from .workflows.identify import run_identification

    cfg = load_config(config)
    if "linear" in cfg.objectives:
        raise ValueError(f"{cfg.path}: identify() returns two-objective results; a config with [objectives] "
                         f"use = [..., \"linear\"] runs through `pyomo-heli identify`")
    folder = Path(tempfile.mkdtemp(prefix="pyomo_heli_identify_")) if out is None else Path(out)
    kwargs = {} if progress is None else {"progress": progress}
    result = run_identification(cfg, folder, restart=restart, uncertainty=uncertainty, **kwargs)
    if report and result.chosen is not None:
        from .report.identification import write_report

        write_report(folder, cfg)
    return Results(result, folder)
