"""Equation-level inspection of an identification NLP, without solving.

:func:`inspect_problem` builds the NLP of a config and returns a readable
report (``pyomo-heli inspect CONFIG`` prints it):

1. the data and the free parameters (SI and display units);
2. variables and constraints per block, and the degrees of freedom, counted
   here and by IDAES (``degrees_of_freedom``), which must agree;
3. the IDAES structural diagnostics (``DiagnosticsToolbox.report_structural_issues``), and the IDAES
   scaling report: the factors :class:`~pyomo_heli.nlp.scaling.IdentificationScaler` writes (per
   equation family), the rows and variables left without one, IDAES's ``report_scaling_factors`` of the
   model's top level and the variables ``badly_scaled_var_generator`` flags, unscaled and scaled;
4. the equations of one time point of the first maneuver and of its start
   trim block, first in a compact form (short names, 6 significant digits,
   with a legend), then in full (``expr.to_string()``, Pyomo's own names).

In a maneuver block the intermediates that several equations of a time
point share (rotor flow, thrust coefficient, thrust, total forces:
``blk.shared``, physics.model.SHARED) are named Expressions; the compact form
prints them by name and lists their definitions first, the full form inlines
them, which is the exact mathematics the solver sees (the NL file holds each
once, as a defined variable).
"""
from __future__ import annotations

import contextlib
import io
import re
import textwrap

import pyomo.environ as pyo
from pyomo.core.expr.symbol_map import SymbolMap
from pyomo.core.base.expression import ExpressionData
from pyomo.core.expr.visitor import _ToStringVisitor

from ..units import KT

WIDTH = 120
_NUMBER = re.compile(r"(?<![\w.@\]])(\d+\.\d*(?:[eE][-+]?\d+)?|\d+[eE][-+]?\d+)")


# ---------------------------------------------------------------- text helpers
def _wrap(text: str, indent: str = "      ", width: int = WIDTH) -> str:
    """Wrap an expression string at ~width chars, breaking at spaces, else after * / , (."""
    room = max(width - len(indent), 20)
    lines = []
    while len(text) > room:
        cut = text.rfind(" ", 0, room)
        if cut <= 0:
            cut = max(text.rfind(ch, 0, room) for ch in "*/,(") + 1
        if cut <= 0:
            cut = room
        lines.append(text[:cut].rstrip())
        text = text[cut:].lstrip()
    lines.append(text)
    return "\n".join(indent + ln for ln in lines)


def _fill(line: str, width: int = WIDTH) -> str:
    """Wrap a long prose line (equations are wrapped already), continuing indented by two more spaces."""
    if len(line) <= width:
        return line
    lead = line[: len(line) - len(line.lstrip())]
    return textwrap.fill(line.strip(), width, initial_indent=lead, subsequent_indent=lead + "  ",
                         break_on_hyphens=False, break_long_words=False)


def _round_numbers(s: str) -> str:
    return _NUMBER.sub(lambda mt: f"{float(mt.group()):.6g}", s)


def _section(title: str) -> list[str]:
    return ["", "=" * WIDTH, title, "=" * WIDTH]


class _ShortNames:
    """A Pyomo labeler giving short names relative to a home block (and one time point).

    In a maneuver block at time t: ``x[u,t] -> u``, ``dx[u,t] -> u_dot``,
    ``beta[beta_1c,t] -> beta_1c``, ``du[col,t] -> du_col``, ``y[n_z,t] -> y_n_z``;
    other times get ``@time``; trim-block components get ``_trim``; model-level
    components (``theta_s[...]``) keep their names. ``legend`` records label -> full name.
    """

    RENAME = {"x": "{}", "dx": "{}_dot", "beta": "{}", "du": "du_{}", "y": "y_{}", "shared": "{}"}

    def __init__(self, model, home, t=None):
        self.model, self.home, self.t = model, home, t
        self.legend: dict[str, str] = {}

    def _label(self, obj) -> str:
        comp = obj.parent_component()
        blk = comp.parent_block()
        idx = obj.index()
        idx = idx if isinstance(idx, tuple) else (() if idx is None else (idx,))
        suffix = ""
        if self.t is not None and idx and isinstance(idx[-1], float) and blk is self.home:
            if idx[-1] != self.t:
                suffix = f"@{idx[-1]:.6g}"
            idx = idx[:-1]
        name = comp.local_name
        if blk is self.model:
            return obj.name
        if name in self.RENAME and len(idx) == 1 and blk is self.home and self.t is not None:
            base = self.RENAME[name].format(idx[0])
        else:
            base = name + (f"[{','.join(str(i) for i in idx)}]" if idx else "")
        if blk is self.home:
            return base + suffix
        if blk.parent_component() is getattr(self.model, "trim", None):
            return base + "_trim"
        return obj.name

    def __call__(self, obj) -> str:
        label = self._label(obj)
        if self.legend.get(label, obj.name) != obj.name:  # never two objects under one label
            label = obj.name
        self.legend[label] = obj.name
        return label


