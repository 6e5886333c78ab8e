"""Structure determination: trace the residual to a missing effect, listed in advance or not.

One step of the closed loop with ``[loop] discovery = true`` (docs/discovery.md):

1. **Rank the whole library** by the score test (:func:`pyomo_heli.diagnosis.attribution.attribute`,
   robust: batch-means variance): the physical candidates (:mod:`.candidates`) and the generic
   discrepancy family (:mod:`pyomo_heli.physics.discrepancy`: dX, dZ, dM as regressors in speed, state
   and controls, and sensor scale/bias terms). Cheap (float sensitivities); it only picks which terms
   the NLP estimates: the best ``SCREEN_GENERIC`` generic terms and ``SCREEN_PHYSICAL`` physical ones, and the
   generic terms rejected earlier (never added again; a physical candidate must still encompass them).
2. **Estimate and test in the full NLP** (:func:`nlp_screen`): one identification NLP holds the
   current model plus the screened terms, their coefficients pinned at zero by equal bounds. It is
   solved once for the joint negative log-likelihood of time series and trims

       J = J_time + sum_c (N/2) ln(mean_i r_ic^2)     (J_time: output error, Eq. 5-6; r_ic: trim
                                                       residual of channel c at point i, N points)

   then each term is freed by its bounds alone, solved warm from that solution (its primal values and
   multipliers, the barrier parameter from tol / 10: the fronts' ``continuation``, a few Ipopt
   iterations; if that stops at its cap, again with Ipopt's inertia-free curvature test, then from the primal
   values alone) and pinned again:
   its estimate, ``LR = 2 (J_0 - J_term)`` and a standard error |c| / sqrt(LR) (the curvature of the
   profile likelihood). The LR is corrected for coloured residuals (:func:`robust_p`: times the score
   test's robust-over-white ratio, capped at 1, referred to F(1, df)). **Significant: p < alpha / L**
   with L the size of the whole library scored (Bonferroni: by the union bound the chance of any false
   discovery over the library is at most alpha, whichever terms the screen passes on). This p is the
   corrected LR's when the NLP models the measured inputs' noise (``[objectives] input_errors``); in
   output error it is the robust score test's own (there the time residuals carry a constant input
   offset per maneuver that the score test projects off and the NLP does not: on M0 + noise the LR
   found a constant dM at p = 2e-5, docs/discovery.md).
3. **Name the physics by encompassing**: a significant physical candidate P is named only when it
   explains the data as well as the best significant generic term G: with P and G free together,
   ``LR(G | P) = 2 (J_P - J_PG)`` must not be significant at ``alpha`` (G adds nothing once P is in;
   tested at alpha without a multiplicity correction, so that a P is named only when even a lenient test
   finds nothing for G to add), and P must add something G does not, ``LR(P | G) = 2 (J_G - J_PG)``
   significant at ``alpha``: when neither adds to the other the two are equivalent on these data, and
   the data cannot name the physics. Of several such P, the one of lowest J is named. Otherwise G is kept and
   reported as *not explained by any library effect*. A significant physical candidate with no
   significant generic term is tested against the best generic term all the same: named if it
   encompasses it, taken (lowest J) if the two are equivalent, nothing added otherwise ("ambiguous", with
   the best generic term reported as what is left).
4. **Nothing significant**: nothing is added; the best generic term's NLP estimate is still reported
   as the shape of what is left. A term the score test finds significant that the screen did not estimate
   (below the best ``SCREEN_GENERIC`` generic terms or ``SCREEN_PHYSICAL`` physical candidates by LM) is named
   (``significant_unscreened``): the step then says "nothing significant among the terms estimated", not "over
   the whole library". A significant term whose fit failed is named too (``significant_unfitted``; under the
   likelihood ratio, which such a fit lacks, by its score test).

The backward check (a term added earlier that is no longer significant once the new one is in), the
validation rule (a step that makes validation significantly worse on any output is rejected) and the name check
(a physical candidate the loop added must leave the generic family nothing significant at the next step:
``generic_significant`` and ``best_generic_fit`` of that step) are run by the loop
(:mod:`pyomo_heli.workflows.close_loop`).
"""
from __future__ import annotations

import dataclasses
import math
import time

import numpy as np
from scipy import stats

from ..physics.discrepancy import BUMP_CENTRES, FORCE_CHANNELS, REGRESSORS, generic_names, is_generic
from ..units import KT
from . import attribution as attr
from .candidates import CANDIDATES, as_candidate, make_candidate

#: generic terms (best by LM) estimated in the NLP at every step
SCREEN_GENERIC = 3
#: physical candidates (significant, best by LM) estimated in the NLP for the encompassing test
SCREEN_PHYSICAL = 3
#: Ipopt iteration cap of each of the screen's two base solves: a base from the diagnosed point takes 29-52
#: iterations on the held-out flight tests; one that needs more is stuck (a flight test's base with three lag
#: terms pinned crept for 1955 iterations under Hessian regularization), and the screen then runs one NLP per
#: term and per pair instead (:func:`nlp_screen`); the base solved again from the best single fit is capped alike
SCREEN_BASE_MAX_ITER = 200
#: Ipopt iteration cap of each of the screen's fits (a term or a pair freed from the base): they take 5-80
#: iterations on the held-out flight tests, 227 at most (col_delay, 862 s); one stuck under Hessian
#: regularization otherwise runs to the solver's max_iter and once more from its primal (inflow_time_constant on
#: fuselage_wake_incidence 22 with the extended family: 1000 iterations, more than 30 min, then the retry). A fit
#: stopped at the cap is a failed fit: no likelihood ratio.
SCREEN_FIT_MAX_ITER = 300
#: how far (in J, half a likelihood ratio) a pair's fit may end above the better of its two terms' fits alone: the
#: pair nests each of them, so a pair fit above that stopped at a worse local optimum; it is solved again from that
#: term's solution (:func:`nlp_screen`), and one still above is no encompassing test (:func:`encompassing`)
PAIR_SLACK = 0.25
#: Ipopt iteration cap of a fit's continuation warm start (the base's multipliers, a small barrier): the fits that
#: converge from it take 3-25 iterations (docs/discovery.md, step 2); one that needs more is mostly stuck (a lag or
#: time-constant term, nx_delay on the bundled flight test: uncapped it ran to the 300 cap, ~11 min) and is solved
#: again with SCREEN_CURVATURE_TEST, then from the primal values alone under SCREEN_FIT_MAX_ITER
SCREEN_CONTINUATION_MAX_ITER = 50
#: Ipopt options of a fit's second continuation warm start, after the first stopped at SCREEN_CONTINUATION_MAX_ITER:
#: the inertia-free curvature test (Zavala and Chiang 2014) in place of the inertia check. A fit that stops at the
#: cap is one crept under Hessian regularization (nx_delay on the bundled flight test: a regularization near 1e-4 at
#: every iteration, steps of 1e-4, J falling in the sixth digit); Ipopt then accepts a step of positive curvature
#: along itself whatever the factorisation's inertia (nx_delay: 10 iterations, 11 s, where the primal retry took
#: 124 iterations, 149 s; docs/discovery.md, step 2). The fit is solved from the primal values alone only if this
#: fails too.
SCREEN_CURVATURE_TEST = {"neg_curv_test_tol": 1e-12}


