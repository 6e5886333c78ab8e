"""Commands on the model alone (no flight test, no results folder): ``trim``, ``simulate``, ``linearize``."""
from __future__ import annotations

import json
import math

from ..units import DEG, KT
from .folders import _check_out_file
from .options import MAX_INPUT_DEG, MAX_SIM_SAMPLES, UserError, _check_speed_kt, _parse_params

def _speeds_and_model(args):
    """``--speeds-kt`` checked, ``--json`` writable, and the model with the ``--param`` overrides."""
    from ..physics.model import HelicopterModel

    for v in args.speeds_kt:
        _check_speed_kt(v, "--speeds-kt")
    if args.json:
        _check_out_file(args.json, "--json")
    return _parse_params(args.param, HelicopterModel())


def _write_json(path, records) -> None:
    with open(path, "w") as fh:
        json.dump(records, fh, indent=2)
        fh.write("\n")


def cmd_trim(args) -> int:
    from ..nlp.trim_table import trim_table

    model = _speeds_and_model(args)
    table = trim_table(model, [v * KT for v in args.speeds_kt], solver=args.solver)
    records = []
    for v_kt, row in zip(args.speeds_kt, table.to_dict("records")):
        records.append({"speed_kt": v_kt, "col_deg": row["col"] / DEG, "lon_deg": row["lon"] / DEG,
                        "theta_deg": row["theta"] / DEG, "lambda_i": row["lambda_i"],
                        "beta_0_deg": row["beta_0"] / DEG, "beta_1c_deg": row["beta_1c"] / DEG})
    head = (f"{'speed kt':>8} {'col deg':>8} {'lon deg':>8} {'theta deg':>9} {'lambda_i':>9} {'beta_0 deg':>10} "
            f"{'beta_1c deg':>11}")
    print(head)
    for r in records:
        print(f"{r['speed_kt']:8.1f} {r['col_deg']:8.3f} {r['lon_deg']:8.3f} {r['theta_deg']:9.3f} "
              f"{r['lambda_i']:9.5f} {r['beta_0_deg']:10.3f} {r['beta_1c_deg']:11.3f}")
    if args.json:
        _write_json(args.json, records)
    return 0


def cmd_simulate(args) -> int:
    import numpy as np

    from ..physics.model import HelicopterModel
    from ..simulation.inputs import InputSpecError, parse_input
    from ..simulation.integrate import simulate
    from ..simulation.trim import trim_float

    _check_speed_kt(args.speed_kt, "--speed-kt")
    # --duration, --rate, --t-start are finite and in range by their argparse types; here what ties them together
    n_samples = math.floor(args.duration * args.rate + 1e-6) + 1
    if n_samples < 2:
        raise UserError(f"--rate {args.rate:g} Hz gives fewer than 2 samples over --duration {args.duration:g} s "
                        f"(need --rate >= {1.0 / args.duration:g} Hz)")
    if n_samples > MAX_SIM_SAMPLES:
        raise UserError(f"--rate {args.rate:g} Hz over --duration {args.duration:g} s gives {n_samples:.3g} samples, "
                        f"more than {MAX_SIM_SAMPLES:,}; lower --rate or --duration")
    if args.input and args.t_start >= args.duration:
        raise UserError(f"--t-start {args.t_start:g} s: the input would start at or after the end of the record "
                        f"(--duration {args.duration:g} s) and never be applied")
    signals = []
    for text in args.input or []:
        try:
            sig = parse_input(text, t_start=args.t_start)
        except InputSpecError as exc:
            raise UserError(f"--input {text!r}: {exc}") from None
        if abs(sig.amplitude) > MAX_INPUT_DEG * DEG:
            raise UserError(f"--input {text!r}: amplitude {sig.amplitude / DEG:g} deg is outside "
                            f"+-{MAX_INPUT_DEG:g} deg (an increment on trim; larger ones leave the control travel and "
                            f"the model's small-angle, attached-flow range)")
        signals.append(sig)
    channels = [s.channel for s in signals]
    if len(set(channels)) != len(channels):
        raise UserError(f"--input: channel given twice ({', '.join(channels)})")
    if args.out:
        _check_out_file(args.out, "--out")
    model = _parse_params(args.param, HelicopterModel())
    trim = trim_float(model, args.speed_kt * KT)
    t = np.arange(n_samples) / args.rate
    df = simulate(model, trim, t, {s.channel: s for s in signals}, max_step=0.05)
    out = df.assign(t_s=df.t, col_deg=df.col / DEG, lon_deg=df.lon / DEG, q_deg_s=df.q / DEG,
                    theta_deg=df.theta / DEG, nx_g=df.n_x, nz_g=df.n_z, tas_m_s=df.TAS,
                    beta0_deg=df.beta_0 / DEG, u_m_s=df.u, w_m_s=df.w, lambda_i=df.lambda_i,
                    beta1c_deg=df.beta_1c / DEG)
    cols = ["t_s", "col_deg", "lon_deg", "q_deg_s", "theta_deg", "nx_g", "nz_g", "tas_m_s", "beta0_deg",
            "u_m_s", "w_m_s", "lambda_i", "beta1c_deg"]
    if args.out:
        out[cols].to_csv(args.out, index=False, float_format="%.10g")
        print(f"wrote {len(out)} samples of {', '.join(channels) or 'no input'} at {args.speed_kt:g} kt to {args.out}")
    else:
        print(out[cols].to_string(index=False, float_format=lambda x: f"{x:.4f}"))
    return 0


def cmd_linearize(args) -> int:
    from ..report.linearization import linearization_dict, linearization_text
    from ..simulation.linearize import linearize_float

    model = _speeds_and_model(args)
    records = []
    for v in args.speeds_kt:
        lin = linearize_float(model, v * KT)
        print(linearization_text(lin, v))
        print()
        records.append(linearization_dict(lin, v))
    if args.json:
        _write_json(args.json, records)
        print(f"wrote {args.json}")
    return 0