class _KeepNamed(_ToStringVisitor):
    """Pyomo's to-string visitor that prints a named Expression by its label and records it."""

    def __init__(self, smap):
        super().__init__(verbose=False, smap=smap)
        self.named: list = []

    def visiting_potential_leaf(self, node):
        if isinstance(node, ExpressionData):
            if all(node is not e for e in self.named):
                self.named.append(node)
            return True, self.smap.getSymbol(node)
        return super().visiting_potential_leaf(node)


def _equations(model, home, constraints, t=None) -> list[str]:
    """Compact form of each constraint (named intermediates first, with legend), then the full to_string() form."""
    names = _ShortNames(model, home, t)
    smap = SymbolMap(names)

    def compact(expr) -> tuple[str, list]:
        visitor = _KeepNamed(smap)
        return _round_numbers(visitor.dfs_postorder_stack(expr)), visitor.named

    rows, used = [], []
    for c in constraints:
        text, named = compact(c.expr)
        rows.append((c.local_name if c.parent_block() is home else c.name, text))
        used += named
    defs, seen = [], set()

    def define(e) -> None:  # depth first: an intermediate is listed after those it uses
        if id(e) in seen:
            return
        seen.add(id(e))
        text, named = compact(e.expr)
        for d in named:
            define(d)
        defs.append((smap.getSymbol(e), text))

    for e in used:
        define(e)
    out = ["compact form (short names, numbers to 6 significant digits):"]
    if defs:
        out.append("  named intermediates (each defined once, used by the equations below):")
        out += [_wrap(f"{label} := {text}", indent="    ") for label, text in defs]
    for label, s in rows:
        out += [f"  {label}:", _wrap(s)]
    out += ["", "legend (short name = Pyomo component):"]
    for label, full in sorted(names.legend.items(), key=lambda kv: kv[0].lower()):
        if label != full:
            out.append(f"  {label:<24} = {full}")
    if any(full.startswith("theta_s[") for full in names.legend.values()):
        out.append(f"  {'theta_s[p]':<24} = scaled free parameter p: physical p = theta_scale[p] * theta_s[p] (see 4d)")
    out += ["", "full form (constraint.expr.to_string(), exactly as built):"]
    for c in constraints:
        out += [f"  {c.name}:", _wrap(c.expr.to_string())]
    return out


# ---------------------------------------------------------------- counting
def _count(vars_, cons) -> dict:
    vars_, cons = list(vars_), list(cons)
    free = sum(1 for v in vars_ if not v.fixed)
    active = [c for c in cons if c.active]
    eq = sum(1 for c in active if c.equality)
    return {"vars": len(vars_), "free": free, "fixed": len(vars_) - free, "eq": eq,
            "ineq": len(active) - eq, "inactive": len(cons) - len(active)}