def library(model, physical=None, generic=None) -> list[str]:
    """The names scored at a step: physical candidates then generic terms, minus those already in ``model``."""
    have = {e.name for e in model.extensions}
    phys = list(physical) if physical is not None else list(CANDIDATES)
    gen = list(generic) if generic is not None else generic_names()
    return [n for n in phys + gen if n not in have]


def _joint_objective(m, data, trim_outputs):
    """``m.discovery_objective`` = J_time + sum over trim channels c of (N/2) ln(mean_i r_ic^2): the negative
    log-likelihood of the time series (J_time) and of the trims with one variance per channel, estimated
    (concentrated out), N trim points. Also ``m.discovery_trim_nll``, its trim part."""
    import pyomo.environ as pyo

    if m.component("objective") is not None:
        m.objective.deactivate()
    nll = 0.0
    N = len(data.trims)
    mutable = m.component("trim_meas") is not None
    for c in trim_outputs or ():
        res = []
        for i, (_, row) in enumerate(data.trims.iterrows()):
            blk = m.trim[data.speed_index(row["V"])]
            res.append((m.trim_meas[i, c] if mutable else float(row[c])) - getattr(blk, c))
        nll = nll + 0.5 * N * pyo.log(sum(r**2 for r in res) / N)
    m.discovery_trim_nll = pyo.Expression(expr=nll)
    m.discovery_objective = pyo.Objective(expr=m.J_time + m.discovery_trim_nll)
    return m.discovery_objective


