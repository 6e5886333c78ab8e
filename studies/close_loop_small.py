"""The closed loop on the small wake instance of tests/test_close_loop.py, with its before/after table.

    python studies/close_loop_small.py --out results/small_wake [--instance wake|test] [--seed 25]
                                       [--input-reference 1.9] [--points 3]

``--instance wake``: the instance of test_wake_on_tail_is_picked_first_and_the_errors_fall (2 s lead-in,
6 s records); ``test``: the other close-loop tests' maneuvers (1 s lead-in, 5 s records). Truth = M0 + E1 at
K_lamT 1.5 + sensor noise, free twist, CL_alpha_HT, Iyy, one added effect. An existing ``OUT/loop/loop.json``
is tabulated without rerunning. Evaluation only: the table reads the generated truth.json.

Printed: the decisions, the pooled trim RMS change, the validation RMS change per output (data minus model)
and the validation RMS of model minus the truth simulator replayed the same way (the model error without the
sensor noise), and the errors of twist, CL_alpha_HT and Iyy against truth at the diagnosed point.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))

import test_close_loop as T  # noqa: E402  (the instances are defined with the tests)

from pyomo_heli.cli import main as cli_main  # noqa: E402
from pyomo_heli.config import load_identification_config  # noqa: E402
from pyomo_heli.units import DEG  # noqa: E402

WAKE = "[truth.effects.wake_on_tail]\nK_lamT = 1.5\nd_t = 1.8\ns_w = 0.5\n"


def table(out: Path) -> None:
    cfg = load_identification_config(out / "ident.toml")
    doc = json.loads((out / "loop" / "loop.json").read_text())
    truth = json.loads((out / "data" / "truth.json").read_text())["parameters"]
    its = doc["iterations"]
    for it in its:
        a = it["attribution"]
        top = sorted(a["scores"], key=lambda r: -r["LM"])[:2] if a else []
        print(f"iteration {it['iteration']} (M0{''.join(' + ' + n for n in it['extensions'])}): decision "
              f"{a and a['decision']} {a and a['accepted'] or ''}; top LM "
              + ", ".join(f"{r['name']} {r['LM']:.1f}" for r in top) + f"; threshold {a and a['threshold']:.3g}")
    i0, i1 = its[0], its[-1]
    pooled = [T._pooled_trim(i["trim_rms"]) for i in (i0, i1)]
    print("trim RMS [deg]: " + ", ".join(f"{c} {i0['trim_rms'][c] / DEG:.3f} -> {i1['trim_rms'][c] / DEG:.3f}"
                                         for c in ("col", "lon", "theta"))
          + f"; pooled {pooled[0] / DEG:.3f} -> {pooled[1] / DEG:.3f} ({100 * (pooled[1] / pooled[0] - 1):+.1f} %)")
    print("validation RMS change, data minus model: "
          + ", ".join(f"{o} {100 * (i1['validation_rms'][o] / i0['validation_rms'][o] - 1):+.1f} %"
                      for o in i0["validation_rms"]))
    model_err, truth_rms = T._truth_replay_errors(cfg, doc)
    print("validation RMS change, model minus truth replay: "
          + ", ".join(f"{o} {100 * (model_err[-1][o] / model_err[0][o] - 1):+.1f} %" for o in model_err[0]))
    print("validation RMS of the truth model itself vs iteration 0 / last: "
          + ", ".join(f"{o} {truth_rms[o]:.4g} / {i0['validation_rms'][o]:.4g} / {i1['validation_rms'][o]:.4g}"
                      for o in truth_rms) + " (SI)")
    for n in ("theta_twist", "CL_alpha_HT", "Iyy"):
        e = [100 * (i["parameters"][n] - truth[n]) / abs(truth[n]) for i in (i0, i1)]
        print(f"{n}: truth {truth[n]:.6g}, iteration 0 {i0['parameters'][n]:.6g} ({e[0]:+.2f} %), "
              f"last {i1['parameters'][n]:.6g} ({e[1]:+.2f} %)")
    if "k_wt" in i1["parameters"]:
        print(f"k_wt {i1['parameters']['k_wt']:.4f}")
    for it in its:
        if it.get("shape_selection"):
            print(f"iteration {it['iteration']} shape rule: {it['shape_selection']['decision']}; held at "
                  f"{it['shape_parameters']}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True, type=Path)
    ap.add_argument("--instance", choices=("wake", "test"), default="wake")
    ap.add_argument("--seed", type=int, default=25)
    ap.add_argument("--input-reference", type=float, default=None,
                    help="[data] input_reference_s (default 1.9 for wake, 0 for test)")
    ap.add_argument("--points", type=int, default=3)
    a = ap.parse_args()
    ref = a.input_reference if a.input_reference is not None else (1.9 if a.instance == "wake" else 0.0)
    if not (a.out / "loop" / "loop.json").is_file():
        t0 = time.perf_counter()
        cfg = T.make_case(a.out, WAKE, seed=a.seed, points=a.points, loop="\n[loop]\nmax_iterations = 1\n",
                          maneuvers=T.WAKE_MANEUVERS if a.instance == "wake" else T.MANEUVERS,
                          input_reference_s=ref, resample_inputs="sample")  # as its documented numbers were made
        assert cli_main(["close-loop", str(cfg.path), "--out", str(a.out / "loop")]) == 0
        print(f"wall time {time.perf_counter() - t0:.0f} s")
    table(a.out)


if __name__ == "__main__":
    main()