def _block_rows(m) -> list[tuple[str, dict]]:
    rows = []
    theta = list(m.theta_s.values()) if hasattr(m, "theta_s") else []
    rows.append(("params (theta_s)", _count(theta, [])))
    speeds = list(m.trim_speeds) if hasattr(m, "trim") else []
    for i in speeds:
        blk = m.trim[i]
        rows.append((f"{f'trim[{i}]':<9}{pyo.value(blk.V_target) / KT:6.1f} kt",
                     _count(blk.component_data_objects(pyo.Var, descend_into=True),
                            blk.component_data_objects(pyo.Constraint, descend_into=True))))
    for name in (m.maneuver_names if hasattr(m, "man") else []):
        blk = m.man[name]
        rows.append((f"man[{name}]", _count(blk.component_data_objects(pyo.Var, descend_into=True),
                                             blk.component_data_objects(pyo.Constraint, descend_into=True))))
    theta_ids = {id(v) for v in theta}
    rows.append(("objective (L, cholesky, eps_con)",
                 _count((v for v in m.component_data_objects(pyo.Var, descend_into=False) if id(v) not in theta_ids),
                        m.component_data_objects(pyo.Constraint, descend_into=False))))
    return rows


def _table(rows, total) -> list[str]:
    head = (f"{'block':<34} {'vars':>7} {'free':>7} {'fixed':>6} {'eq':>7} {'ineq':>5} {'free-eq':>8}")
    out = [head, "-" * len(head)]
    for label, c in rows + [("TOTAL", total)]:
        if label == "TOTAL":
            out.append("-" * len(head))
        extra = f"  ({c['inactive']} deactivated)" if c["inactive"] else ""
        out.append(f"{label:<34} {c['vars']:>7} {c['free']:>7} {c['fixed']:>6} {c['eq']:>7} {c['ineq']:>5} "
                   f"{c['free'] - c['eq']:>8}{extra}")
    return out


# ---------------------------------------------------------------- sections
def _header(cfg, m, data) -> list[str]:
    opts = m.options
    out = ["identification NLP (built, not solved)", f"config:   {cfg.path}", f"dataset:  {cfg.dataset}",
           f"outputs:  time {', '.join(opts.time_outputs) or '-'}; trim {', '.join(opts.trim_outputs) or '-'}; "
           + (f"covariance {opts.covariance}" if not opts.input_errors else
              f"input errors {', '.join(opts.input_errors)} (noise sigmas "
              f"{'given' if opts.noise_sigma is not None else 'from the lead-in'}"
              + (f"; AR({opts.input_error_ar}) errors" if opts.input_error_ar else "")
              + ("; each record's reference error" if opts.input_reference_error else "")
              + (f"; AR({opts.output_error_ar}) output noise" if opts.output_error_ar else "") + ")")
           + f"; collocation {opts.scheme}, ncp={opts.ncp}"
           + (f"; resample {cfg.resample_hz:g} Hz" if cfg.resample_hz else "")
           + (f"; max duration {cfg.max_duration:g} s" if cfg.max_duration else ""),
           *([f"noise sigmas ({m.noise_sigma_source}, SI: rad, rad/s, g, m/s): "
              + ", ".join(f"{k} {pyo.value(v):.4g}" for k, v in m.noise_sigma.items())]
             if m.component("noise_sigma") is not None else []),
           "", f"maneuvers ({len(data.maneuvers)}):",
           f"  {'name':<24} {'samples':>7} {'duration s':>10} {'start trim kt':>13}"]
    for mv in data.maneuvers:
        t = mv.data["t"]
        out.append(f"  {mv.name:<24} {len(t):>7} {float(t.iloc[-1] - t.iloc[0]):>10.3f} {mv.trim_speed / KT:>13.1f}")
    speeds = ", ".join(f"{v / KT:.0f}" for v in data.speeds)
    out += [f"trim points: {len(data.trims)} data rows; {len(data.speeds)} trim blocks at {speeds} kt"]
    out += ["", f"free parameters ({len(cfg.free)}):",
            f"  {'name':<14} {'initial':>11} {'lower':>11} {'upper':>11} {'scale':>9}  {'SI unit':<7}| "
            f"{'initial':>10} {'lower':>10} {'upper':>10}  display unit"]
    for f in cfg.free:
        spec = cfg.model.parameters.spec(f.name)
        dunit, fac = spec.display if spec.display else (spec.unit, 1.0)
        out.append(f"  {f.name:<14} {f.initial:>11.6g} {f.lower:>11.6g} {f.upper:>11.6g} {f.scale:>9.4g}  "
                   f"{spec.unit:<7}| {f.initial * fac:>10.6g} {f.lower * fac:>10.6g} {f.upper * fac:>10.6g}  {dunit}")
    return out