def nlp_screen(cfg, start: dict, terms: list, pairs=(), shape_free: bool = True, progress=print,
               warm_start: str = "continuation", separate_on_failure: bool = True) -> dict:
    """Estimate each of ``terms`` alone, and each pair of ``pairs`` together, in one identification NLP, freed by
    their bounds (module docstring, step 2).

    The base (every term pinned at zero) is solved with at most :data:`SCREEN_BASE_MAX_ITER` Ipopt iterations, and
    once more from where it stopped; so is the base solved again from the best single fit's solution. When the
    first two base solves fail and there is more than one term, the screen is run again as one NLP per term and one
    per pair (:func:`_separate_screens`; ``separate`` in the result), each with its own base
    (``separate_on_failure=False``: keep the failed base and go on). Each fit is capped at
    :data:`SCREEN_FIT_MAX_ITER` Ipopt iterations. A pair whose fit ends more than :data:`PAIR_SLACK` above the better
    of its terms alone (it nests each, so it stopped at a worse local optimum) is solved again from that term's
    solution, and the lower J kept (``first_start`` or ``second_start`` in its record: the other solve).

    ``cfg``: the current identification config (its model and free parameters); ``start``: values of its free
    parameters to start from (the diagnosed point); ``terms``: library names or extension objects
    (:func:`~.candidates.as_candidate`), ``pairs`` by name. Returns ``{"J0", "base", "fits": {name: {...}}, "pairs":
    {"P+G": {...}}}`` with each fit's estimate, standard error, J, LR against the base, p (chi-square(1)), solve
    status, Ipopt iterations, solve wall seconds and parameters.
    """
    import pyomo.environ as pyo

    from ..nlp.identification import build_problem
    from ..nlp.parameters import FreeParameter, free_parameter_values
    from ..pareto.snapshot import Snapshot
    from ..physics.model import HelicopterModel
    from ..solvers import SolverError, make_solver

    t0 = time.perf_counter()
    exts = [as_candidate(t) for t in terms]
    model = HelicopterModel(parameters=cfg.model.parameters, extensions=tuple(cfg.model.extensions) + tuple(exts))
    free = [dataclasses.replace(f, initial=min(max(start.get(f.name, f.initial), f.lower), f.upper)) for f in cfg.free]
    own = {}  # term -> its parameters in the NLP (strength first, then shape parameters)
    for e in exts:
        names = [e.strength] + (list(getattr(e, "shape_parameters", ())) if shape_free else [])
        own[e.name] = names
        for n in names:
            spec = model.parameters.spec(n)
            lo, hi = spec.bounds
            free.append(FreeParameter(n, min(max(spec.value, lo), hi), lo, hi, spec.scale or 1.0))
    cfg_s = dataclasses.replace(cfg, model=model, free=free)
    m, data, _ = build_problem(cfg_s)
    _joint_objective(m, data, cfg.nlp.trim_outputs)
    solver = make_solver(m, cfg.pareto.solver, cfg.pareto.solver_options)
    by = {f.name: f for f in free}
    ext_by = {e.name: e for e in exts}

    def pin(n, free_it: bool):
        f = by[n]
        s = m.theta_scale[n]
        if free_it:
            m.theta_s[n].setlb(f.lower / s)
            m.theta_s[n].setub(f.upper / s)
        else:
            v = model.parameters[n] / s
            m.theta_s[n].setlb(v)
            m.theta_s[n].setub(v)
            m.theta_s[n].set_value(v)

    effort = {}  # the last solve's Ipopt iterations and wall seconds (recorded with each fit)

    def solve(ws, options=None):
        try:
            r = solver.solve(warm_start=ws, options=options)
            effort.update(iterations=int(r.iterations), wall_time=float(r.wall_time))
            return r.success, r.status
        except SolverError as exc:
            effort.update(iterations=None, wall_time=None)
            return False, f"{type(exc).__name__}: {exc}"

    for names in own.values():
        for n in names:
            pin(n, False)
    max_iter = int((cfg.pareto.solver_options or {}).get("max_iter", 3000))
    cap = {"max_iter": min(SCREEN_BASE_MAX_ITER, max_iter)}
    fit_cap = {"max_iter": min(SCREEN_FIT_MAX_ITER, max_iter)}
    continuation_cap = {"max_iter": min(SCREEN_CONTINUATION_MAX_ITER, max_iter)}
    ok, status = solve("none", cap)
    if not ok:  # once more from where it stopped (its primal values)
        progress(f"    NLP screen: base solve failed ({status}, {effort.get('iterations')} iterations); once more "
                 "from where it stopped")
        ok, status = solve("primal", cap)
    if not ok and separate_on_failure and len(exts) > 1:
        progress(f"    NLP screen: base solve failed again ({status}); one NLP per term and per pair instead")
        return _separate_screens(cfg, start, exts, pairs, status, time.perf_counter() - t0, shape_free=shape_free,
                                 progress=progress, warm_start=warm_start)
    J0 = float(pyo.value(m.discovery_objective))
    J0_tr = float(pyo.value(m.discovery_trim_nll))
    base = free_parameter_values(m)
    snap = Snapshot(m)
    progress(f"    NLP screen: base J = {J0:.6g} ({status}, {effort.get('iterations')} iterations)")

    def free(group, keep=None):
        for name in group:
            for n in own[name]:
                pin(n, True)
            e = ext_by[name]
            if getattr(e, "one_sided", False) and name != keep:  # start a one-sided strength inside its bounds
                f = by[e.strength]
                m.theta_s[e.strength].set_value((f.lower + 0.05 * (f.upper - f.lower)) / m.theta_scale[e.strength])

    # a fit's starts, each from the base's solution: the warm start, then (crept under regularization) the same with
    # the curvature test instead of the inertia check, then (the multipliers did not carry it) its primal values alone
    starts = ([(warm_start, warm_start, continuation_cap),
               ("curvature test", warm_start, {**continuation_cap, **SCREEN_CURVATURE_TEST})]
              if warm_start != "primal" else []) + [("primal", "primal", fit_cap)]

    def fit(group, from_fit=None):
        """Fit the terms of ``group`` from the base's solution, or with ``from_fit`` (a term of the group) from
        that term's own fit's solution, the others at zero (its primal values)."""
        tries = starts if from_fit is None else [(f"{from_fit}'s fit", "primal", fit_cap)]
        for k, (solved_from, ws, options) in enumerate(tries):
            if from_fit is not None:
                singles[from_fit].restore()
            elif k:
                snap.restore()
            free(group, keep=from_fit)
            ok_k, status_k = solve(ws, options)
            if ok_k or k + 1 == len(tries):
                break
            progress(f"    NLP screen: {'+'.join(group)}: {solved_from} start failed ({status_k}); {tries[k + 1][0]}")
        J = float(pyo.value(m.discovery_objective))
        J_tr = float(pyo.value(m.discovery_trim_nll))
        vals = free_parameter_values(m)
        lr = max(2.0 * (J0 - J), 0.0) if ok and ok_k else float("nan")
        rows = {}
        for name in group:
            e = ext_by[name]
            c = vals[e.strength]
            rows[name] = {"name": name, "strength": e.strength, "generic": bool(getattr(e, "generic", False)),
                          "formula": e.formula() if hasattr(e, "formula") else e.describe(), "estimate": c,
                          "shape": {n: vals[n] for n in own[name][1:]}}
        res = {"J": J, "LR": lr, "LR_trim": 2.0 * (J0_tr - J_tr), "LR_time": 2.0 * (J0 - J0_tr - J + J_tr),
               "p": float(stats.chi2.sf(lr, len(group))) if not math.isnan(lr) else float("nan"),
               "success": bool(ok_k), "status": status_k, "solved_from": solved_from, **effort, "terms": rows,
               "parameters": {f.name: vals[f.name] for f in cfg.free}}
        progress(f"    NLP screen: {'+'.join(group)}: "
                 + ", ".join(f"{r['strength']} = {r['estimate']:.4g}" for r in rows.values())
                 + f", J = {J:.6g}, LR = {lr:.4g} (time {res['LR_time']:.3g}, trim {res['LR_trim']:.3g}; {status_k}, "
                 + f"{effort.get('iterations')} iterations, {effort.get('wall_time') or 0.0:.0f} s)")
        if len(group) == 1 and ok_k:  # a single fit's solution: a pair's second start, the best the base's
            singles[group[0]] = Snapshot(m)
            if not best or J < best["J"]:
                best.update(J=J, name=group[0], snap=singles[group[0]])
        for name in group:
            for n in own[name]:
                pin(n, False)
        snap.restore()
        return res

    def rescore(r):
        """A fit's likelihood ratios against the base of the moment."""
        lr = max(2.0 * (J0 - r["J"]), 0.0) if ok and r["success"] else float("nan")
        r.update(LR=lr, p=float(stats.chi2.sf(lr, 1)) if not math.isnan(lr) else float("nan"))
        # standard error from the profile likelihood's curvature: LR = (c / se)^2
        r["se"] = abs(r["estimate"]) / math.sqrt(lr) if not math.isnan(lr) and lr > 0 else float("nan")
        return r

    best = {}
    singles = {}  # term -> its single fit's solution
    fits = {}
    for name in own:
        r = fit([name])
        fits[name] = rescore({**r.pop("terms")[name], **r})
    refined = None
    if best:
        # the base must be the best the current model reaches: the best single fit's solution, its term pinned
        # back at zero, is a second start for it; a base lower by more than LR 1 replaces the first (a base solve
        # that stopped at a worse point would inflate every LR by the same amount)
        best["snap"].restore()
        for n in own[best["name"]]:
            pin(n, False)
        ok_b, status_b = solve("primal", cap)  # a base solve too: one stuck beyond the cap keeps the first base
        J0b = float(pyo.value(m.discovery_objective))
        if ok_b and (not ok or 2.0 * (J0 - J0b) > 1.0):
            refined = {"from": best["name"], "J_before": J0, "status_before": status, "J": J0b}
            progress(f"    NLP screen: base again from {best['name']}'s solution with it at zero: J = {J0b:.6g} "
                     f"({status_b}; before {J0:.6g}, {status}); the likelihood ratios are taken against it")
            J0_tr_old, J0_old = J0_tr, J0
            J0, J0_tr, ok, status = J0b, float(pyo.value(m.discovery_trim_nll)), True, status_b
            base, snap = free_parameter_values(m), Snapshot(m)
            for f in fits.values():  # J_trim of the fit = J0_tr_old - LR_trim / 2, unchanged
                f["LR_trim"] += 2.0 * (J0_tr - J0_tr_old)
                f["LR_time"] = 2.0 * (J0 - J0_old) + f["LR_time"] - 2.0 * (J0_tr - J0_tr_old)
                rescore(f)
        else:
            snap.restore()

    def pair_fit(a, b):
        """A pair from the base's solution; when that ends above one of its terms alone (a pair nests each term, so
        it stopped at a worse local optimum), again from the better term's solution, keeping the lower J."""
        r = fit([a, b])
        parts = [n for n in (a, b) if n in singles and fits[n]["success"]]
        if not (r["success"] and parts):
            return r
        n = min(parts, key=lambda n: fits[n]["J"])
        if r["J"] <= fits[n]["J"] + PAIR_SLACK:
            return r
        progress(f"    NLP screen: {a}+{b}: J = {r['J']:.6g} above {n}'s alone ({fits[n]['J']:.6g}); again from "
                 f"{n}'s solution")
        again = fit([a, b], from_fit=n)
        first = {k: r[k] for k in ("J", "status", "success", "solved_from")}
        if again["success"] and again["J"] < r["J"]:
            return {**again, "first_start": first}
        return {**r, "second_start": {k: again[k] for k in ("J", "status", "success", "solved_from")}}

    if callable(pairs):
        pairs = pairs(fits)
    both = {f"{a}+{b}": pair_fit(a, b) for a, b in pairs}
    return {"J0": J0, "base_success": bool(ok), "base_status": status, "base": base, "base_refined": refined,
            "fits": fits, "pairs": both,
            "wall_time": time.perf_counter() - t0}


