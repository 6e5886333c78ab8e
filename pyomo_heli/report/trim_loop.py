"""The report of a trim-only closed loop (``pyomo-heli trim-loop``): ``report.md`` and two figures, written
from the loop's document (``trim_loop.json``, :mod:`pyomo_heli.workflows.trim_loop`) with its dense model
curves (``doc["curves"]``)."""
from __future__ import annotations

from pathlib import Path

from ..dataset.schema import TRIM_CHANNELS
from ..physics.conventions import THETA_DATUM
from ..physics.discrepancy import is_generic

REPORT_FILE = "report.md"


def held_text(every: int) -> str:
    if not every:
        return "nothing held out"
    nth = {2: "second", 3: "third", 4: "fourth", 5: "fifth"}.get(every, f"{every}th")
    return f"every {nth} point of each channel in speed order held out"



LABELS = {"col": "collective (as recorded) [deg]", "lon": "longitudinal cyclic [deg]",
          "theta": "pitch attitude [deg]"}


def plot_trim_curves(doc: dict, curves_before: dict, curves_after: dict, path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pts = doc["points"]
    fig, axes = plt.subplots(3, 1, figsize=(7, 9), sharex=True)
    for ax, c in zip(axes, TRIM_CHANNELS):
        for role, mk, lab in (("identification", "o", "data, identification"), ("validation", "s", "data, held out")):
            sel = [i for i, (cc, r) in enumerate(zip(pts["channel"], pts["role"])) if cc == c and r == role]
            ax.plot([pts["speed_kt"][i] for i in sel], [pts["value_deg"][i] for i in sel], mk,
                    mfc="none" if role == "validation" else None, color="k", label=lab)
        ax.plot(curves_before["speed_kt"], curves_before[c], "--", color="tab:blue", label="model before (initial)")
        ax.plot(curves_after["speed_kt"], curves_after[c], "-", color="tab:red", label="model after (identified)")
        ax.set_ylabel(LABELS[c])
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    axes[-1].set_xlabel("airspeed [kt]")
    fig.suptitle(f"{doc['aircraft']}: level-flight trims, data vs model")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def plot_residuals(doc: dict, path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pts = doc["points"]
    fig, axes = plt.subplots(3, 1, figsize=(7, 8), sharex=True)
    first, last = doc["initial"]["model_deg"], doc["iterations"][doc.get("final_iteration", -1)]["model_deg"]
    for ax, c in zip(axes, TRIM_CHANNELS):
        sel = sorted((i for i, cc in enumerate(pts["channel"]) if cc == c), key=lambda i: pts["speed_kt"][i])
        v = [pts["speed_kt"][i] for i in sel]
        ax.plot(v, [pts["value_deg"][i] - first[i] for i in sel], "--o", color="tab:blue", mfc="none",
                label="before")
        ax.plot(v, [pts["value_deg"][i] - last[i] for i in sel], "-o", color="tab:red", label="after")
        held = [pts["speed_kt"][i] for i in sel if pts["role"][i] == "validation"]
        for h in held:
            ax.axvline(h, color="0.8", lw=0.8)
        ax.axhline(0.0, color="k", lw=0.8)
        ax.set_ylabel(f"data - model, {c} [deg]")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8, title="grey lines: held-out speeds", title_fontsize=7)
    axes[-1].set_xlabel("airspeed [kt]")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)



#: rows of the score table in the report with discovery (the library has tens of terms)
TOP_ROWS = 12