def _dof_section(m) -> tuple[list[str], int, int | None]:
    rows = _block_rows(m)
    total = _count(m.component_data_objects(pyo.Var, descend_into=True),
                   m.component_data_objects(pyo.Constraint, descend_into=True))
    out = _section("2. variables and constraints per block (active constraints; free-eq = local balance)")
    out += _table(rows, total)
    summed = {k: sum(c[k] for _, c in rows) for k in total}
    if summed != total:
        out.append(f"note: the rows sum to {summed}, the model has {total} (components outside these blocks)")
    dof = total["free"] - total["eq"]
    try:
        from idaes.core.util.model_statistics import degrees_of_freedom

        dof_idaes = int(degrees_of_freedom(m))
        idaes_txt = str(dof_idaes)
    except Exception as exc:  # pragma: no cover - idaes is a dependency, but never crash the report
        dof_idaes, idaes_txt = None, f"unavailable ({type(exc).__name__}: {exc})"
    verdict = "agree" if dof_idaes == dof else "DISAGREE"
    out += ["", f"degrees of freedom: free variables - active equalities = {total['free']} - {total['eq']} = {dof}; "
                f"idaes degrees_of_freedom(m) = {idaes_txt} ({verdict})"]
    n_free = len(m.theta_s) if hasattr(m, "theta_s") else 0
    non_param = [(label, c["free"] - c["eq"]) for label, c in rows[1:] if c["free"] != c["eq"]]
    if not non_param and dof == n_free:
        n_l = rows[-1][1]
        out.append(f"decision freedom = the {n_free} free parameters theta_s: every trim and maneuver block is square "
                   f"given theta_s, the {n_l['free']} Cholesky factors L are fixed by {n_l['eq']} equalities, and "
                   f"eps_con is an inequality ({n_l['ineq']}), so it adds no DOF.")
    else:
        out.append(f"decision freedom: {n_free} free parameters theta_s plus the unbalanced blocks "
                   f"{non_param or 'none'} (each block should be square given theta_s).")
    return out, dof, dof_idaes


def _diagnostics_section(m) -> list[str]:
    out = _section("3. IDAES structural diagnostics")
    theta = [v for v in m.theta_s.values() if not v.fixed] if hasattr(m, "theta_s") else []
    out.append(f"run with the {len(theta)} free parameters theta_s fixed at their initial values, i.e. on the "
               "simulation problem, which must be square (0 DOF, no structural singularity); with theta_s free the "
               "toolbox would report those DOF as an under-constrained set.")
    buf = io.StringIO()
    try:
        from idaes.core.util.diagnostics_tools.diagnostics_toolbox import DiagnosticsToolbox

        for v in theta:
            v.fix()
        try:
            with contextlib.redirect_stdout(buf):
                DiagnosticsToolbox(m).report_structural_issues(stream=buf)
        finally:
            for v in theta:
                v.unfix()
        out.append(buf.getvalue().rstrip())
    except Exception as exc:
        if buf.getvalue():
            out.append(buf.getvalue().rstrip())
        out.append(f"structural diagnostics failed: {type(exc).__name__}: {exc}")
    if hasattr(m, "man"):
        dx0 = [v for name in m.maneuver_names for v in m.man[name].dx.values()
               if v.fixed and v.index()[-1] == m.man[name].t.first()]
        if dx0:
            out.append(f"note: the {len(dx0)} variables fixed to 0 and unused are dx[state, t0] of each maneuver "
                       "(Radau collocation uses no derivative at t0; fixed so no variable dangles).")
    try:
        from pyomo.contrib.pynumero.asl import AmplInterface

        pynumero = AmplInterface.available()
    except Exception:
        pynumero = False
    out.append("numerical diagnostics (report_numerical_issues, Jacobian conditioning, SVD, degeneracy hunter) need "
               + ("PyNumero; not run by inspect (no solve)." if pynumero else
                  "PyNumero with its compiled ASL library, which is not available here: not run."))
    return out