def _separate_screens(cfg, start, exts, pairs, joint_status, spent, **kw) -> dict:
    """:func:`nlp_screen` as one NLP per term and one per pair, after the joint base failed: each fit's LR is
    taken against its own NLP's base, and a pair's record holds its NLP's single fits (``single_J``), so that
    the encompassing test compares the two terms alone and together within one NLP. ``J0`` and ``base`` are
    those of the best base; ``base_success`` is True when every NLP's base (or its refined base) converged."""
    t0 = time.perf_counter()
    fits, bases = {}, []
    for e in exts:
        s = nlp_screen(cfg, start, [e], separate_on_failure=False, **kw)
        fits[e.name] = {**s["fits"][e.name], "J0": s["J0"], "base_status": s["base_status"]}
        bases.append(s)
    if callable(pairs):
        pairs = pairs(fits)
    by = {e.name: e for e in exts}
    both = {}
    for a, b in pairs:
        s = nlp_screen(cfg, start, [by[a], by[b]], pairs=[(a, b)], separate_on_failure=False, **kw)
        both[f"{a}+{b}"] = {**s["pairs"][f"{a}+{b}"], "J0": s["J0"],
                            "single_J": {n: s["fits"][n]["J"] for n in (a, b)}}
        bases.append(s)
    best = min(bases, key=lambda s: s["J0"])
    return {"J0": best["J0"], "base_success": all(s["base_success"] for s in bases), "base": best["base"],
            "base_status": "; ".join(dict.fromkeys(s["base_status"] for s in bases)),
            "base_refined": None, "fits": fits, "pairs": both, "separate": {"joint_base_status": joint_status},
            "wall_time": spent + time.perf_counter() - t0}


def describe_fit(fit: dict) -> str:
    lr = f"LR {fit['LR']:.3g}"
    if "LR_robust" in fit:
        lr += f", corrected {fit['LR_robust']:.3g} on df {fit['df']:.3g}"
    return f"{fit['formula']}, c = {fit['estimate']:.4g} +- {fit['se']:.2g} (NLP estimate; {lr})"


def discovery_step(cfg, model, start: dict, data, **kw) -> dict:
    """One structure-determination step (module docstring). ``model``: the current model at its estimate;
    ``start``: the free parameters' values; keywords ``physical``, ``generic``, ``alpha``, ``ratio``,
    ``confound_corr``, ``robust``, ``score_kw``, ``rank`` (how the generic terms are ranked, :func:`best_fit`),
    ``progress``. Returns a plain dict: ``decision`` (named |
    discovered | accepted | ambiguous | none), ``added`` (name or None), ``initial`` (its strength's start value),
    ``attribution`` (the score table over the whole library, used to rank), ``screen`` (NLP estimates and
    likelihood ratios), ``encompassing`` (one row per physical candidate tested), ``level`` (alpha / library
    size), ``criterion``, ``message``; ``base_failed`` (the status) when the NLP screen's base solve failed twice,
    which leaves no likelihood ratio: the score test then decides, and the message says so."""
    out = _step(cfg, model, start, data, **kw)
    if out.get("base_failed"):
        out["message"] += (f" (the NLP screen's base solve failed: {out['base_failed']}; with no likelihood ratio "
                           "the score test decided)")
    return out


