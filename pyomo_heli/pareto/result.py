"""The result of an identification: plain data that saves to and loads from a folder.

Files (written as each point finishes, so nothing finished is lost):
- ``front.csv``: one row per front point: index, kind (A, eps, B), epsilon,
  J_time, J_trim, every free parameter (SI), success, status, iterations,
  wall_time, setup_time, warm_start.
- ``time_domain.json``: point A (classic time-domain output error).
- ``chosen.json``: the utopia-closest front point (Eq. 11, post hoc), the
  direct Eq. 11 solve, the utopia and nadir points and the distances.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd


def _json_default(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(type(o))


def write_json(path: Path, data: dict) -> None:
    path.write_text(json.dumps(data, indent=2, sort_keys=True, default=_json_default) + "\n")


@dataclass
class IdentificationResult:
    """Front, anchors, choices and units of one identification run."""

    front: pd.DataFrame
    parameters: list  # free parameter names
    units: dict  # name -> SI unit
    utopia: tuple
    nadir: tuple
    chosen: dict
    direct: dict | None
    time_domain: dict
    info: dict = field(default_factory=dict)

    def save(self, out: str | Path) -> None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        self.front.to_csv(out / "front.csv", index=False, float_format="%.12g")
        write_json(out / "time_domain.json", self.time_domain)
        write_json(out / "chosen.json", {"chosen": self.chosen, "direct": self.direct, "utopia": list(self.utopia),
                                         "nadir": list(self.nadir), "parameters": self.parameters,
                                         "units": self.units, "info": self.info})

    @classmethod
    def load(cls, out: str | Path) -> "IdentificationResult":
        out = Path(out)
        for name in ("front.csv", "chosen.json", "time_domain.json"):
            if not (out / name).is_file():
                raise FileNotFoundError(f"{out}: no {name}; is this an identification results folder?")
        ch = json.loads((out / "chosen.json").read_text())
        return cls(front=pd.read_csv(out / "front.csv"), parameters=ch["parameters"], units=ch["units"],
                   utopia=tuple(ch["utopia"]), nadir=tuple(ch["nadir"]), chosen=ch["chosen"], direct=ch["direct"],
                   time_domain=json.loads((out / "time_domain.json").read_text()), info=ch.get("info", {}))

    def __str__(self) -> str:
        cols = ["index", "kind", "epsilon", "J_time", "J_trim"] + self.parameters + ["status", "iterations",
                                                                                     "wall_time"]
        lines = ["Pareto front (parameters in SI units):",
                 self.front[cols].to_string(index=False, float_format=lambda x: f"{x:.6g}"), "",
                 f"utopia (J_time, J_trim) = ({self.utopia[0]:.6g}, {self.utopia[1]:.6g}); "
                 f"nadir = ({self.nadir[0]:.6g}, {self.nadir[1]:.6g})"]
        if self.chosen is None:  # a sweep in which no point converged still ends with its statuses on disk
            lines.append("no front point converged: nothing chosen")
            return "\n".join(lines)
        lines.append(f"chosen (Eq. 11, post hoc): front point {self.chosen['index']}")
        rows = [("time domain (A)", self.time_domain), ("multi-objective (chosen)", self.chosen)]
        if self.direct:
            rows.append(("Eq. 11 direct", self.direct))
        lines.append(f"{'':26s}" + "".join(f"{p:>16s}" for p in self.parameters) + f"{'J_time':>14s}{'J_trim':>12s}")
        for label, d in rows:
            lines.append(f"{label:26s}" + "".join(f"{d['parameters'][p]:16.6g}" for p in self.parameters)
                         + f"{d['J_time']:14.6g}{d['J_trim']:12.6g}")
        return "\n".join(lines)
