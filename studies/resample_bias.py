"""How much of the time-domain estimate's error is the resampling of the records? Anchor A without noise.

    python studies/resample_bias.py --out results/resample_bias [--grids 25:2,25:3,50:2,25:2:project]
                                    [--variants no_noise,bundled]

The study configs fit the 50 Hz records at 25 Hz (``[data] resample_hz = 25``: every 2nd sample of the
outputs *and of the inputs*; between samples the inputs are linear, in the NLP as in the float
simulation). On the flight test of ``data/bo105_synthetic.toml`` without noise (``[sensors] noise =
false``: exact samples of the truth simulator, no filter; ``--variants bundled`` adds the noisy one) it
solves the time-domain anchor A (min J_time) of ``studies/close_loop.toml`` (Case 2 parameters) with M0 plus
the truth simulator's own wake effect, i.e. the model of exactly the right form
(``studies/input_noise_check.py``), on each grid ``RATE:NCP`` (``resample_hz`` and Radau points per sample
interval; a third field ``project`` sets ``[data] resample_inputs = "project"``: the coarse input samples
whose linear interpolant is closest to the 50 Hz record instead of every 2nd sample), and prints the errors of twist, CL_alpha_HT and Iyy against truth and the fitted K_lamT (truth
1.5). With no noise and the right form, whatever error is left comes from the discretisation. Evaluation
only (reads truth.json). Each finished solve is written to ``OUT/<variant>_<rate>hz_ncp<ncp>.json`` and
reused by a rerun; the no-noise data go to ``OUT/data_<seed>_no_noise``.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "studies"))

import input_noise_check as N  # noqa: E402  (data variants and the truth-form anchor A)

from pyomo_heli.cli import main as cli_main  # noqa: E402
from pyomo_heli.report.identification import read_truth  # noqa: E402

SEED = 20261122  # the bundled flight test's seed
PARAMS = ("theta_twist", "CL_alpha_HT", "Iyy")


def grids_of(text: str) -> list[tuple[float, int, str]]:
    out = []
    for part in text.split(","):
        fields = part.split(":")
        rate, ncp, inputs = fields[0], fields[1] if len(fields) > 1 else "2", fields[2] if len(fields) > 2 else "sample"
        try:
            out.append((float(rate), int(ncp or 2), inputs or "sample"))
        except ValueError:
            raise SystemExit(f"--grids: cannot read {part!r}; give RATE:NCP[:project], e.g. 25:2,50:2,25:2:project")
        if out[-1][2] not in ("sample", "project"):
            raise SystemExit(f"--grids: {part!r}: the third field is 'project' (or 'sample', the default)")
    return out


def dataset(variant: str, out: Path) -> Path:
    if variant == "bundled":
        return ROOT / "data" / "bo105_synthetic"
    d = out / f"data_{SEED}_{variant}"
    if not (d / "truth.json").is_file():
        assert cli_main(["generate-data", "--config", str(N.data_config(variant, out)), "--seed", str(SEED),
                         "--out", str(d)]) == 0
    return d


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--grids", default="25:2,25:3,50:2,25:2:project",
                    help="RATE:NCP[:project] (resample_hz, Radau points, inputs projected)")
    ap.add_argument("--variants", default="no_noise", help="no_noise and/or bundled, comma-separated")
    a = ap.parse_args(argv)
    variants = [v for v in a.variants.split(",") if v]
    bad = [v for v in variants if v not in ("no_noise", "bundled")]
    if bad:
        raise SystemExit(f"--variants: unknown {bad}; choose no_noise, bundled")
    a.out.mkdir(parents=True, exist_ok=True)
    rows = []
    for v in variants:
        ds = dataset(v, a.out)
        truth = read_truth(ds)
        for rate, ncp, inputs in grids_of(a.grids):
            f = a.out / f"{v}_{rate:g}hz_ncp{ncp}{'' if inputs == 'sample' else '_' + inputs}.json"
            if f.is_file():
                res = json.loads(f.read_text())
            else:
                t0 = time.perf_counter()
                res = N.anchor_a(ds, overrides={"data": {"resample_hz": rate, "resample_inputs": inputs},
                                                "discretization": {"ncp": ncp}}, standard_errors=False)
                res["wall_time"] = time.perf_counter() - t0
                f.write_text(json.dumps(res, indent=1))
            p = res["parameters"]
            rows.append({"data": v, "resample_hz": rate, "ncp": ncp, "inputs": inputs, "status": res["status"],
                         **{f"{n} err %": 100 * (p[n] - truth[n]) / abs(truth[n]) for n in PARAMS},
                         "K_lamT": p.get("K_lamT"), "J_time": res["J_time"], "wall s": res.get("wall_time")})
            print(rows[-1], flush=True)
    import pandas as pd

    tab = pd.DataFrame(rows)
    tab.to_csv(a.out / "resample_bias.csv", index=False)
    print(tab.to_string(index=False, float_format=lambda x: f"{x:.4g}"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