def _step(cfg, model, start: dict, data, *, physical=None, generic=None, rejected_generic=(), alpha=attr.ALPHA,
          ratio=attr.RATIO, confound_corr=attr.CONFOUND_CORR, robust=True, score_kw=None, rank="p",
          progress=print) -> dict:
    score_kw = dict(score_kw or {})
    identified = [f.name for f in cfg.free]
    # generic terms an earlier step added and the validation rule rejected: never added again, but still the
    # competitors a physical candidate must encompass and the name check asks about (the data hold what they
    # describe; their model only validated worse)
    rejected_generic = list(rejected_generic)
    addable = [n for n in (generic if generic is not None else generic_names()) if n not in rejected_generic]
    names = library(model, physical, addable + rejected_generic)
    att = attr.attribute(model, identified, data, cfg.nlp.time_outputs, cfg.nlp.trim_outputs, candidates=names,
                         alpha=alpha, ratio=ratio, confound_corr=confound_corr, robust=robust, **score_kw)
    progress(str(att))
    sc = att.scores
    ranked = [n for n in sc["name"] if not (sc.set_index("name").loc[n, "p_value"] >= 1.0)]  # wrong-sign one-sided out
    gen_screen = ([n for n in ranked if is_generic(n) and n not in rejected_generic][:SCREEN_GENERIC]
                  + [n for n in ranked if n in rejected_generic])
    phys_screen = [n for n in ranked if not is_generic(n)][:SCREEN_PHYSICAL]
    level = alpha / max(len(names), 1)  # Bonferroni over the whole library: the family-wise level is alpha
    out = {"library_size": len(names), "level": level, "attribution": att.to_dict(), "encompassing": [],
           "added": None, "initial": None}
    try:
        omega_r = float(model.parameters["Omega"]) * float(model.parameters["R"])
    except (KeyError, TypeError):
        omega_r = None
    # the shape of what is left per force/moment channel, over speed and over the state it follows (score test)
    out["shape_by_channel"] = channel_shapes(sc, omega_r)

    def pairs_of(fits):
        """(P, G) for every significant physical candidate P and each competitor G (:func:`competitors`)."""
        for n, f in fits.items():  # the deciding p-values (the pairs are asked for before they are set below)
            f.setdefault("p_LR", f["p"])
            judge(f, sc.set_index("name").loc[n], getattr(make_candidate(n), "one_sided", False),
                  "likelihood ratio" if cfg.nlp.input_errors and not math.isnan(f["LR"]) else "score test")
        # every significant physical candidate against each best generic term (significant or not)
        return [(n, g["name"]) for g in competitors(fits, rank)
                for n in phys_screen if fits[n]["success"] and fits[n]["p"] < level]

    screen = nlp_screen(cfg, start, gen_screen + phys_screen, pairs=pairs_of, progress=progress)
    out["screen"] = screen
    fits = screen["fits"]
    rows_by = sc.set_index("name")
    # the criterion: the corrected LR when the likelihood models the measured inputs' noise (errors in variables);
    # in output error the score test's own p (docs/discovery.md, "Which test decides")
    # a base solve that failed leaves no likelihood ratio: the score test decides, and the message says so
    base_failed = screen.get("base_success", True) is False
    criterion = deciding_criterion(cfg, screen)
    out["criterion"] = criterion
    if base_failed:
        out["base_failed"] = screen.get("base_status")
    for n, f in fits.items():
        one_sided = getattr(make_candidate(n), "one_sided", False)
        judge(f, rows_by.loc[n], one_sided, criterion)
        if criterion == "likelihood ratio":
            f["detectable"] = detection_limit(f, level, one_sided)
    G = best_fit(fits, True, rank)  # the competitor a physical candidate must encompass (a rejected term included)
    A = best_fit({n: f for n, f in fits.items() if n not in rejected_generic}, True, rank)  # the best that may be added
    g_sig = A is not None and A["p"] < level
    p_sig = [f for f in fits.values() if not f["generic"] and f["success"] and f["p"] < level]
    # the family's best term at this model and whether it is significant, whatever is decided (the loop's check of
    # a physical candidate it added: it must leave the generic family nothing significant, rejected terms included)
    # (any generic fit significant, not only the best by the ranking: with generic_rank = "likelihood_ratio" the best
    # by raw LR can have a larger p than another term)
    out.update(generic_significant=any(f["generic"] and f["success"] and f.get("p", math.nan) < level
                                       for f in fits.values()), best_generic_fit=G,
               most_significant_generic_fit=best_fit(fits, True, "p"))  # what the name check names
    if rejected_generic:
        out["rejected_generic"] = list(rejected_generic)
    # a term the deciding test finds significant whose NLP fit failed (no estimate, no likelihood ratio): best_fit
    # leaves it out, so the step must not read "nothing significant" as if the library had been tested in full
    # (under the likelihood ratio a failed fit has no p of its own: its score test's p stands in)
    def p_or_score(f):
        p = f.get("p", math.nan)
        return float(rows_by.loc[f["name"], "p_value"]) if math.isnan(p) else p

    unfitted = sorted((dict(f, p=p_or_score(f)) for f in fits.values() if not f["success"] and p_or_score(f) < level),
                      key=lambda f: f["p"])
    if unfitted:
        out["significant_unfitted"] = [f["name"] for f in unfitted]
    # generic terms that may be added, significant by the score test's own p, but below the screen's best by LM:
    # never estimated, so "nothing significant" holds only for the terms that were
    # (physical candidates likewise: the screen takes the best SCREEN_PHYSICAL by LM, and a candidate of larger df
    # can have a smaller p with a smaller LM)
    unscreened = [n for n in ranked if n not in rejected_generic and n not in fits
                  and rows_by.loc[n, "p_value"] < level]
    if unscreened:
        out["significant_unscreened"] = unscreened
    if not g_sig and not p_sig:
        # "unexplained": the best generic term is significant on its own (p < alpha) but not over the library, or a
        # significant term could not be fitted
        unexplained = (G is not None and G["p"] < alpha) or bool(unfitted)
        out.update(decision="none", best_generic=G, unexplained=bool(unexplained),
                   message=(f"not decided: the NLP fit of {', '.join(f['name'] for f in unfitted)} failed although "
                            f"its {criterion} is significant (p = {unfitted[0]['p']:.2g} < {level:.2g}); of the "
                            "terms fitted, " if unfitted else "")
                           + (f"nothing significant among the terms estimated ({criterion}, Bonferroni over the "
                              f"library of {len(names)} terms: p < {level:.2g}); not estimated, significant by the "
                              "score test: " + ", ".join(f"{n} (p = {rows_by.loc[n, 'p_value']:.2g})"
                                                         for n in unscreened)
                              + f" (the NLP estimates the best {SCREEN_GENERIC} generic terms and "
                                f"{SCREEN_PHYSICAL} physical candidates by LM)"
                              if unscreened else
                              f"nothing significant over the whole library of {len(names)} terms ({criterion}, "
                              f"Bonferroni: p < {level:.2g})")
                           + (f" but the rejected {G['name']}, which is not added again (p = {G['p']:.2g})"
                              if G is not None and G["name"] in rejected_generic and G["p"] < level else "")
                           + ("; unexplained residual (its best generic term is significant on its own, "
                              f"p = {G['p']:.2g} < {alpha:g}, not over the library)"
                              if G is not None and G["p"] < alpha else "")
                           + (f"; best generic description of what is left: {describe_fit(G)}, p = {G['p']:.2g}"
                              if G else "")
                           + (f"; a term of its shape is significant from |c| >= {G['detectable']:.2g}"
                              if G and math.isfinite(G.get("detectable", math.nan)) else "")
                           + (f"; shape per channel (score test): {shapes_sentence(out['shape_by_channel'])}"
                              if out["shape_by_channel"] else ""))
        return out
    # a physical candidate must encompass every competitor: the best generic term by either ranking (they part when
    # the terms' colour corrections differ, and then which one is "best" is a near tie the name must not hang on)
    comps = competitors(fits, rank)
    rows = [{"candidate": pf["name"], "generic": g["name"],
             **encompassing(pf, g, screen["pairs"].get(f"{pf['name']}+{g['name']}"), alpha)}
            for pf in p_sig for g in comps]
    out["encompassing"] = rows
    if len(comps) > 1:
        out["competitors"] = [g["name"] for g in comps]
    by_candidate = {}
    for r in rows:
        by_candidate.setdefault(r["candidate"], []).append(r)
    # named: it encompasses every competitor; equivalent: no competitor adds to it, and it is not named
    named = [rs[0] for rs in by_candidate.values() if all(r["encompasses"] for r in rs)]
    not_added_to = {c for c, rs in by_candidate.items() if all(r["encompasses"] or r.get("equivalent") for r in rs)}
    if not g_sig:
        # physical candidates significant, no generic term: named when one encompasses the best generic terms too
        if named:
            best = min(named, key=lambda r: _lowest_J(r, "J_P"))
            rej = ", rejected earlier" if G["name"] in rejected_generic else ""
            out.update(decision="named", added=best["candidate"], initial=float(best["estimate"]),
                       message=f"{best['candidate']} significant (p < {level:.2g}) and encompasses the best generic "
                               f"term {G['name']} (p = {G['p']:.2g}{rej}; no generic term that may be added is "
                               f"significant): with {best['candidate']} "
                               f"fitted, {G['name']} adds nothing (p = {best['p_G_given_P']:.2g} >= {alpha:g}), and it "
                               f"adds to {G['name']} (p = {best['p_P_given_G']:.2g})"
                               + _nor_does(by_candidate[best["candidate"]], G, rank) + f"; named {best['candidate']}")
            return out
        equivalent = [f for f in p_sig if f["name"] in not_added_to]
        if equivalent or G is None:
            best = min(equivalent or p_sig, key=_lowest_J)
            out.update(decision="accepted", added=best["name"], initial=float(best["estimate"]),
                       message=f"{best['name']} significant (LR {best['LR']:.3g}, p = {best['p']:.2g} < {level:.2g}); "
                               + ("no generic term that may be added is" if G and G["name"] in rejected_generic
                                  else "no generic term is")
                               + (f" (the best, {G['name']}" + (", rejected earlier" if G["name"] in rejected_generic
                                                                 else "")
                                  + f", p = {G['p']:.2g}, is equivalent to it on these data)" if G else "")
                               + ": taken by the library")
            return out
        out.update(decision="ambiguous", best_generic=G,
                   message="physical candidates significant (" + ", ".join(f["name"] for f in p_sig)
                   + ") but " + _adders(by_candidate, G, rejected_generic, alpha) + ": none added; what is left "
                   f"looks like {describe_fit(G)}, p = {G['p']:.2g}")
        return out
    if named:
        best = min(named, key=lambda r: _lowest_J(r, "J_P"))
        out.update(decision="named", added=best["candidate"], initial=float(best["estimate"]),
                   message=f"{best['candidate']} encompasses the "
                           + ("generic term rejected earlier " if G["name"] in rejected_generic else "discovered ")
                           + f"{G['name']} ({G['formula']}): with "
                           f"{best['candidate']} fitted, {G['name']} adds nothing (LR {best['LR_G_given_P']:.3g}, "
                           f"p = {best['p_G_given_P']:.2g} >= {alpha:g})"
                           + _nor_does(by_candidate[best["candidate"]], G, rank) + f"; named {best['candidate']}")
    else:
        tested = ", ".join(f"{r['candidate']} (p of {r['generic']} given it {r.get('p_G_given_P', float('nan')):.2g}, "
                           f"of it given {r['generic']} {r.get('p_P_given_G', float('nan')):.2g}"
                           + ("; equivalent on these data" if r.get("equivalent") else "") + ")" for r in rows)
        out.update(decision="discovered", added=A["name"], initial=float(A["estimate"]), discovered=A,
                   message="not explained by any library effect" + (f" (tested: {tested})" if rows else "")
                           + f"; discovered {describe_fit(A)}, p = {A['p']:.2g} < {level:.2g}")
    return out