def write_trim_loop_report(doc: dict, config_path, out) -> Path:
    """``report.md``, ``trim_curves.png`` and ``trim_residuals.png`` in ``out`` from ``doc`` (with its curves)."""
    out = Path(out)
    plot_trim_curves(doc, doc["curves"]["before"], doc["curves"]["after"], out / "trim_curves.png")
    plot_residuals(doc, out / "trim_residuals.png")
    last = doc["iterations"][doc.get("final_iteration", -1)]
    c = doc["conventions"]
    L = [f"# Trim-only closed loop: {doc['aircraft']}", "",
         f"Config `{config_path}`, dataset `{doc['dataset']}` (relative to the config).", ""]
    if doc.get("source"):
        L += [f"Source: {doc['source']}", ""]
    L += [f"Front: {doc['front']}.", "",
          "## Conventions applied by the model's output equations", "",
          "- collective: recorded at r/R = "
          f"{c['collective_station'] if c['collective_station'] is not None else 'r_ref'}"
          f" (model col at r_ref = {c['model_r_ref']:g}); col_rec = col + (r_c - r_ref) theta_twist R",
          f"- longitudinal cyclic sign: {c['lon_sign']:+d} (+1: positive aft)",
          "- pitch-attitude datum: " + ("unknown, **estimated** (theta_datum below)" if c["theta_datum_estimated"]
                                        else f"{c['theta_datum_deg']:g} deg (declared)"),
          f"- mass {doc['mass_kg']:g} kg, air density {doc['rho_kg_m3']:g} kg/m^3 (manifest)"]
    for a in doc.get("assumptions") or []:
        L.append(f"- assumption: {a}")
    n_id, n_val = doc["counts"]["identification"], doc["counts"]["validation"]
    L += ["", "## Data", "",
          f"Trim points per channel, identification / held out ({held_text(doc['holdout_every'])}): "
          + ", ".join(f"{ch} {n_id[ch]}/{n_val[ch]}" for ch in TRIM_CHANNELS), ""]
    L += ["## Iterations", ""]
    for it in doc["iterations"]:
        L += [f"### Iteration {it['iteration']}"
              + (f" (with {', '.join(it['extensions'])})" if it["extensions"] else ""),
              "", f"J_trim = {it['solve']['J_trim']:.4g} deg^2 (Ipopt {it['solve']['status']}, "
              f"{it['solve']['iterations']} iterations; float-model check {it['J_trim_float']:.4g}); "
              f"residual sigma {it['residual_sigma_deg']:.3f} deg, "
              f"{it['dof']} degrees of freedom", "",
              "| parameter | estimate | standard error | robust SE | unit |", "|---|---|---|---|---|"]
        for n, p in it["parameters"].items():
            tag = " (convention offset)" if n == THETA_DATUM else ""
            L.append(f"| {n}{tag} | {p['shown'][0]:.5g} | {p['se_shown'][0]:.3g} | {p['se_robust_shown'][0]:.3g} | "
                     f"{p['shown'][1]} |")
        L += ["", "Standard errors: s^2 (J^T J)^-1 with one residual variance s^2 for every point; robust: the "
                  "sandwich (HC1) estimate. Both take the residuals as independent, which a structured residual "
                  "(below) is not: read them as lower bounds."]
        if it.get("rejected"):
            L += ["", f"**Rejected**: {it['rejected']}; the next iteration starts again from the model before it."]
        st = it["score_test"]
        d = st.get("discovery")  # structure determination: its decision, the library's best rows in the table
        head = (f"Score test ({st['n_testable']} {'terms' if d else 'candidates'} with a trim signature, level "
                f"{st['level']:.2g}, leverage-corrected sandwich variance)")
        L += ["", f"{head}: **{st['decision']}**: {st['message']}" if not d else
              f"{head}, structure determination over the candidates and the generic discrepancy family: "
              f"**{d['decision']}**: {d['message']}", ""]
        L += ["| candidate | LM | df | p | estimate [SI] | kept | note |", "|---|---|---|---|---|---|---|"]
        top = {r["name"] for r in [r for r in st["scores"] if r["testable"]][:TOP_ROWS]}
        shown = [r for r in st["scores"] if not d or r["name"] in top or not is_generic(r["name"])]
        for r in shown:
            if r["testable"]:
                L.append(f"| {r['name']} | {r['LM']:.3g} | {r['df']:.3g} | {r['p_value']:.2g} | {r['kappa_hat']:.3g} | "
                         f"{r['kept']:.2f} | |")
            else:
                L.append(f"| {r['name']} | - | - | - | - | - | {r['note']} |")
        if d:
            L.append("")
            L.append(f"(the {len(top)} testable terms of largest LM and every physical candidate; every row in "
                     "`trim_loop.json`)")
        L.append("")
    L += ["## RMS error, data minus model [deg]", "", "| points | channel | before | after |", "|---|---|---|---|"]
    for role in ("identification", "validation"):
        for ch in TRIM_CHANNELS:
            if ch in last["rms_deg"][role]:
                L.append(f"| {role} | {ch} | {doc['initial']['rms_deg'][role][ch]:.3f} | "
                         f"{last['rms_deg'][role][ch]:.3f} |")
    raw = doc["initial"]["rms_deg_without_conventions"]
    L += ["", "Before = the initial model with the declared conventions applied; without them (collective read as "
              "if at r_ref, no datum) the initial RMS on all identification points would be "
              + ", ".join(f"{ch} {v:.3f}" for ch, v in raw["identification"].items()) + " deg."]
    L += ["", "## Remaining residual (final model, all points)", "",
          "| channel | RMS | largest step | between [kt] | mean below / above | trend [deg/10 kt] |",
          "|---|---|---|---|---|---|"]
    def cell(x, fmt):  # a shape value the channel has not (a single point: no step, no trend): "-", not 0
        return "-" if x is None else format(x, fmt)

    for ch, s in last["residual_shape"].items():
        between = s.get("step_between_kt")  # no step with a single point of the channel
        L.append(f"| {ch} | {s['rms_deg']:.3f} | {cell(s.get('step_deg'), '+.2f')} | "
                 + (f"{between[0]:.1f}-{between[1]:.1f}" if between else "-") + " | "
                 f"{cell(s.get('mean_below_step_deg'), '+.2f')} / {cell(s.get('mean_above_step_deg'), '+.2f')} | "
                 f"{cell(s.get('trend_deg_per_10kt'), '+.3f')} |")
    d = last["score_test"].get("discovery")
    if d and not d["added"]:
        L += ["", "Nothing in the library, generic terms included, is significant on the remaining residual "
                  f"(structure determination above: {d['decision']}). Its shape per channel is in the table and in "
                  "`trim_residuals.png`; docs/real_data.md discusses the missing physics it points to."]
    elif not d and last["score_test"]["decision"] != "accepted":
        L += ["", "No candidate of the library explains the remaining residual (score test above). Its shape per "
                  "channel is in the table and in `trim_residuals.png`; a generic speed-dependent correction "
                  "(structure determination, `[loop] discovery = true`) was not offered. docs/real_data.md "
                  "discusses the missing physics the shape points to."]
    L += ["", "Not represented by the 3-DoF longitudinal model (not fitted, whatever the data hold): lateral cyclic "
              "and roll attitude (no lateral degrees of freedom), tail-rotor collective (no tail rotor), main-rotor "
              "power (no torque equation)."]
    L += ["", f"Stopped: {doc['stopped']}.", "",
          "Figures: `trim_curves.png` (data and model before/after), `trim_residuals.png` (data minus model).",
          "Every number above is in `trim_loop.json`.", ""]
    path = out / REPORT_FILE
    path.write_text("\n".join(L))
    return path
