"""What the input-path regression of the residual analysis (pyomo_heli/diagnosis/input_path.py) reports on the
held-out flight tests, with M0 at the truth parameters: its power and its description, apart from the identification.

    python studies/input_path_check.py --seeds 1 --out results/input_path
    python studies/input_path_check.py --effects none --seeds 5 --out results/input_path   # false alarms

For each held-out effect (or none) and seed (20261122 + k): the flight test of studies/held_out_effects.py (the
bundled maneuvers, trims and noise levels with that truth effect), the residual analysis of M0 at the truth's M0
parameters under studies/held_out_discovery.toml (the loop's config: input errors estimated, twist, CL_alpha_HT and
Iyy free, so their shift is allowed), and the terms it selects, with whether they match the truth's own control
error along the validation records (held_out_effects.input_path_match). One row per case in
OUT/<effect>_<seed>/row.json, a finished case is not rerun; OUT/input_path.csv and .md from every row in OUT.
Evaluation only: this script reads truth.json and the held-out module; the diagnosis does not.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without installing
sys.path.insert(0, str(Path(__file__).resolve().parent))

from held_out_effects import (CONFIG, ROOT, format_input_path, generate_case, input_path_match,  # noqa: E402
                              parse_input_path, seeds_of)
from pyomo_heli.flighttest.held_out_effects import HELD_OUT_EFFECTS  # noqa: E402
from pyomo_heli.studies.args import out_folder, positive_int  # noqa: E402
from pyomo_heli.studies.commands import exit_status  # noqa: E402


def run_case(effect: str, seed: int, out: Path, template: str) -> dict:
    from pyomo_heli.config import load_identification_config
    from pyomo_heli.diagnosis.analysis import diagnose
    from pyomo_heli.diagnosis.residuals import compute_residuals

    case = out / f"{effect}_{seed}"
    if (case / "row.json").is_file():
        return json.loads((case / "row.json").read_text())
    data = generate_case(case, template, effect, seed)
    cfg = load_identification_config(CONFIG, overrides={"data": {"dataset": str(data)}})
    truth = json.loads((data / "truth.json").read_text())["parameters"]
    d = diagnose(compute_residuals(cfg, {p.name: truth[p.name] for p in cfg.free}, label="M0 at truth"))
    ip = d.input_path
    best = min(ip["screen"], key=lambda r: r["p"], default=None)
    row = {"truth": effect, "seed": seed, "input path": format_input_path(ip["terms"]),
           "input path shape matches truth": input_path_match(effect, ip["terms"]),
           "best term not selected": (f"{best['channel']} += {best['estimate']:+.3g} x {best['signal']} "
                                      f"(p = {best['p']:.2g})" if best else "-"),
           "level": ip["level"], "scale": ip["scale"], "records": ip["records"],
           "verdict": "noise only" if d.verdict["noise_only"] else "unexplained residual"}
    (case / "row.json").write_text(json.dumps(row, indent=1))
    return row


def write_table(out: Path) -> pd.DataFrame:
    rows = [json.loads(f.read_text()) for f in sorted(out.glob("*/row.json"))]
    tab = pd.DataFrame(rows).sort_values(["truth", "seed"], kind="stable").reset_index(drop=True)
    tab.to_csv(out / "input_path.csv", index=False)
    cols = ["truth", "seed", "input path", "input path shape matches truth", "best term not selected"]
    held, none = tab[tab["truth"] != "none"], tab[tab["truth"] == "none"]
    L = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    L += ["| " + " | ".join(str(v) for v in r) + " |" for r in tab[cols].itertuples(index=False)]
    L += ["", f"held-out rows: {len(held)}; a term selected: {int((held['input path'] != 'none').sum())}; "
              f"matching the truth's control error: "
              f"{int(held['input path shape matches truth'].astype(str).str.startswith('yes').sum())}; "
              f"M0 + noise rows: {len(none)}, a term selected: {int((none['input path'] != 'none').sum())}", ""]
    (out / "input_path.md").write_text("\n".join(L))
    return tab


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--effects", nargs="+", default=sorted(HELD_OUT_EFFECTS), metavar="EFFECT",
                    help="held-out effects (or none); default all")
    ap.add_argument("--seeds", type=positive_int, default=1)
    ap.add_argument("--out", required=True)
    ap.add_argument("--rescore", action="store_true",
                    help="run nothing: re-score every row in OUT (the match column) from the terms it reports")
    a = ap.parse_args(argv)
    bad = [e for e in a.effects if e != "none" and e not in HELD_OUT_EFFECTS]
    if bad:
        ap.error(f"option --effects: unknown {', '.join(bad)}; choose from none, {', '.join(HELD_OUT_EFFECTS)}")
    out = out_folder(ap, a.out, "--out")
    out.mkdir(parents=True, exist_ok=True)
    if a.rescore:
        for f in sorted(out.glob("*/row.json")):
            row = json.loads(f.read_text())
            row["input path shape matches truth"] = input_path_match(row["truth"], parse_input_path(row["input path"]))
            f.write_text(json.dumps(row, indent=1))
        write_table(out)
        return 0
    template = (ROOT / "data" / "bo105_synthetic.toml").read_text()
    for effect in a.effects:
        for seed in seeds_of(0, a.seeds):
            row = run_case(effect, seed, out, template)
            print(f"{effect} {seed}: {row['input path']} ({row['input path shape matches truth']})", flush=True)
            write_table(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(exit_status(main, "input_path_check"))