#: the speed shapes of the generic family, in words (the rest of the regressors are states or controls)
SPEED_SHAPES = {"one": "constant over speed", "mu": "growing linearly with speed", "mu2": "growing as speed^2",
                "mu4": "growing as speed^4 (a high-speed rise)",
                **{k: f"a bump at mu = {c:.2f}" for k, c in BUMP_CENTRES.items()}}
#: the state or control a state regressor follows
STATE_WORDS = {"alpha": "angle of attack", "w": "heave velocity w", "q": "pitch rate q", "lam": "induced inflow",
               "col": "collective", "lon": "longitudinal cyclic"}
STATE_WORDS.update({f"{r}mu": f"{w} x speed" for r, w in STATE_WORDS.items() if f"{r}mu" in REGRESSORS})
#: the sign of a positive force or moment, in words (body axes: x forward, z down, M nose up)
SIGN_WORDS = {"X": ("forward", "aft"), "Z": ("down", "up"), "M": ("nose-up", "nose-down")}


def channel_shapes(scores, omega_r: float | None = None) -> list[dict]:
    """The shape of what is left, per force or moment channel (X, Z, M), from the score test over the generic family
    (no extra solve): the channel's best speed shape (constant, mu, mu^2, mu^4 or a bump) and its best state or
    control dependence (alpha, w, q, lambda_i, col, lon), each with the one-step estimate ``kappa_hat`` (its sign
    the sign of the force or moment, or of its slope against the state), LM and p, and a sentence. ``omega_r``
    [m/s] (rotor tip speed) turns a bump's mu into knots. Channels with no generic term scored are left out."""
    rows = []
    sc = scores.set_index("name")
    for ch in FORCE_CHANNELS:
        row = {"channel": f"d{ch}"}
        for kind, words in (("speed", SPEED_SHAPES), ("state", STATE_WORDS)):
            names = [f"d{ch}_{r}" for r in words if f"d{ch}_{r}" in sc.index]
            if not names:
                continue
            best = max(names, key=lambda n: float(sc.loc[n, "LM"]))
            r, k = best[3:], float(sc.loc[best, "kappa_hat"])
            pos, neg = SIGN_WORDS[ch]
            if kind == "speed":
                shape = words[r]
                if r in BUMP_CENTRES and omega_r:
                    shape = f"a bump at {BUMP_CENTRES[r] * omega_r / KT:.0f} kt"
                text = f"{pos if k > 0 else neg} d{ch}, {shape}"
            else:
                text = f"d{ch} {'rising' if k > 0 else 'falling'} with {words[r]} ({pos if k > 0 else neg} per +{r})"
            row.update({f"{kind} term": best, f"{kind} kappa_hat": k, f"{kind} LM": float(sc.loc[best, "LM"]),
                        f"{kind} p": float(sc.loc[best, "p_value"]), f"{kind} shape": text})
        if len(row) > 1:
            rows.append(row)
    return rows