def _family(c) -> str:
    """'man[*].x[u]'-like name of a variable's or constraint's family (block indices starred)."""
    comp, blk = c.parent_component(), c.parent_block()
    idx = c.index()
    first = idx[0] if isinstance(idx, tuple) else idx
    head = "" if blk.parent_block() is None else f"{blk.parent_component().local_name}[*]."
    return head + comp.local_name + (f"[{first}]" if isinstance(first, str) else "")


def _scaling_section(m) -> list[str]:
    """The IDAES scaling report of the Scaler's factors (applied to this inspection's model only)."""
    out = _section("3b. IDAES scaling (nlp/scaling.py; the solves use it with the solver option scaling = true)")
    try:
        from idaes.core.scaling import get_scaling_factor, report_scaling_factors
        from idaes.core.scaling.util import unscaled_constraints_generator, unscaled_variables_generator
        from idaes.core.util.scaling import badly_scaled_var_generator

        from .scaling import IdentificationScaler

        def badly():
            return [(v, sv) for v, sv in badly_scaled_var_generator(m)]

        before = badly()
        IdentificationScaler(overwrite=True).scale_model(m)
        after = badly()
        families: dict = {}
        for kind, ctype in (("var", pyo.Var), ("con", pyo.Constraint)):
            for c in m.component_data_objects(ctype, active=True if kind == "con" else None, descend_into=True):
                if kind == "var" and c.fixed:
                    continue
                sf = get_scaling_factor(c)
                if sf is not None:
                    families.setdefault((kind, _family(c)), []).append(sf)
        out.append("scaling factors (1 / nominal magnitude) per family: "
                   + "; ".join(f"{name} {min(v):.3g}" + (f"..{max(v):.3g}" if max(v) != min(v) else "")
                               for (kind, name), v in sorted(families.items())))
        no_var = [v.name for v in unscaled_variables_generator(m)]
        no_con = [c.name for c in unscaled_constraints_generator(m)]
        out.append(f"without a factor (kept at 1): {len(no_var)} free variables"
                   + (f" ({', '.join(sorted({_family(v) for v in unscaled_variables_generator(m)}))})" if no_var
                      else "") + f", {len(no_con)} constraints")
        out.append(f"IDAES badly_scaled_var_generator (scaled value above 1e4 or below 1e-3, zeros excepted): "
                   f"{len(before)} variables unscaled, {len(after)} scaled"
                   + (f"; still flagged: {', '.join(sorted({_family(v) for v, _ in after}))}" if after else ""))
        buf = io.StringIO()
        report_scaling_factors(m, descend_into=False, stream=buf)  # the model's own level: parameters, noise rows
        out.append("IDAES report_scaling_factors of the model's top level (the blocks' families are listed above):")
        out.append(buf.getvalue().rstrip())
    except Exception as exc:  # never crash the report
        out.append(f"scaling report failed: {type(exc).__name__}: {exc}")
    return out


def _time_point_section(m, mv) -> list[str]:
    blk = m.man[mv.name]
    samples, times = list(blk.samples), list(blk.t)
    k = 1 if len(samples) > 1 else 0
    t = samples[k]
    pos = times.index(t)
    left = samples[k - 1] if k else t
    inside = [f"{tt:.6g}" for tt in times if left < tt < t]
    out = _section(f"4a. equations at one time point: man[{mv.name}], t = {t:.6g} s")
    out.append(f"sample {k + 1} of {len(samples)}, time point {pos + 1} of {len(times)}; "
               + (f"right end of finite element [{left:.6g}, {t:.6g}] (a Radau collocation point; interior point(s) "
                  f"{', '.join(inside) or 'none'})" if k else "the initial time"))
    cons = [c for c in blk.component_data_objects(pyo.Constraint, active=True, descend_into=True)
            if isinstance(c.index(), tuple) and isinstance(c.index()[-1], float) and c.index()[-1] == t]
    groups: dict = {}
    for c in cons:
        groups.setdefault(c.parent_component().local_name, []).append(c)
    out.append("constraints here: " + ", ".join(f"{g} ({len(v)})" for g, v in groups.items()))
    return out + _equations(m, blk, cons, t)