def shapes_sentence(rows: list[dict]) -> str:
    """One line per channel of :func:`channel_shapes`, the stronger of speed and state first."""
    parts = []
    for r in rows:
        kinds = sorted((k for k in ("speed", "state") if f"{k} term" in r), key=lambda k: -r[f"{k} LM"])
        parts.append(f"{r['channel']}: " + "; ".join(f"{r[f'{k} shape']} ({r[f'{k} term']}, kappa = "
                                                     f"{r[f'{k} kappa_hat']:.2g}, p = {r[f'{k} p']:.2g})"
                                                     for k in kinds))
    return " | ".join(parts)


def deciding_criterion(cfg, screen: dict) -> str:
    """What a step decides on (docs/discovery.md, "Which test decides"): "likelihood ratio" (corrected,
    :func:`robust_p`) when the likelihood models the measured inputs' noise and the NLP screen's base solved, else
    "score test" (the robust score test's own p)."""
    base_failed = screen.get("base_success", True) is False
    return "likelihood ratio" if cfg.nlp.input_errors and not base_failed else "score test"


def robust_p(lr: float, row, one_sided: bool = False) -> tuple[float, float, float]:
    """The NLP's likelihood ratio corrected for coloured residuals: ``LR x LM / LM_white`` (the score test's robust
    over white-noise statistic: the white-noise variance of the score over its batch-means estimate, capped at 1 so
    the correction never makes the test more liberal), referred to F(1, df) with the score test's df (chi-square(1)
    when df is infinite). Returns (p, corrected LR, df)."""
    if math.isnan(lr):
        return float("nan"), float("nan"), float("nan")
    lm, lm_w, df = float(row["LM"]), float(row.get("LM_white", row["LM"])), float(row["df"])
    factor = min(1.0, lm / lm_w) if lm_w > 0 else 1.0
    adj = lr * factor
    ref = stats.f(1, df) if np.isfinite(df) else stats.chi2(1)
    p = float(ref.sf(adj))
    return (p / 2 if one_sided else p), adj, df


def detection_limit(fit: dict, level: float, one_sided: bool = False) -> float:
    """The smallest |c| of a judged term's shape that the corrected LR would call significant at ``level``: its
    standard error times the root of the F(1, df) (chi-square(1)) quantile the test compares ``LR_robust`` with,
    taking the profile likelihood as quadratic, ``LR_robust = (c / se)^2`` (:func:`judge`). What the data resolve:
    an effect of this shape smaller than it goes unnoticed. NaN when the fit has no standard error."""
    se, df = float(fit.get("se", math.nan)), float(fit.get("df", math.inf))
    if not (math.isfinite(se) and se > 0):
        return float("nan")
    tail = 2.0 * level if one_sided else level
    ref = stats.f(1, df) if math.isfinite(df) else stats.chi2(1)
    return se * math.sqrt(float(ref.isf(tail)))


def judge(fit: dict, score_row, one_sided: bool, criterion: str) -> dict:
    """Set a screened term's deciding ``p`` (the corrected LR's, :func:`robust_p`, or with ``criterion`` "score
    test" the score test's own, the LR's kept as ``p_robust_LR``), ``LR_robust``, ``df`` and the standard error from
    the corrected profile likelihood's curvature (``LR_robust = (c / se)^2``). Returns ``fit``."""
    fit["p"], fit["LR_robust"], fit["df"] = robust_p(fit["LR"], score_row, one_sided)
    if criterion == "score test":
        fit["p_robust_LR"], fit["p"] = fit["p"], float(score_row["p_value"])
    fit["se"] = abs(fit["estimate"]) / math.sqrt(fit["LR_robust"]) if fit["LR_robust"] > 0 else float("nan")
    return fit


def encompassing(P: dict, G: dict, pair: dict | None, alpha: float) -> dict:
    """Step 3's test of a term P against a generic term G from their NLP fits alone and together (``pair``):
    ``LR(G | P) = 2 (J_P - J_PG)`` and ``LR(P | G) = 2 (J_G - J_PG)``, each against chi-square(1) at ``alpha``.
    P encompasses G when G adds nothing once P is in and P adds something G does not; the two are equivalent on
    these data when neither adds to the other."""
    row = {}
    if pair and "single_J" in pair:  # a pair of its own NLP (_separate_screens): P and G alone in that NLP
        P = {**P, "J": pair["single_J"][P["name"]]}
        G = {**G, "J": pair["single_J"][G["name"]]}
        row["J0"] = pair["J0"]
    row.update({"candidate": P["name"], "J_P": P["J"], "J_G": G["J"], "LR_P": P["LR"], "estimate": P["estimate"],
                "shape": P["shape"]})
    if not (pair and pair["success"]):
        return {**row, "encompasses": False, "note": "joint solve failed"}
    # the pair nests each term: a pair fit above either alone stopped at a worse local optimum, and its likelihood
    # ratios (clipped at zero) would read "adds nothing"; no test then
    above = pair["J"] - min((f["J"] for f in (P, G) if f.get("success", True)), default=pair["J"])
    if not above <= PAIR_SLACK:
        return {**row, "J_PG": pair["J"], "encompasses": False, "equivalent": False,
                "note": f"joint fit ended {above:.3g} above the better term alone (a worse local optimum)"}
    lr = max(2.0 * (P["J"] - pair["J"]), 0.0)
    p = float(stats.chi2.sf(lr, 1))
    # and the other way: does P add anything once G is in? If not, the two are equivalent on these data and the
    # physics cannot be named from them
    lr_pg = max(2.0 * (G["J"] - pair["J"]), 0.0)
    p_pg = float(stats.chi2.sf(lr_pg, 1))
    return {**row, "J_PG": pair["J"], "LR_G_given_P": lr, "p_G_given_P": p, "LR_P_given_G": lr_pg, "p_P_given_G": p_pg,
            "equivalent": bool(p >= alpha and p_pg >= alpha), "encompasses": bool(p >= alpha and p_pg < alpha)}


def check_term(cfg, model, start: dict, data, term, *, level: float, against: str | None = None,
               alpha=attr.ALPHA, robust=True, score_kw=None, progress=print) -> dict:
    """Test one term, a library name or an extension object of one's own (a hypothesis: "is the missing effect
    this?"), at the current model as a structure-determination step tests a library term: the score test (its
    colour correction and df), the NLP estimate and LR (:func:`nlp_screen`), the deciding p (the corrected LR's
    with the measured inputs' noise modelled, else the score test's) against ``level``. With ``against`` (a
    generic term's name, e.g. the one a step discovered) also step 3's encompassing test both ways
    (:func:`encompassing`): does the term explain the data as well as that generic term does?

    ``cfg``, ``model``, ``start``, ``data`` as for :func:`discovery_step`. Returns a plain dict: ``term`` (the
    fit: estimate, se, LR, LR_time, LR_trim, LR_robust, df, p, status), ``score`` (LM, p), ``level``,
    ``significant``, ``criterion`` and, with ``against``, ``against`` (its fit) and ``encompassing``."""
    t = as_candidate(term)
    terms = [t] + ([against] if against else [])
    att = attr.attribute(model, [f.name for f in cfg.free], data, cfg.nlp.time_outputs, cfg.nlp.trim_outputs,
                         candidates=terms, alpha=alpha, robust=robust, **dict(score_kw or {}))
    rows = att.scores.set_index("name")
    screen = nlp_screen(cfg, start, terms, pairs=[(t.name, against)] if against else (), progress=progress)
    criterion = deciding_criterion(cfg, screen)
    fit = judge(screen["fits"][t.name], rows.loc[t.name], getattr(t, "one_sided", False), criterion)
    if criterion == "likelihood ratio":
        fit["detectable"] = detection_limit(fit, level, getattr(t, "one_sided", False))
    out = {"term": fit, "score": {"LM": float(rows.loc[t.name, "LM"]), "p": float(rows.loc[t.name, "p_value"])},
           "level": level, "significant": bool(fit["p"] < level), "criterion": criterion}
    if against:
        g = judge(screen["fits"][against], rows.loc[against], getattr(make_candidate(against), "one_sided", False),
                  criterion)
        out.update(against=g, encompassing=encompassing(fit, g, screen["pairs"].get(f"{t.name}+{against}"), alpha))
    return out


def _lowest_J(fit: dict, key: str = "J") -> float:
    """A fit's (or an encompassing row's, ``key="J_P"``) J against its NLP's base when the screen was run as
    separate NLPs (``J0`` in the record), else its J: within one NLP the order of J is that of the likelihood
    ratio."""
    return fit[key] - fit.get("J0", 0.0)


#: how a step ranks the screened generic terms (``[loop] generic_rank``): by the p it decides on, or by raw LR
GENERIC_RANKS = ("p", "likelihood_ratio")
#: the ranking other than the step's, in words (a physical candidate must encompass the best by either)
_OTHER_RANK_WORDS = {"p": "raw likelihood ratio", "likelihood_ratio": "deciding p"}


def competitors(fits: dict, rank: str = "p") -> list:
    """The generic terms a significant physical candidate must encompass to be named: the best by ``rank``
    (:func:`best_fit`, rejected terms included) and, when it is another term, the best by the other ranking.
    The two orders part when the terms' colour corrections or degrees of freedom differ; the best is then often a
    near tie (docs/discovery.md, step 4), and a name must not hang on which of the two a ranking happens to put
    first."""
    out = []
    for r in (rank, *(x for x in GENERIC_RANKS if x != rank)):
        g = best_fit(fits, True, r)
        if g is not None and all(g["name"] != o["name"] for o in out):
            out.append(g)
    return out


def _nor_does(rows: list, G: dict, rank: str) -> str:
    """A named candidate's other competitors in words: "; nor does X, the best by ... (p = ...)"."""
    return "".join(f"; nor does {r['generic']}, the best by {_OTHER_RANK_WORDS[rank]} (p = {r['p_G_given_P']:.2g})"
                   for r in rows if r["generic"] != G["name"])


def _adders(by_candidate: dict, G: dict, rejected: list, alpha: float) -> str:
    """Which competitor adds to the significant physical candidates, in words: the best generic term when it adds
    to each, else each candidate with the competitors that add to it."""
    adds = {c: [r["generic"] for r in rs if not (r["encompasses"] or r.get("equivalent"))]
            for c, rs in by_candidate.items()}
    if all(G["name"] in a for a in adds.values()):
        return (f"the best generic term {G['name']}" + (" (rejected earlier)" if G["name"] in rejected else "")
                + " adds to each of them")
    return "; ".join(f"{', '.join(a)} add{'s' if len(a) == 1 else ''} to {c} (p < {alpha:g})"
                     for c, a in adds.items() if a)


def _nan_last(x: float) -> float:
    return math.inf if math.isnan(x) else x


def best_fit(fits: dict, generic: bool, rank: str = "p"):
    """The best of the solved generic (or physical) terms of an NLP screen, or None.

    ``rank="p"``: the smallest deciding ``p`` (the test the step decides on, set by :func:`judge`), ties (a p that
    underflows to 0) broken by the larger corrected LR, then the lower J; so the term whose significance the step
    asks is the most significant one. ``rank="likelihood_ratio"``: the largest raw likelihood ratio (lowest J: the
    same order, and defined when the base solve failed), which can differ from the order of p when the terms'
    colour corrections or degrees of freedom differ."""
    if rank not in GENERIC_RANKS:
        raise ValueError(f"rank must be one of {GENERIC_RANKS}, got {rank!r}")
    ok = [f for f in fits.values() if f["generic"] == generic and f["success"] and not math.isnan(f["J"])]
    if not ok:
        return None
    if rank == "likelihood_ratio":
        return min(ok, key=_lowest_J)
    return min(ok, key=lambda f: (_nan_last(f["p"]), _nan_last(-f.get("LR_robust", math.nan)), _lowest_J(f)))