def _trim_section(m, i: int, why: str) -> list[str]:
    tb = m.trim[i]
    out = _section(f"4b. equations of one trim block: trim[{i}], V = {pyo.value(tb.V_target) / KT:.1f} kt ({why})")
    tcons = list(tb.component_data_objects(pyo.Constraint, active=True, descend_into=True))
    tvars = [v.local_name for v in tb.component_data_objects(pyo.Var, descend_into=True)]
    out.append(f"unknowns ({len(tvars)}): {', '.join(tvars)}; {len(tcons)} equalities")
    return out + _equations(m, tb, tcons)


def _objective_section(m) -> list[str]:
    from idaes.core.util.misc import compact_expression_to_string

    out = _section("4c. objective part (named Expressions kept by name: idaes compact_expression_to_string)")
    for name in ("J_time", "J_trim"):
        if hasattr(m, name):
            out += [f"  {name} =", _wrap(_round_numbers(compact_expression_to_string(getattr(m, name).expr)))]
    for c in m.component_data_objects(pyo.Constraint, active=True, descend_into=False):
        out += [f"  {c.name}:", _wrap(_round_numbers(compact_expression_to_string(c.expr)))]
    for o in m.component_data_objects(pyo.Objective, active=True, descend_into=False):
        out += [f"  {o.name} ({'minimize' if o.sense == pyo.minimize else 'maximize'}):",
                _wrap(compact_expression_to_string(o.expr))]
    return out


def _parameter_section(cfg, m) -> list[str]:
    out = _section("4d. physical parameters: which names in the equations are free parameters")
    for f in cfg.free:
        spec = cfg.model.parameters.spec(f.name)
        scale = pyo.value(m.theta_scale[f.name])
        out.append(f"  {f.name:<14} = {scale:.6g} * theta_s[{f.name}]  [{spec.unit}]   "
                   f"theta_s in [{f.lower / scale:.6g}, {f.upper / scale:.6g}], initial {f.initial / scale:.6g}"
                   f"   ({spec.description})")
    free = {f.name for f in cfg.free}
    fixed = [s for s in cfg.model.parameters.specs() if s.name not in free]
    out.append("fixed parameters enter the equations as numbers (often multiplied together):")
    line = " "
    for s in fixed:
        item = f" {s.name}={cfg.model.parameters[s.name]:.6g} {s.unit};"
        if len(line) + len(item) > WIDTH:
            out.append(line)
            line = " "
        line += item
    out.append(line)
    return out


# ---------------------------------------------------------------- entry point
def inspect_problem(cfg, diagnostics: bool = True, responses=None) -> str:
    """Build the NLP of ``cfg`` (no solve) and return the inspection report as text. ``responses``: the coherent
    bands of a three-objective config's frequency responses (the J_linear blocks are built with them)."""
    from .identification import build_problem

    m, data, _ = build_problem(cfg, responses)
    out = ["=" * WIDTH, "1. problem"] + ["=" * WIDTH] + _header(cfg, m, data)
    if responses is not None:
        out += ["", f"frequency responses (J_linear, {sum(len(r.omega) for r in responses)} coherent bins):"]
        out += [f"  {r.label:<24} {len(r.omega):>4} bins, {r.omega.min():.2f}..{r.omega.max():.2f} rad/s"
                for r in responses]
    dof_lines, _, _ = _dof_section(m)
    out += dof_lines
    if diagnostics:
        out += _diagnostics_section(m)
    else:
        out += _section("3. IDAES structural diagnostics") + ["skipped (--no-diagnostics)"]
    out += _scaling_section(m)
    if data.maneuvers:
        mv = data.maneuvers[0]
        out += _time_point_section(m, mv)
        out += _trim_section(m, data.speed_index(mv.trim_speed), f"start trim of {mv.name}")
    elif hasattr(m, "trim") and len(m.trim_speeds):
        out += _trim_section(m, m.trim_speeds.first(), "first trim block")
    out += _objective_section(m)
    out += _parameter_section(cfg, m)
    return "\n".join(_fill(line) for line in "\n".join(out).splitlines())
