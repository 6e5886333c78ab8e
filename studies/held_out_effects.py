"""Structure determination on flight tests whose undeclared effect is held out of the library (issue 27). A study.

    python studies/held_out_effects.py --seeds 3 --out results/held_out \
        [--effects fuselage_download drag_rise ...] [--config studies/held_out_discovery.toml] \
        [--data-config data/bo105_synthetic.toml] [--generic-family extended|control] [--input-path-family extended] \
        [--set TABLE.KEY=VALUE ...]

For every held-out effect (pyomo_heli/flighttest/held_out_effects.py, at its nominal strength) and every seed
(20261122 + k, k = FIRST..FIRST+SEEDS-1): the bundled flight test's generator config with its truth effect
replaced by the held-out one (same maneuvers, trims and noise levels) -> ``OUT/<effect>_<seed>/data``; the
closed loop with ``[loop] discovery = true`` (CONFIG) -> ``OUT/<effect>_<seed>/loop``; its table row ->
``OUT/<effect>_<seed>/row.json``. A finished loop is not rerun (an interrupted one resumes), so a rerun of the same
command resumes row by row; a finished loop made from another config text (other flags) is refused. ``--workers N``
runs the cases on N local processes (``--scheduler ADDRESS``: on a Dask cluster whose workers see OUT); the rows are
the same as one after the other.
``--effects none`` is M0 plus noise only; ``--first-seed K`` starts at seed 20261122 + K; ``--evaluate-only`` runs
nothing and re-evaluates every finished loop in OUT (rows and table); ``--rescore`` runs nothing and re-scores
``OUT/held_out.csv`` alone (shape columns and criterion, from the terms the table reports); ``--merge FOLDER...`` runs
nothing and puts the rows of FOLDER/held_out.csv in place of OUT's rows of the same truth and seed;
``--summary FOLDER...`` runs nothing and writes the tallies of several studies' tables as one table to
``OUT/summary.md``. ``--generic-family``, ``--input-path-family`` and ``--set`` run the loop (or ``--reanalyse``)
with a copy of CONFIG in OUT that sets ``[loop] generic_family``, ``[diagnosis] input_path_family`` or any field
(e.g. ``--set data.resample_inputs=record objectives.input_error_ar=4``).

Written after every case: ``OUT/held_out.csv`` and ``OUT/held_out.md``, one row per effect and seed of every
``OUT/*/row.json`` (also rows of earlier runs into the same OUT): truth, verdict, what was added,
pooled trim / identification / validation RMS of iteration 0 and of the kept model, a significant validation rise,
parameter errors against truth before and after, wrong acceptance (a physical library candidate kept although the
truth holds none), and for a discovered or described generic term whether its shape matches the truth term: for
a truth that adds a steady force or moment (through the force equations or the rotor, e.g. a tilt of the
tip-path plane; :func:`steady_force`), sign and speed dependence of the same force or moment along the level
trims (:func:`shape_match`); for one that adds a force or moment that is zero at every trim (a damping), sign and
speed dependence of its derivative along the trims, for a force or moment term (:func:`derivative_match`); for
control-path and sensor effects, and a sensor term against a damping, its trim and time signature against M0 on
the validation records (:func:`signature_match`). A kept model of several discovered terms is also scored as a
whole ("kept terms" at the kept model's estimates, "kept model matches truth", :func:`model_match`): what its terms
add together, in every channel they touch. With an "unexplained" verdict, the shape it reports (a discovered term
the validation rule rejected, else the last step's best generic term: at the iteration limit the significant term
the loop would add next) and whether that matches. The residual analysis of the kept model (:func:`final_residual`):
its verdict, where an output's records disagree on its bias whether that shape matches the truth's
(:func:`record_bias_match`), and the input error it reports with whether that follows the truth's control error
(:func:`input_path_match`). ``--reanalyse`` makes that analysis again for rows whose loops are gone and whose kept
model the table holds (:func:`reanalyse`; ``--rows CSV`` starts OUT's table from another study's, which stays as it
is).
The criterion (:func:`criterion_met`) counts a kept discovered term as a reported shape: the loop reports
it "not explained by any library effect; discovered ...". The tallies also read the criterion with the trim cut
measured above the noise floor (:func:`criterion_met_above_floor`), beside the issue's reading. The trim RMS of
the truth model (M0 + the held-out effect at the truth parameters: only the trim noise and offsets are left) is the
floor; "trim change possible %" is the cut from iteration 0 to that floor, and "share of possible trim cut %" the part
of it the loop achieved (shown where at least 5 % is possible). On the validation maneuvers (as CONFIG prepares
them), each output's RMS over the truth model's, before and after (1: as good as the truth), and in the md table
the output worst before. Could the data name the missing effect at all (:func:`truth_form_check`)? The truth's
own form, its strength free, tested at iteration 0 as the loop tests a library term: its estimate and LR ("truth
form at M0"), the loop's p ("truth form p"), whether that is below the loop's level ("truth form significant") and
the strength from which it would be ("truth form significant from": a truth strength below it is too weak for these
data by the loop's test).
Evaluation only: this script reads truth.json and the held-out module; the loop does not.
"""
from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import math
import re
import shutil
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without installing

from pyomo_heli.studies.commands import exit_status, run_command  # noqa: E402
from pyomo_heli.cli.options import nonneg_int  # noqa: E402
from pyomo_heli.flighttest.held_out_effects import HELD_OUT_EFFECTS, HELD_OUT_STRENGTHS  # noqa: E402
from pyomo_heli.physics.discrepancy import FAMILIES, is_force_term  # noqa: E402
from pyomo_heli.studies.args import in_file, out_folder, positive_int  # noqa: E402
from pyomo_heli.parallel import check_dask_flags  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
PARAMETERS = ("theta_twist", "CL_alpha_HT", "Iyy")
#: a possible trim cut smaller than this [%] is within the noise: no share of it is reported
POSSIBLE_CUT_MIN = 5.0
CONFIG = ROOT / "studies" / "held_out_discovery.toml"
TRIM = ("col", "lon", "theta")
OUTPUTS = ("q", "theta", "n_x", "n_z", "TAS", "beta_0")
SPEEDS_KT = (0, 10, 20, 30, 40, 50, 60, 70, 80, 90, 100, 110, 120)


def data_config(template: str, effect: str, seed: int, strengths: dict | None = None) -> str:
    """The generator config ``template`` (TOML text) with its [truth.effects.*] tables replaced by ``effect`` and its
    seed by ``seed`` (``effect`` "none": no effect)."""
    text = re.sub(r"\n\[truth\.effects\.[^\]]+\][^\[]*", "\n", template)
    text = re.sub(r"(?m)^seed = \d+", f"seed = {seed}", text)
    text = text.replace("M0 + wake on tail", f"M0 + {effect} (held out)" if effect != "none" else "M0 only")
    if effect != "none":
        vals = (strengths or HELD_OUT_STRENGTHS)[effect]
        block = f"[truth.effects.{effect}]\n" + "".join(f"{k} = {v!r}\n" for k, v in vals.items()) + "\n"
        text = text.replace("\n[sensors]", "\n" + block + "[sensors]", 1)
    return text


class StudyFolderError(ValueError):
    """A case folder holds another study's files (the folder given is at fault, not the code)."""


class StudyConfigError(ValueError):
    """The study's config cannot evaluate a finished loop (the config given is at fault, not the code)."""


def generate_case(case: Path, template: str, effect: str, seed: int) -> Path:
    """The flight test of ``effect`` and ``seed`` in ``case/data`` (generated unless it is there): its generator
    config ``case/gen.toml`` is ``template`` with the truth effect and seed replaced (:func:`data_config`)."""
    data, wanted = case / "data", data_config(template, effect, seed)
    if (data / "truth.json").is_file() and (case / "gen.toml").is_file() and (case / "gen.toml").read_text() != wanted:
        raise StudyFolderError(f"{case}: its flight test was generated from another generator config "
                               f"({case / 'gen.toml'}); give this study another folder")
    if not (data / "truth.json").is_file():
        case.mkdir(parents=True, exist_ok=True)
        (case / "gen.toml").write_text(wanted)
        run_command(["generate-data", "--config", str(case / "gen.toml"), "--out", str(data)])
    return data


def run_case(effect: str, seed: int, out: Path, config: Path, template: str) -> Path:
    """The closed loop of ``config`` on the flight test of ``effect`` and ``seed``, run unless ``OUT/<case>/loop``
    holds it finished from the same config and flight test (:func:`~pyomo_heli.workflows.close_loop.finished_loop`:
    another config's loop is refused); the loop folder."""
    from pyomo_heli.workflows.close_loop import LoopMismatchError, finished_loop

    case = out / f"{effect}_{seed}"
    data, loop = generate_case(case, template, effect, seed), case / "loop"
    try:
        done = finished_loop(loop, config, data)  # a loop not stopped resumes
    except LoopMismatchError as exc:  # one of another config or flight test: this OUT is another study's
        raise StudyFolderError(str(exc)) from None
    if not done:
        t0 = time.perf_counter()
        run_command(["close-loop", str(config), "--dataset", str(data), "--out", str(loop)])
        print(f"{effect} {seed}: loop done in {time.perf_counter() - t0:.0f} s", flush=True)
    return loop


def extensions_of(extension) -> tuple:
    """One extension or several (a kept model's terms) as a tuple; () for None."""
    if extension is None:
        return ()
    return tuple(extension) if isinstance(extension, (tuple, list)) else (extension,)


def level_trims(extension, strengths: dict):
    """M0 with ``extension`` (one, or a sequence of several) at ``strengths`` and its level trims at SPEEDS_KT:
    (model, [(states, inputs)]), SI."""
    from pyomo_heli.physics.model import HelicopterModel
    from pyomo_heli.simulation.trim import trim_float
    from pyomo_heli.units import KT

    m = HelicopterModel(extensions=extensions_of(extension)).with_parameters(**strengths)
    points = []
    for v in SPEEDS_KT:
        tp = trim_float(m, v * KT)
        points.append(({"u": tp.u, "w": tp.w, "q": 0.0, "theta": tp.theta, "lambda_i": tp.lambda_i,
                        **tp.extra_states}, {"col": tp.col, "lon": tp.lon}))
    return m, points


def steady_force(extension, strengths: dict, channel: str) -> np.ndarray:
    """The force (X, Z) or moment (M) ``extension`` (one, or several together) adds along its level trims
    (:func:`level_trims`), SI: the total force of M0 with it at ``strengths`` minus M0's (the extension at zero
    strength) at the same states and controls, so a term added to the force equations (``extra_forces``) and one that
    acts through the rotor (e.g. a tilt of the tip-path plane, ``tip_path_plane``) are measured alike."""
    m, points = level_trims(extension, strengths)
    m0 = m.with_parameters(**dict.fromkeys(strengths, 0.0))
    return np.array([float(getattr(m.evaluate(x, u).forces, channel) - getattr(m0.evaluate(x, u).forces, channel))
                     for x, u in points])


def acts_on_controls(extension) -> bool:
    """Does ``extension`` change the controls the rotor sees (``adjust_controls``)? Its force at given stick
    positions is the rotor's answer to other controls: such a truth is compared by its signature."""
    from pyomo_heli.physics.extensions import Extension

    return type(extension).adjust_controls is not Extension.adjust_controls


@functools.lru_cache(maxsize=64)
def truth_curve(effect: str, channel: str) -> np.ndarray | None:
    """The truth effect's steady force (X, Z) or moment (M) along the truth's level trims (:func:`steady_force`);
    None if it adds none there, or acts on the control path (:func:`acts_on_controls`)."""
    if effect == "none" or acts_on_controls(HELD_OUT_EFFECTS[effect]()):
        return None
    vals = steady_force(HELD_OUT_EFFECTS[effect](), HELD_OUT_STRENGTHS[effect], channel)
    return None if not np.any(np.abs(vals) > 1e-9) else vals


#: a channel whose truth force (in the family's units: X, Z by m g, M by m g R) is below this share of the truth's
#: largest channel is not where its shape is: a term there matches nothing
MINOR_CHANNEL = 0.1


def minor_channel(effect: str, channel: str) -> bool:
    """Is ``channel`` a minor one of the truth's steady force (:data:`MINOR_CHANNEL`)?"""
    from pyomo_heli.physics.discrepancy import force_scale
    from pyomo_heli.physics.parameters import bo105

    p = bo105().to_dict()
    size = {ch: (0.0 if (c := truth_curve(effect, ch)) is None else float(np.max(np.abs(c))) / force_scale(p, ch))
            for ch in "XZM"}
    return size[channel] < MINOR_CHANNEL * max(size.values())


def curve_match(truth: np.ndarray, vals: np.ndarray) -> str:
    """Do two curves over SPEEDS_KT agree in sign and speed dependence? 'yes' when their correlation over speed is
    > 0.7 and they agree in sign at the speed of the truth's largest |value|; a curve constant over speed has no
    speed dependence to match (two constants match by sign)."""
    k = int(np.argmax(np.abs(truth)))
    # constant over speed (to rounding): a correlation is not defined, and a constant has no speed dependence to match
    flat = [np.ptp(a) <= 1e-9 * np.max(np.abs(a)) for a in (vals, truth)]
    if all(flat):
        corr = float(np.sign(truth[k] * vals[k]))
    elif any(flat):
        return "no (" + ("the term" if flat[0] else "the truth") + " is constant over speed)"
    else:
        corr = float(np.corrcoef(truth, vals)[0, 1])
    return "yes" if corr > 0.7 and np.sign(vals[k]) == np.sign(truth[k]) else f"no (corr {corr:+.2f})"


def shape_match(effect: str, fit: dict | None) -> str:
    """Does a generic term's force or moment along the level trims match the truth's in sign and speed dependence
    (:func:`curve_match`)? 'n/a' without a force/moment term or a truth force in that channel."""
    from pyomo_heli.physics.discrepancy import generic_term

    if not fit or not is_force_term(fit["name"]):
        return "n/a"
    ch = fit["name"][1]
    truth = truth_curve(effect, ch)
    if truth is None:
        return "n/a"
    if minor_channel(effect, ch):
        return f"no (the truth adds little in {ch})"
    t = generic_term(fit["name"])
    return curve_match(truth, steady_force(t, {t.strength: fit["estimate"]}, ch))


#: the states and controls a force derivative is taken with respect to, with the sizes that weigh them against each
#: other (the discrepancy family's regressor scales, physics/discrepancy.py: w 5 m/s, q 0.2 rad/s, col 0.2 rad, lon
#: 0.05 rad; u as w) and the central-difference steps (SI)
DERIVATIVE_SCALES = {"u": 5.0, "w": 5.0, "q": 0.2, "col": 0.2, "lon": 0.05}
DERIVATIVE_STEPS = {"u": 0.1, "w": 0.1, "q": 0.005, "col": 0.001, "lon": 0.001}


def force_derivatives(extension, strengths: dict, channel: str) -> dict:
    """d(force or moment in ``channel``)/d(state or control) that ``extension`` (one, or several: their sum) adds,
    along the level trims of M0 with it at ``strengths`` (central differences, SI): state -> array over SPEEDS_KT."""
    exts = extensions_of(extension)
    m, points = level_trims(exts, strengths)
    i = "XZM".index(channel)
    out = {s: [] for s in DERIVATIVE_STEPS}
    for x, u in points:
        for s, h in DERIVATIVE_STEPS.items():
            f = []
            for sign in (1.0, -1.0):
                xx, uu = dict(x), dict(u)
                (xx if s in xx else uu)[s] += sign * h
                ctx = m.evaluate(xx, uu)
                f.append(sum(float(np.asarray(e.extra_forces(ctx)[i])) for e in exts))
            out[s].append((f[0] - f[1]) / (2 * h))
    return {s: np.array(a) for s, a in out.items()}


def scaled_sizes(derivatives: dict) -> dict:
    """Each derivative's largest |value| along the trims times its state's scale (:data:`DERIVATIVE_SCALES`)."""
    return {s: float(np.max(np.abs(a))) * DERIVATIVE_SCALES[s] for s, a in derivatives.items()}


@functools.lru_cache(maxsize=64)
def truth_derivative(effect: str, channel: str) -> tuple[str, np.ndarray] | None:
    """The truth effect's dominant force derivative in ``channel`` along the level trims (the state whose derivative
    times its scale, :data:`DERIVATIVE_SCALES`, is largest) as (state, curve), for a truth that adds a force or moment
    with no steady value through M0's states alone (e.g. a damping); None otherwise. A truth with states of its own
    (a lag, a mode) has no such quasi-steady derivative with them held, so it is compared by its signature."""
    if effect == "none":
        return None
    e = HELD_OUT_EFFECTS[effect]()
    if e.states or truth_curve(effect, channel) is not None:
        return None
    d = force_derivatives(e, HELD_OUT_STRENGTHS[effect], channel)
    size = scaled_sizes(d)
    s = max(size, key=size.get)
    return (s, d[s]) if size[s] > 1e-9 else None


def derivative_match(effect: str, fit: dict | None) -> str:
    """Does a generic force or moment term match, in sign and speed dependence (:func:`curve_match`), the truth's
    dominant force derivative (:func:`truth_derivative`), e.g. a pitch damping dM/dq that grows with speed? For a
    truth whose force or moment is zero at every trim, where its steady curve says nothing. 'n/a' without a
    force/moment term or such a truth derivative in its channel."""
    from pyomo_heli.physics.discrepancy import generic_term

    if not fit or not is_force_term(fit["name"]):
        return "n/a"
    truth = truth_derivative(effect, fit["name"][1])
    if truth is None:
        return "n/a"
    t = generic_term(fit["name"])
    return derivative_verdict(truth, force_derivatives(t, {t.strength: fit["estimate"]}, fit["name"][1]))


def derivative_verdict(truth: tuple[str, np.ndarray], derivatives: dict, what: str = "the term does") -> str:
    """The truth's dominant derivative (state, curve) against a model's ``derivatives`` (:func:`force_derivatives`):
    :func:`curve_match` of the same state's derivative, or 'no' when the model hardly depends on that state."""
    s, curve = truth
    size = scaled_sizes(derivatives)
    if size[s] <= 0.01 * max(size.values()):  # to rounding (mu moves with q through the hub's velocity)
        return f"no ({what} not depend on {s})"
    return curve_match(curve, derivatives[s])


#: a time signature matches when what the best positive multiple of the term leaves of the truth's is below
#: detection: its noncentrality (sum of squares in noise standard deviations) under the chi-square(1) 0.99 quantile
SIGNATURE_LEFT_MAX = 6.63
SIGNATURE_DATA = ROOT / "data" / "bo105_synthetic"
#: its generator config: the template of the full-size held-out flight tests (--data-config's default)
BUNDLED_TEMPLATE = ROOT / "data" / "bo105_synthetic.toml"


@dataclasses.dataclass(frozen=True, eq=False)  # hashed by identity (a cache key)
class SignatureSetup:
    """Where signatures are taken: validation records, the M0 truth parameters (SI) and the noise standard
    deviations of the outputs and trims (SI), with M0's prediction there."""

    maneuvers: tuple
    m0: dict
    sigma: dict
    trim_sigma: dict

    @functools.cached_property
    def base(self):
        return self.predict(None, {})

    def predict(self, extension, strengths: dict):
        from pyomo_heli.physics.model import HelicopterModel
        from pyomo_heli.simulation.replay import predict
        from pyomo_heli.units import KT

        model = HelicopterModel(extensions=extensions_of(extension))
        return predict("signature", model.with_parameters(**self.m0, **strengths), {},
                       [v * KT for v in SPEEDS_KT], list(self.maneuvers))


def signature_setup(config: str = str(CONFIG), template: str | None = None, cache: str | None = None) -> SignatureSetup:
    """The validation records (as ``config`` prepares them), M0 truth parameters and noise levels of the flight tests
    the study generates from the generator config ``template`` (its text; None: the bundled flight test's,
    ``data/bo105_synthetic.toml``). For the bundled template the bundled flight test itself: the held-out flight tests
    share its maneuvers, trims, noise levels and M0 parameters. For another (the small instance's one 6 s validation
    record) a flight test generated from it with no effect (seed 20261122) into ``cache/signature_reference``
    (:func:`signature_cache`): a row's signature is judged on the records its own flight test has."""
    if template is not None and template == BUNDLED_TEMPLATE.read_text():
        template, cache = None, None  # one setup (and one cache of its signatures) for the bundled flight test
    return _signature_setup(str(config), template, cache)


@functools.lru_cache(maxsize=4)
def _signature_setup(config: str, template: str | None, cache: str | None) -> SignatureSetup:
    from pyomo_heli.config import load_identification_config
    from pyomo_heli.dataset import load_flight_test
    from pyomo_heli.nlp.identification import validation_maneuvers
    from pyomo_heli.physics.model import HelicopterModel

    if template is None:
        data = SIGNATURE_DATA
    else:
        if cache is None:
            raise ValueError("signature_setup: a generator config other than the bundled one needs a cache folder")
        data = reference_flight_test(Path(cache), template)
    cfg = load_identification_config(config, overrides={"data": {"dataset": str(data)}})
    truth = json.loads((data / "truth.json").read_text())
    names = {sp.name for sp in HelicopterModel().parameters.specs()}
    return SignatureSetup(tuple(validation_maneuvers(cfg, load_flight_test(data))),
                          {k: v for k, v in truth["parameters"].items() if k in names},
                          truth["sensor_sigma_si"], truth["trim_sigma_si"])


def reference_flight_test(cache: Path, template: str) -> Path:
    """``cache/signature_reference/data``: the flight test of ``template`` with no effect (seed 20261122), generated
    once. Cases running at once may each ask for it: each generates into a folder of its own and renames it into
    place, the first one wins (a rename onto a folder that holds files fails)."""
    import os
    import tempfile

    ref = cache / "signature_reference"
    if not (ref / "data" / "truth.json").is_file():
        cache.mkdir(parents=True, exist_ok=True)
        mine = Path(tempfile.mkdtemp(dir=cache, prefix="reference_"))
        generate_case(mine, template, "none", seeds_of(0, 1)[0])
        try:
            os.replace(mine, ref)
        except OSError:  # another case put it there first
            shutil.rmtree(mine, ignore_errors=True)
    return ref / "data"


def signature_cache(template: str) -> Path:
    """Where :func:`signature_setup` generates the reference flight test of a generator config other than the
    bundled one: a folder of the system's temporary directory named by the config's content and the package's
    sources (never a results folder; the same config and code find it again, another config or generator never)."""
    import hashlib
    import tempfile

    from pyomo_heli.provenance import source_sha256

    key = hashlib.sha256((source_sha256() + template).encode()).hexdigest()[:16]
    return Path(tempfile.gettempdir()) / f"pyomo_heli_signature_{key}"


def signature(extension, strengths: dict, setup: SignatureSetup) -> np.ndarray | None:
    """What ``extension`` at ``strengths`` changes against M0 (both at the setup's M0 parameters), in noise standard
    deviations: the level trims (col, lon, theta at SPEEDS_KT) and the records' outputs, stacked; None if a trim or
    a replay fails."""
    return signature_of(setup.predict(extension, strengths), setup)


def signature_of(pred, setup: SignatureSetup) -> np.ndarray | None:
    """:func:`signature` of a prediction ``pred`` made at the setup (:meth:`SignatureSetup.predict`)."""
    from pyomo_heli.units import KT

    base = setup.base
    if pred.problems or base.problems:
        return None
    speeds = [v * KT for v in SPEEDS_KT]
    a, b = pred.trim_table(speeds), base.trim_table(speeds)
    parts = [(a[c].to_numpy() - b[c].to_numpy()) / setup.trim_sigma[c] for c in TRIM]
    parts += [(pred.maneuvers[mv.name][o].to_numpy() - base.maneuvers[mv.name][o].to_numpy()) / setup.sigma[o]
              for mv in setup.maneuvers for o in OUTPUTS]
    return np.concatenate(parts)


@functools.lru_cache(maxsize=4)
def truth_prediction(effect: str, setup: SignatureSetup):
    """The truth model's prediction of the validation records (M0 truth parameters plus the effect at its strength)."""
    return setup.predict(HELD_OUT_EFFECTS[effect](), HELD_OUT_STRENGTHS[effect])


@functools.lru_cache(maxsize=16)
def truth_signature(effect: str, setup: SignatureSetup) -> np.ndarray | None:
    return signature_of(truth_prediction(effect, setup), setup)


def signature_match(effect: str, fit: dict | None, setup: SignatureSetup | None = None) -> str:
    """Does a generic term's trim and time signature match the truth effect's? For a truth with no steady force or
    moment (control-path and sensor effects), where "sign and speed dependence" of a force means nothing.
    'yes' when the best positive multiple of the term's signature (:func:`signature`) leaves less than
    :data:`SIGNATURE_LEFT_MAX` of the truth's; 'no (left L of T)' otherwise; 'n/a' when a replay fails."""
    from pyomo_heli.physics.discrepancy import generic_term

    if not fit:
        return "n/a"
    setup = setup or signature_setup()
    s = truth_signature(effect, setup)
    t = generic_term(fit["name"])
    return signature_verdict(s, signature(t, {t.strength: fit["estimate"]}, setup))


def signature_verdict(truth: np.ndarray | None, sig: np.ndarray | None) -> str:
    """'yes' when the best positive multiple of ``sig`` leaves less than :data:`SIGNATURE_LEFT_MAX` of the truth's
    signature ``truth``; 'no (left L of T)' otherwise; 'n/a' without both."""
    if truth is None or sig is None or not np.any(sig):
        return "n/a"
    if float(truth @ truth) < SIGNATURE_LEFT_MAX:  # every term would "leave less" of it: no test
        return f"n/a (the truth's signature, {float(truth @ truth):.3g}, is below detection)"
    beta = float(truth @ sig / (sig @ sig))
    left = float(np.sum((truth - max(beta, 0.0) * sig) ** 2))
    return "yes" if beta > 0 and left < SIGNATURE_LEFT_MAX else f"no (left {left:.3g} of {float(truth @ truth):.3g})"


def has_steady_force(effect: str) -> bool:
    return any(truth_curve(effect, ch) is not None for ch in "XZM")


def has_force_derivative(effect: str) -> bool:
    return any(truth_derivative(effect, ch) is not None for ch in "XZM")


def match(effect: str, fit: dict | None, setup: SignatureSetup | None = None) -> str:
    """The shape test of the study criterion, the truth's sign and speed dependence where it has them:
    :func:`shape_match` (the force or moment along the trims) for a truth that adds a steady force or moment;
    :func:`derivative_match` (its derivative along the trims) for a force or moment term where the truth adds one
    that is zero at every trim (a damping); :func:`signature_match` otherwise (control-path and sensor effects, a
    sensor term against a damping)."""
    if effect == "none" or not fit:
        return "n/a" if effect == "none" else "-"
    if has_steady_force(effect):
        return shape_match(effect, fit)
    if has_force_derivative(effect) and is_force_term(fit["name"]):
        return derivative_match(effect, fit)
    return signature_match(effect, fit, setup)


def model_match(effect: str, fits: list[dict], setup: SignatureSetup | None = None) -> str:
    """:func:`match` for the kept model of several discovered terms, all at their estimates: for a truth with a steady
    force or moment, the force the model's force and moment terms add together in each channel they touch
    (:func:`steady_force` of them all); for a damping truth, their summed derivative in each channel they touch
    (:func:`force_derivatives`); otherwise (control-path and sensor truths) the signature of all of them together
    (:func:`signature`). 'yes' when every channel the terms touch matches (a channel where the truth adds little or
    nothing matches nothing, as for one term), 'no (channel: why; ...)' otherwise. One term: :func:`match`."""
    from pyomo_heli.physics.discrepancy import generic_term

    if effect == "none" or not fits:
        return "n/a" if effect == "none" else "-"
    if len(fits) == 1:
        return match(effect, fits[0], setup)
    terms = [generic_term(f["name"]) for f in fits]
    strengths = {t.strength: f["estimate"] for t, f in zip(terms, fits)}
    forces = [(t, f) for t, f in zip(terms, fits) if is_force_term(f["name"])]
    channels = sorted({f["name"][1] for _, f in forces}, key="XZM".index)
    force_strengths = {t.strength: f["estimate"] for t, f in forces}
    verdicts = {}
    steady = has_steady_force(effect)
    if steady or (has_force_derivative(effect) and forces):
        if not forces:
            return "n/a"
        for ch in channels:
            if steady:
                truth = truth_curve(effect, ch)
                if truth is None:
                    verdicts[ch] = "no (the truth adds nothing here)"
                elif minor_channel(effect, ch):
                    verdicts[ch] = "no (the truth adds little here)"
                else:
                    verdicts[ch] = curve_match(truth, steady_force([t for t, _ in forces], force_strengths, ch))
            else:
                truth = truth_derivative(effect, ch)
                if truth is None:
                    verdicts[ch] = "no (the truth adds no derivative here)"
                    continue
                verdicts[ch] = derivative_verdict(
                    truth, force_derivatives([t for t, _ in forces], force_strengths, ch), "the terms do")
        if all(v == "yes" for v in verdicts.values()):
            return "yes"
        return "no (" + "; ".join(f"{ch}: {v}" for ch, v in verdicts.items()) + ")"
    setup = setup or signature_setup()
    return signature_verdict(truth_signature(effect, setup), signature(terms, strengths, setup))


def format_terms(fits: list[dict]) -> str:
    """Terms as the table prints them: ``name: c = X +- SE; ...`` ('-' for none)."""
    return "; ".join(f"{f['name']}: c = {f['estimate']:.3g} +- {f['se']:.2g}" for f in fits) or "-"


def parse_terms(text) -> list[dict]:
    """A table's :func:`format_terms` cell back to fits."""
    return [f for part in str(text).split("; ") if (f := parse_term(part.strip()))]


def kept_model_shape(row: dict) -> str:
    """The shape verdict of the row's kept model: "kept model matches truth" where the row records all its kept
    terms ("kept terms"); else its first discovered term's ("shape matches truth": the only one, or a row made
    before the table recorded them all)."""
    whole = str(row.get("kept model matches truth", ""))
    return whole if whole not in ("", "-", "nan") else str(row.get("shape matches truth", "-"))


def criterion_met(row: dict) -> bool | str:
    """Issue 27's criterion for a row: no wrong acceptance, no significant validation rise of a kept step, and either
    a discovered term kept that cuts the pooled trim RMS by >= 50 %, or an "unexplained" verdict whose reported shape
    matches the truth's. A kept discovered model is such a verdict (the loop reports it "not explained by any library
    effect; discovered ..."), scored as a whole (:func:`kept_model_shape`: all its terms together, or its first term
    in a row made before the table recorded them all); so are the shape the loop reports when it stops unexplained,
    the shape of an output's record biases that the residual analysis of the kept model reports
    (:func:`record_bias_match`), and the input error it reports (:func:`input_path_match`) where the loop kept no
    discovered term: after a kept term the input error describes what that term left, which is not the truth's
    effect to compare with."""
    if row["truth"] == "none":
        return "n/a"
    kept = row.get("kept discovered term", "-") != "-"
    return bool(not row["wrong acceptance"] and row["significant val rise (kept steps)"] == "none"
                and ((kept and float(row["trim change %"]) <= -50.0)
                     or (kept and kept_model_shape(row) == "yes")
                     or row["unexplained shape matches truth"] == "yes"
                     or str(row.get("record bias shape matches truth", "-")).startswith("yes")
                     or (not kept and str(row.get("input path shape matches truth", "-")).startswith("yes"))))


#: the second reading's trim cut: this share [%] of the cut the truth model makes (the part of the trim RMS above the
#: noise floor), where that cut is at least POSSIBLE_CUT_MIN
FLOOR_SHARE_MIN = 50.0


def criterion_met_above_floor(row: dict) -> bool | str:
    """The criterion read with the trim cut measured above the noise floor: as :func:`criterion_met`, but a kept
    discovered term counts when it achieves at least half of the trim cut the truth model makes ("share of possible
    trim cut %" >= 50, where the truth model cuts at least POSSIBLE_CUT_MIN %), not half of the pooled trim RMS, which
    holds the trims' noise that no model removes. Reported beside the issue's own reading, never in its place."""
    if row["truth"] == "none":
        return "n/a"
    share = pd.to_numeric(row.get("share of possible trim cut %", "-"), errors="coerce")  # "-": NaN, not counted
    kept = row.get("kept discovered term", "-") != "-"
    literal = row["criterion met"] in (True, "True") if "criterion met" in row else criterion_met(row) is True
    return bool(literal
                or (kept and not row["wrong acceptance"] and row["significant val rise (kept steps)"] == "none"
                    and share >= FLOOR_SHARE_MIN))


def truth_floor(dataset: Path, config: Path) -> dict:
    """The truth model's errors (report.identification.truth_model_errors) on the trims and on the validation
    records as the loop's ``config`` replays them."""
    from pyomo_heli.config import load_identification_config
    from pyomo_heli.dataset import load_flight_test
    from pyomo_heli.nlp.identification import validation_maneuvers
    from pyomo_heli.report.identification import truth_model_errors

    cfg = load_identification_config(config, overrides={"data": {"dataset": str(dataset)}})
    ft = load_flight_test(dataset)
    return truth_model_errors(dataset, validation_maneuvers(cfg, ft), ft.trims.reset_index(drop=True))


def validation_joint_p(doc: dict, config: Path = CONFIG) -> float | str:
    """One-sided p of a rise of the joint validation error (all outputs, the report's "all outputs (joint)" row) of
    the kept model against iteration 0, from their replays; "-" when the loop kept iteration 0. (The validation rule
    tests each step against the model before it; this compares the loop's end with its start.)"""
    from pyomo_heli.config import load_identification_config
    from pyomo_heli.dataset import load_flight_test
    from pyomo_heli.nlp.identification import validation_maneuvers
    from pyomo_heli.report.loop import JOINT, final_index, iterations_validation_change

    its = doc["iterations"]
    kept = its[final_index(doc)]
    if kept is its[0]:
        return "-"
    cfg = load_identification_config(config, overrides={"data": {"dataset": doc["dataset"]}})
    tab = iterations_validation_change(cfg, its[0], kept, validation_maneuvers(cfg, load_flight_test(doc["dataset"])))
    return float(tab.loc[tab["output"] == JOINT, "p (rise)"].iloc[0])


#: the truth form's strength is estimated within this multiple of its nominal value (0 to it for a time constant)
TRUTH_FORM_RANGE = 10.0


def truth_form(effect: str):
    """The held-out effect itself as a term to score and estimate: its strength bounded (+-TRUTH_FORM_RANGE x
    nominal; a time constant from 0, one-sided, with the secant step of the library's time shifts) and its other
    parameters at their truth values."""
    cls = HELD_OUT_EFFECTS[effect]
    nominal = abs(HELD_OUT_STRENGTHS[effect][cls.strength])

    class TruthForm(cls):
        lag = any(s.name == cls.strength and s.unit == "s" for s in cls().parameters())
        one_sided = lag
        score_step = 0.02 if lag else None
        shape_parameters = ()

        def parameters(self):
            lo = 0.0 if self.lag else -TRUTH_FORM_RANGE * nominal
            return [dataclasses.replace(s, bounds=(lo, TRUTH_FORM_RANGE * nominal), scale=nominal)
                    if s.name == self.strength else s for s in super().parameters()]

    return TruthForm()


def truth_form_check(effect: str, loop: Path, config: Path = CONFIG) -> dict:
    """Could the data name the missing effect at all? The truth's own form (:func:`truth_form`) tested at the loop's
    iteration 0 (M0 at its estimate) as the loop tests a library term
    (:func:`pyomo_heli.workflows.check_effect.check_effect`): its NLP estimate and LR, the loop's deciding p
    against the loop's level (alpha / library size). Evaluation only (the loop never sees this term); cached in
    ``<case>/truth_form.json``."""
    from pyomo_heli.workflows.check_effect import check_effect

    cache = loop.parent / "truth_form.json"
    strength = HELD_OUT_STRENGTHS[effect]
    if cache.is_file():
        old = json.loads(cache.read_text())
        if old.get("truth strength") == strength:
            return old
    r = check_effect(loop, truth_form(effect), iteration=0, config=config, against=None, progress=lambda s: None)
    fit = r["term"]
    out = {"truth strength": strength, "estimate": fit["estimate"], "LR": fit["LR"], "LR time": fit["LR_time"],
           "LR trim": fit["LR_trim"], "LR corrected": fit["LR_robust"], "df": fit["df"], "score LM": r["score"]["LM"],
           "score p": r["score"]["p"], "p": fit["p"], "level": r["level"], "significant": r["significant"],
           "status": fit["status"]}
    cache.write_text(json.dumps(out, indent=1))
    return out


def truth_form_detectable(effect: str, tf: dict) -> float:
    """The strength from which the truth's own form would be significant at the loop's level (its detection limit:
    :func:`pyomo_heli.diagnosis.discovery.detection_limit` from the check's corrected LR, df and level): a truth
    below it is one these data cannot name by the loop's test. NaN when the check has no corrected LR."""
    from pyomo_heli.diagnosis.discovery import detection_limit

    lr, est = float(tf.get("LR corrected", math.nan)), float(tf.get("estimate", math.nan))
    if not (lr > 0 and math.isfinite(est)):
        return math.nan
    fit = {"se": abs(est) / math.sqrt(lr), "df": float(tf.get("df", math.inf))}
    return detection_limit(fit, float(tf["level"]), truth_form(effect).one_sided)


#: the residual analysis a cached final verdict was made with (a new test in diagnosis/ invalidates the cache)
RESIDUAL_ANALYSIS = ("trim shape, whiteness, record biases (scaled by each record's innovation RMS), input path "
                     "(stepwise regression of the input errors, corrected for the input noise; parameter shift from "
                     "the inputs less their expected error)")


def made_with_of(loop: Path, rec: dict, doc: dict, cfg) -> dict:
    """The analysis settings (:func:`pyomo_heli.workflows.close_loop.analysis_settings`) of the config an iteration's
    results were made with: the text its ``chosen.json`` records (``info.config_text``; the loop's config file may
    have been rewritten since, e.g. by a study's ``--set``), read beside that file so its relative paths hold; ``cfg``
    (the config as it is now) for results that record none."""
    import tempfile

    from pyomo_heli.config import load_identification_config
    from pyomo_heli.workflows.close_loop import analysis_settings

    info = json.loads((loop / rec["results_dir"] / "chosen.json").read_text()).get("info") or {}
    text = info.get("config_text")
    if not text:
        return analysis_settings(cfg)
    with tempfile.NamedTemporaryFile("w", suffix=".toml", dir=Path(doc["config"]).parent) as f:
        f.write(text)
        f.flush()
        return analysis_settings(load_identification_config(f.name, overrides={"data": {"dataset": doc["dataset"]}}))


def final_residual(loop: Path, config: Path | None = None) -> dict:
    """The residual analysis of the model the loop kept (``residual_verdict`` of the loop, the same call), made
    with the current analysis: a loop run before a test was added to it reports its older verdict in
    ``loop.json``. With ``config`` (the study's) whose ``[diagnosis]`` differs from what the loop's analysis was made
    with (another replay, say), the analysis is made again with the study's ``[diagnosis]`` (its resampling must be
    the loop's). What the loop's was made with: its record's ``made_with``, else (a loop run before the record held
    it) the config text the kept iteration's results record (:func:`made_with_of`). Cached in
    ``<case>/final_residual.json`` (with the settings, when they are not the loop's). A loop without its
    iteration's results folder keeps the verdict of its ``loop.json``."""
    from pyomo_heli.config import load_identification_config
    from pyomo_heli.report.loop import final_index
    from pyomo_heli.workflows.check_effect import loop_iteration
    from pyomo_heli.workflows.close_loop import analysis_settings, residual_verdict

    doc = json.loads((loop / "loop.json").read_text())
    said = doc["iterations"][-1].get("residual_diagnosis") or {}
    rec = doc["iterations"][final_index(doc)]
    has_results = (loop / rec.get("results_dir", "-") / "chosen.json").is_file()
    cfg, made_with = None, None  # made_with: the study's settings where they are not the loop's
    if config is not None and has_results:
        _, rec, cfg = loop_iteration(loop, rec["iteration"], doc["config"])
        study = load_identification_config(config, overrides={"data": {"dataset": doc["dataset"]}})
        ours, theirs = analysis_settings(study), said.get("made_with") or made_with_of(loop, rec, doc, cfg)
        if ours != theirs:
            if (ours["resample_hz"], ours["resample_inputs"]) != (theirs["resample_hz"], theirs["resample_inputs"]):
                raise StudyConfigError(f"{config}: resamples the inputs otherwise than the loop {loop} "
                                 f"({ours['resample_hz']} Hz {ours['resample_inputs']} against {theirs['resample_hz']} "
                                 f"Hz {theirs['resample_inputs']}): its residual analysis would be of another fit")
            cfg = dataclasses.replace(cfg, diagnosis=study.diagnosis_settings)
            made_with = ours
    if "input_path" in said and made_with is None:  # the loop ran with the current analysis
        return {"analysis": RESIDUAL_ANALYSIS, **said}
    cache = loop.parent / "final_residual.json"
    if cache.is_file():
        old = json.loads(cache.read_text())
        if old.get("analysis") == RESIDUAL_ANALYSIS and old.get("made_with") == made_with:
            return old
    if not has_results:  # nothing to analyse again
        return {"analysis": "the loop's", "status": said.get("status", "-"),
                "record_biases": said.get("record_biases") or {}, "input_path": {}}
    if cfg is None:
        _, rec, cfg = loop_iteration(loop, rec["iteration"], doc["config"])
    v = residual_verdict(cfg, rec["parameters"], progress=lambda s: None)
    out = {"analysis": RESIDUAL_ANALYSIS, "status": v["status"], "findings": v.get("findings", []),
           "record_biases": {o: t for o, t in (v.get("record_biases") or {}).items()},
           "input_path": v.get("input_path") or {}, **({"made_with": made_with} if made_with else {})}
    cache.write_text(json.dumps(out, indent=1))
    return out


def truth_record_change(effect: str, output: str, setup: SignatureSetup | None = None) -> dict:
    """What the truth effect adds to ``output``'s mean over each validation record, averaged per trim speed
    {V [m/s]: SI} (truth model against M0, both at the M0 truth parameters)."""
    setup = setup or signature_setup()
    pred, base = truth_prediction(effect, setup), setup.base
    per = {}
    for mv in setup.maneuvers:
        d = pred.maneuvers[mv.name][output].to_numpy() - base.maneuvers[mv.name][output].to_numpy()
        per.setdefault(round(float(mv.trim_speed), 6), []).append(float(np.mean(d)))
    return {v: float(np.mean(x)) for v, x in per.items()}


def record_bias_match(effect: str, tests: dict, setup: SignatureSetup | None = None) -> str:
    """Does a record-bias shape the residual analysis reports (an output whose records disagree on its bias, with
    each speed's shift against the records' mean, residual = model - data) match the truth's change of that output's
    record means in sign and speed dependence? The data hold the truth's change and the model lacks it, so the
    shift should follow minus the change: 'yes' when, both centred over the speeds they share, their correlation
    is > 0.7 and they agree in sign at the speed of the truth's largest centred change; 'no (...)' otherwise;
    '-' when no output's records disagree."""
    flagged = {o: t for o, t in tests.items() if not t["consistent"]}
    if effect == "none" or not flagged:
        return "n/a" if effect == "none" else "-"
    verdicts = []
    for o, t in flagged.items():
        change = truth_record_change(effect, o, setup)
        shift = {round(r["V"], 6): -r["shift"] for r in t["by_speed"]}
        vs = sorted(set(change) & set(shift))
        if len(vs) < 3:
            verdicts.append(f"{o}: n/a")
            continue
        a = np.array([change[v] for v in vs])
        b = np.array([shift[v] for v in vs])
        a, b = a - a.mean(), b - b.mean()
        if not np.any(np.abs(a) > 1e-12):
            verdicts.append(f"{o}: no (the truth does not change its record means)")
            continue
        corr = float(np.corrcoef(a, b)[0, 1])
        k = int(np.argmax(np.abs(a)))
        if corr > 0.7 and np.sign(a[k]) == np.sign(b[k]):
            return f"yes ({o}, corr {corr:+.2f})"
        verdicts.append(f"{o}: no (corr {corr:+.2f})")
    return "no (" + "; ".join(verdicts) + ")"


@functools.lru_cache(maxsize=8)
def truth_input_error(effect: str, setup: SignatureSetup) -> dict:
    """What the rotor of the truth model sees minus the recorded input, per validation record and input channel
    {maneuver: {"col": array, "lon": array}} [rad] (the truth model's replay at the M0 truth parameters, its
    controls after the effect's ``adjust_controls``); zero for an effect that does not act on the control path."""
    from pyomo_heli.physics.model import HelicopterModel

    pred = truth_prediction(effect, setup)
    model = HelicopterModel(extensions=(HELD_OUT_EFFECTS[effect](),)).with_parameters(
        **setup.m0, **HELD_OUT_STRENGTHS[effect])
    out = {}
    for mv in setup.maneuvers:
        df = pred.maneuvers[mv.name]
        err = {"col": np.zeros(len(df)), "lon": np.zeros(len(df))}
        for k, r in enumerate(df.itertuples(index=False)):
            row = r._asdict()
            ctx = model.evaluate({s: row[s] for s in model.state_names}, {"col": row["col"], "lon": row["lon"]})
            err["col"][k], err["lon"][k] = float(ctx.col) - row["col"], float(ctx.lon) - row["lon"]
        out[mv.name] = err
    return out


def input_path_history(terms: list, setup: SignatureSetup) -> dict:
    """The input error the residual analysis reports, sum of estimate x signal (:mod:`pyomo_heli.diagnosis.input_path`),
    along the validation records of M0 at the truth parameters {maneuver: {"col": array, "lon": array}} [rad]. The play
    signals' widths from the records' lead-in, as the analysis takes them."""
    from pyomo_heli.diagnosis.input_path import input_error, play_widths, signal_values
    from pyomo_heli.nlp.objectives import noise_sigmas

    out = {}
    widths = play_widths(noise_sigmas(setup.maneuvers, ("col", "lon"), input_record=True))
    for mv in setup.maneuvers:
        df, t = setup.base.maneuvers[mv.name], mv.data["t"].to_numpy(dtype=float)
        sig = signal_values(t, mv.increments(), {o: df[o].to_numpy(dtype=float) for o in ("q", "theta", "TAS")},
                            widths)
        out[mv.name] = input_error(terms, sig, len(t))
    return out


#: the centred moving average [s] both input-error histories get before they are compared (the recorded inputs'
#: noise, in both, is no shape; 0.2 s keeps the rigid-body band, up to about 2.5 Hz)
INPUT_PATH_SMOOTH_S = 0.2


def input_error_signature(errors: dict, setup: SignatureSetup) -> np.ndarray | None:
    """What an input error {maneuver: {"col": array, "lon": array}} [rad] (at the records' samples) does to the
    validation records, in noise standard deviations: M0 at the truth parameters replayed with its inputs moved by it,
    minus M0's replay (the records' outputs stacked, as :func:`signature_of` stacks them); None if a replay fails. For
    the truth's own error (:func:`truth_input_error`, the controls its rotor saw along its own replay) this is the
    truth's signature on the records."""
    from dataclasses import replace

    from pyomo_heli.physics.model import HelicopterModel
    from pyomo_heli.simulation.replay import predict

    moved = []
    for mv in setup.maneuvers:
        e, data = errors[mv.name], mv.data.copy()
        rec = None if mv.inputs_record is None else mv.inputs_record.copy()
        for c in ("col", "lon"):
            data[c] = data[c].to_numpy(dtype=float) + e[c]
            if rec is not None:
                rec[c] = rec[c].to_numpy(dtype=float) + np.interp(rec["t"].to_numpy(dtype=float), mv.t, e[c])
        moved.append(replace(mv, data=data, inputs_record=rec))
    pred = predict("input error", HelicopterModel().with_parameters(**setup.m0), {}, [], moved)
    base = setup.base
    if pred.problems or base.problems:
        return None
    return np.concatenate([(pred.maneuvers[mv.name][o].to_numpy() - base.maneuvers[mv.name][o].to_numpy())
                           / setup.sigma[o] for mv in setup.maneuvers for o in OUTPUTS])


def input_path_match(effect: str, terms: list, setup: SignatureSetup | None = None) -> str:
    """Does the input error the residual analysis reports match the truth's in shape? Along the validation records,
    each record's mean taken out of both (a constant is a rigging offset, not this test's business) and both smoothed
    over INPUT_PATH_SMOOTH_S, the channel where the truth's error is largest: their correlation must be > 0.7, and
    what the two errors do to the records (:func:`input_error_signature`) must pass :func:`signature_verdict`, the
    test a kept control-path term passes (a correlated error of another form, e.g. a loss of cyclic gain against a
    washed-out rate feedback, correlates on a doublet but leaves much of the truth's signature). 'yes (channel, corr
    r)', 'no (...)' otherwise, also for a truth that leaves the control path alone; '-' when nothing is reported."""
    if effect == "none" or not terms:
        return "n/a" if effect == "none" else "-"
    setup = setup or signature_setup()
    truth, rep = truth_input_error(effect, setup), input_path_history(list(terms), setup)

    def smooth(x, t):  # the records' inputs are measured: their noise is in both histories, and is no shape
        k = max(int(round(INPUT_PATH_SMOOTH_S / float(np.median(np.diff(t))))), 1)
        return np.convolve(x, np.ones(k) / k, mode="same") if len(x) > k else x

    times = {mv.name: mv.data["t"].to_numpy(dtype=float) for mv in setup.maneuvers}

    def pooled(d, c):
        return np.concatenate([smooth(d[m][c] - d[m][c].mean(), times[m]) for m in d])

    size = {c: float(np.std(pooled(truth, c))) for c in ("col", "lon")}
    c = max(size, key=size.get)
    if size[c] < 1e-9:
        return "no (the truth does not act on the control path)"
    a, b = pooled(truth, c), pooled(rep, c)
    if not np.any(np.abs(b) > 0):
        return f"no (nothing reported on {c}, where the truth acts)"
    corr = float(np.corrcoef(a, b)[0, 1])
    if corr <= 0.7:
        return f"no ({c}, corr {corr:+.2f})"
    verdict = signature_verdict(input_error_signature(truth, setup), input_error_signature(rep, setup))
    return f"yes ({c}, corr {corr:+.2f})" if verdict == "yes" else f"no ({c}, corr {corr:+.2f}; signature {verdict})"


def residual_columns(effect: str, fr: dict, setup: SignatureSetup | None = None) -> dict:
    """The table's columns of a kept model's residual analysis ``fr`` (:func:`final_residual`): the outputs whose
    records disagree on their bias and whether that shape is the truth's, the input error it reports and whether that
    follows the truth's."""
    flagged = {o: t for o, t in fr["record_biases"].items() if not t["consistent"]}
    terms = (fr.get("input_path") or {}).get("terms") or []
    return {"record biases differ": (", ".join(f"{o} (chi2 {t['chi2']:.3g} on {t['df']})"
                                               for o, t in flagged.items()) or "none"),
            "record bias shape matches truth": record_bias_match(effect, fr["record_biases"], setup),
            "input path": format_input_path(terms) if fr.get("input_path") else "-",
            "input path shape matches truth": input_path_match(effect, terms, setup)}


def evaluate(effect: str, seed: int, loop: Path, config: Path = CONFIG, setup: SignatureSetup | None = None) -> dict:
    """The table row of a finished loop; ``setup``: the signature setup of the study's flight tests
    (:func:`signature_setup`; default the bundled flight test's)."""
    from pyomo_heli.diagnosis.candidates import CANDIDATES
    from pyomo_heli.diagnosis.discovery import best_fit
    from pyomo_heli.physics.discrepancy import generic_term
    from pyomo_heli.report.identification import read_truth
    from pyomo_heli.report.loop import JOINT, discovered_terms, final_index, rejected_discovery
    from pyomo_heli.workflows.close_loop import DIRECT_FAILED

    doc = json.loads((loop / "loop.json").read_text())
    its = doc["iterations"]
    i0, ik = its[0], its[final_index(doc)]
    truth = read_truth(Path(doc["dataset"]))
    physical = [n for n in ik["extensions"] if n in CANDIDATES]
    last_disc = next((it.get("discovery") for it in reversed(its) if it.get("discovery")), None) or {}
    if last_disc.get("decision") == "ambiguous" and "best_generic" not in last_disc:
        # loops run before the ambiguous record carried it: the generic term its message names (largest LR)
        last_disc = {**last_disc, "best_generic": best_fit((last_disc.get("screen") or {}).get("fits", {}), True,
                                                           "likelihood_ratio")}
    # each step's decision and the term it added (or the term the backward check dropped), "(rejected)" where the
    # validation rule rejected that term's step (or the model without the dropped term)
    def step_words(it):
        if (it.get("decision") or {}).get("decision") == "dropped":  # the name: in the message for older loops
            d = it["decision"]
            return f"dropped {d.get('name') or d['message'].split()[2]}"
        d = it.get("discovery") or {}
        return d.get("decision", "-") + (f" {d['added']}" if d.get("added") else "")

    decisions = [step_words(it) + (" (rejected)" if j + 1 < len(its) and its[j + 1].get("rejected") else "")
                 for j, it in enumerate(its)]
    fr = final_residual(loop, config)
    row = {"truth": effect, "seed": seed, "verdict": "; ".join(decisions),
           "added (kept)": "+".join(ik["extensions"]) or "-", "final residual": fr["status"]}
    row.update(residual_columns(effect, fr, setup))
    row["residual analysis of"] = "the loop's kept model" if fr.get("input_path") else fr.get("analysis", "-")
    # iterations that diagnosed the closest front point because the direct Eq. 11 solve failed from every start
    row["direct solve failed"] = ", ".join(str(j) for j, it in enumerate(its)
                                           if it.get("point") == DIRECT_FAILED) or "none"
    def pooled(d, keys):
        return float(np.sqrt(np.mean([d[c] ** 2 for c in keys if c in d])))

    row["trim RMS before [deg]"] = np.degrees(pooled(i0["trim_rms"], TRIM))
    row["trim RMS after [deg]"] = np.degrees(pooled(ik["trim_rms"], TRIM))
    row["trim change %"] = 100 * (row["trim RMS after [deg]"] / row["trim RMS before [deg]"] - 1)
    # the floor: the truth model at the truth parameters leaves only the noise (and the trims' offsets)
    truth_err = truth_floor(Path(doc["dataset"]), config)
    floor = np.degrees(pooled(truth_err["trim_rms"]["all"], TRIM))
    row["trim RMS truth model [deg]"] = floor
    row["trim change possible %"] = 100 * (floor / row["trim RMS before [deg]"] - 1)
    row["share of possible trim cut %"] = (100 * row["trim change %"] / row["trim change possible %"] + 0.0
                                          if row["trim change possible %"] <= -POSSIBLE_CUT_MIN else "-")
    for key, lab in (("identification_rms", "id"), ("validation_rms", "val")):
        for o in OUTPUTS:
            a, b = (i0.get(key) or {}).get(o), (ik.get(key) or {}).get(o)
            if a and b:
                row[f"{lab} {o} change %"] = 100 * (b / a - 1)
    worst = {}
    for when, it in (("before", i0), ("after", ik)):
        ratios = {o: it["validation_rms"][o] / truth_err["maneuver_rms"]["all"][o] for o in OUTPUTS
                  if (it.get("validation_rms") or {}).get(o) and truth_err["maneuver_rms"]["all"].get(o)}
        for o, r in ratios.items():
            row[f"val {o} / truth model {when}"] = r
        worst[when] = max(ratios, key=ratios.get) if ratios else None
    if worst["before"]:
        o = worst["before"]
        row["val RMS / truth model's, worst output"] = (f"{o}: {row[f'val {o} / truth model before']:.3f} -> "
                                                         f"{row[f'val {o} / truth model after']:.3f}")
    # the criterion: a significant rise on any output (the check's joint row is not an output)
    sig_rise = [r["output"] for it in its[1:final_index(doc) + 1] if not it.get("rejected")
                for r in (it.get("validation_check") or []) if r["significant rise"] and r["output"] != JOINT]
    row["significant val rise (kept steps)"] = ",".join(sig_rise) or "none"
    row["val joint p (kept vs M0)"] = validation_joint_p(doc, config)
    for n in PARAMETERS:
        if truth and n in truth:
            row[f"{n} err0 %"] = 100 * (i0["parameters"][n] - truth[n]) / abs(truth[n])
            row[f"{n} err1 %"] = 100 * (ik["parameters"][n] - truth[n]) / abs(truth[n])
    row["wrong acceptance"] = bool(physical)
    disc = next((fit for _it, fit in discovered_terms(doc)), None)  # the first discovered term the model kept
    not_kept = rejected_discovery(doc)  # discovered, then rejected by the validation rule: reported unexplained
    described = disc or (not_kept[1] if not_kept else None) or last_disc.get("best_generic")
    row["generic term"] = (f"{described['name']}: c = {described['estimate']:.3g} +- {described['se']:.2g}"
                           if described else "-")
    row["kept discovered term"] = disc["name"] if disc else "-"
    row["shape matches truth"] = match(effect, described, setup)
    # the kept model as a whole: every discovered term it kept, at the kept model's estimates
    ses = ik.get("standard_errors") or {}
    whole = [{"name": fit["name"], "estimate": ik["parameters"][s], "se": ses.get(s, math.nan)}
             for _it, fit in discovered_terms(doc) if (s := generic_term(fit["name"]).strength) in ik["parameters"]]
    row["kept terms"] = format_terms(whole)
    row["kept model matches truth"] = model_match(effect, whole, setup) if whole else "-"
    # "unexplained": the step said so (best generic term significant on its own), the residual analysis did, or the
    # discovered term's step was rejected by the validation rule (the loop stops with its shape reported)
    alpha = doc["settings"].get("alpha", 0.01)
    # at the iteration limit the last step's discovered term is not added: the loop reports it as what is left
    at_limit = str(doc.get("stopped", "")).startswith("iteration limit") and last_disc.get("decision") == "discovered"
    best = last_disc.get("best_generic") or (last_disc.get("discovered") if at_limit else None) or {}
    row["unexplained verdict"] = (bool(last_disc.get("unexplained")) or best.get("p", 1.0) < alpha
                                  or row["final residual"] == "unexplained residual" or not_kept is not None)
    # the shape the final "unexplained" verdict reports: the rejected discovered term, else the last step's best
    # generic term, at the iteration limit the term it would add next (after a kept discovered term this is what is
    # left, not the kept term)
    left = (not_kept[1] if not_kept else best) if row["unexplained verdict"] else None
    row["unexplained shape"] = (f"{left['name']}: c = {left['estimate']:.3g} +- {left['se']:.2g}" if left else "-")
    row["unexplained shape matches truth"] = match(effect, left, setup) if left else "-"
    row["criterion met"] = criterion_met(row)
    if effect != "none":
        tf = truth_form_check(effect, loop, config)
        row["truth form at M0"] = (f"{HELD_OUT_EFFECTS[effect].strength} = {tf['estimate']:.3g} (truth "
                                   f"{tf['truth strength'][HELD_OUT_EFFECTS[effect].strength]:g}), LR {tf['LR']:.3g}")
        row["truth form p"] = tf["p"]
        row["truth form significant"] = tf["significant"]
        row["truth form significant from"] = truth_form_detectable(effect, tf)
    return row


TERM = re.compile(r"^(\S+): c = (\S+) \+- (\S+)$")
NUMBER = re.compile(r"^[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$")


INPUT_TERM = re.compile(r"^(col|lon) \+= (\S+) \+- (\S+)(?: \S+)? x (\S+)$")


def format_input_path(terms: list) -> str:
    """The input-path terms the residual analysis selected, as the table prints them ('none' when it selected none):
    ``lon += +0.0528 +- 0.0024 x col; ...`` (estimate in rad per signal unit, SI)."""
    return "; ".join(f"{t['channel']} += {t['estimate']:+.3g} +- {t['se']:.2g} x {t['signal']}"
                     for t in terms) or "none"


def parse_input_path(text) -> list:
    """The terms of a table's "input path" cell (:func:`format_input_path`)."""
    out = []
    for part in str(text).split("; "):
        m = INPUT_TERM.match(part.strip())
        if m:
            out.append({"channel": m[1], "estimate": float(m[2]), "se": float(m[3]), "signal": m[4]})
    return out


def parse_term(text) -> dict | None:
    """A table's ``name: c = X +- SE`` back to a fit (name, estimate, se); None for '-'."""
    m = TERM.match(str(text))
    return {"name": m[1], "estimate": float(m[2]), "se": float(m[3])} if m else None


#: columns the study writes as text although they can look like a number (iteration indices: "none", "1", "1, 2")
TEXT_COLUMNS = ("direct solve failed",)


def read_rows(path: Path) -> list[dict]:
    """The rows of a written ``held_out.csv`` as the study made them: a column that mixes numbers and "-" is read as
    text, so its numbers go back to numbers (the md formats them), except in :data:`TEXT_COLUMNS`; an empty cell
    stays empty."""
    tab = pd.read_csv(path, keep_default_na=False, dtype={c: str for c in TEXT_COLUMNS})
    return [{k: (float(v) if isinstance(v, str) and NUMBER.match(v) and k not in TEXT_COLUMNS else v)
             for k, v in r.items()} for r in tab.to_dict("records")]


def merge(out: Path, sources: list[Path]) -> pd.DataFrame:
    """``OUT/held_out.csv`` with each row of the SOURCES' tables in place of OUT's row of the same truth and seed
    (or added); every other row as it is, not re-scored. A column a row lacks is an empty cell. Rewrites csv and
    md. For rows rerun into another folder (a case run again under a new rule) and merged into a committed table."""
    rows = {(r["truth"], int(r["seed"])): r for r in read_rows(out / "held_out.csv")}
    for src in sources:
        rows.update({(r["truth"], int(r["seed"])): r for r in read_rows(src / "held_out.csv")})
    tab = pd.DataFrame([rows[k] for k in sorted(rows)])
    for c in tab.columns[tab.isna().any()]:  # a column some rows lack: empty cells, the other values as they are
        tab[c] = tab[c].astype(object).where(tab[c].notna(), "")
    tab.to_csv(out / "held_out.csv", index=False)
    (out / "held_out.md").write_text(markdown(tab))
    return tab


def reanalyse(out: Path, scratch: Path, config: Path, template: str, setup: SignatureSetup | None = None
              ) -> pd.DataFrame:
    """The residual analysis of the kept model, made with the current analysis, for the rows of ``OUT/held_out.csv``
    whose loops are gone and whose kept model the table holds: M0 (nothing added), or M0 plus the discovered terms
    it kept at the kept model's estimates ("kept terms", 3 significant digits; the analysis allows a shift of every
    free parameter, the terms' strengths included). The flight test is generated again (``template``, the row's
    truth and seed; deterministic) into ``SCRATCH/<effect>_<seed>/data``, the parameters rebuilt from the row's
    parameter errors against its truth.json, and the loop's own call (``residual_verdict`` under ``config``) made.
    Rewrites the final residual, record-bias and input-path columns and the criterion; any other row is left as it
    is. Cached per case and kept model in ``final_residual_<kept>.json`` (with the parameters, and the config's
    resampling and ``[diagnosis]`` input noise and replay, it was made with)."""
    from pyomo_heli.config import load_identification_config
    from pyomo_heli.diagnosis.candidates import model_with_candidates
    from pyomo_heli.nlp.parameters import FreeParameter
    from pyomo_heli.workflows.close_loop import analysis_settings, residual_verdict

    rows = read_rows(out / "held_out.csv")
    for r in rows:
        kept = str(r["added (kept)"])
        terms = parse_terms(r.get("kept terms", "-"))
        if kept != "-" and sorted(kept.split("+")) != sorted(f["name"] for f in terms):
            continue  # a kept term the table holds no estimate of (a named library effect): the loop's analysis stays
        effect, seed = r["truth"], int(r["seed"])
        case = scratch / f"{effect}_{seed}"
        data = generate_case(case, template, effect, seed)
        truth = json.loads((data / "truth.json").read_text())["parameters"]
        cfg = load_identification_config(config, overrides={"data": {"dataset": str(data)}})
        free = sorted(p.name for p in cfg.free)
        if free != sorted(PARAMETERS):
            raise ValueError(f"{config}: frees {free}, the table's parameter errors are of {sorted(PARAMETERS)}")
        # the inverse of the row's error, 100 (p - truth) / |truth| (a negative truth, the twist, included)
        pars = {n: truth[n] + float(r[f"{n} err1 %"]) / 100 * abs(truth[n]) for n in PARAMETERS}
        if terms:
            model = model_with_candidates(cfg.model, [f["name"] for f in terms])
            added = []
            for ext, fit in zip(model.extensions[-len(terms):], terms):
                spec = model.parameters.spec(ext.strength)
                added.append(FreeParameter(ext.strength, fit["estimate"], spec.bounds[0], spec.bounds[1],
                                           spec.scale or 1.0))
                pars[ext.strength] = fit["estimate"]
            cfg = dataclasses.replace(cfg, model=model, free=[*cfg.free, *added])
        # one cache per kept model: tables of other families share a case's flight test, not its kept model
        cache = case / f"final_residual_{kept}.json"
        fr = json.loads(cache.read_text()) if cache.is_file() else {}
        # what of the config the analysis depends on: another resampling or replay is another analysis
        made_with = analysis_settings(cfg)
        # a cache made before a setting was recorded was made with its default then
        old = {"input_path_family": "standard", **fr.get("made_with", {**made_with, "replay": "fit"})}
        if fr.get("analysis") != RESIDUAL_ANALYSIS or fr.get("parameters") != pars or old != made_with:
            v = residual_verdict(cfg, pars, progress=lambda s: None)
            fr = {"analysis": RESIDUAL_ANALYSIS, "status": v["status"], "findings": v.get("findings", []),
                  "record_biases": v.get("record_biases") or {}, "input_path": v.get("input_path") or {},
                  "parameters": pars, "made_with": made_with}
            cache.write_text(json.dumps(fr, indent=1))
        r["final residual"] = fr["status"]
        r.update(residual_columns(effect, fr, setup))
        r["residual analysis of"] = ("M0 rebuilt from the table" if kept == "-" else
                                     f"M0 + {kept} rebuilt from the table")
        r["wrong acceptance"] = str(r["wrong acceptance"]) == "True"
        if effect != "none":
            r["criterion met"] = criterion_met(r)
        print(f"{effect} {seed}: {r['final residual']}; input path {r['input path']} "
              f"({r['input path shape matches truth']})", flush=True)
    new = pd.DataFrame(rows)
    for c in new.columns[new.isna().any()]:  # a column the other rows lack: empty cells
        new[c] = new[c].astype(object).where(new[c].notna(), "")
    new.to_csv(out / "held_out.csv", index=False)
    (out / "held_out.md").write_text(markdown(new))
    return new


def rescore(out: Path, setup: SignatureSetup | None = None) -> pd.DataFrame:
    """Re-score ``OUT/held_out.csv`` without its loops: the shape columns and the criterion from the terms the table
    reports (estimates as printed, 3 significant digits), every other column as it is; rewrites csv and md.
    ``setup``: the signature setup of the study's flight tests (:func:`signature_setup`)."""
    rows = []
    for r in read_rows(out / "held_out.csv"):
        described, left = parse_term(r["generic term"]), parse_term(r["unexplained shape"])
        kept = described["name"] if described and described["name"] in str(r["added (kept)"]).split("+") else "-"
        r["kept discovered term"] = kept
        r["shape matches truth"] = match(r["truth"], described, setup) if described else "-"
        if str(r.get("kept terms", "")) not in ("", "-", "nan"):
            r["kept model matches truth"] = model_match(r["truth"], parse_terms(r["kept terms"]), setup)
        r["unexplained shape matches truth"] = match(r["truth"], left, setup) if left else "-"
        if str(r.get("input path", "-")) not in ("-", "", "nan"):
            r["input path shape matches truth"] = input_path_match(r["truth"], parse_input_path(r["input path"]),
                                                                   setup)
        r["wrong acceptance"] = str(r["wrong acceptance"]) == "True"
        r["criterion met"] = criterion_met(r)
        rows.append(r)
    new = pd.DataFrame(rows)
    new.to_csv(out / "held_out.csv", index=False)
    (out / "held_out.md").write_text(markdown(new))
    return new


def _cpu() -> float:
    """CPU seconds of this process and its finished children (the loop's cost on one core, whatever the load)."""
    import resource

    a, b = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return a.ru_utime + a.ru_stime + b.ru_utime + b.ru_stime


def bundled_config_text(text: str, mode: str) -> str:
    """The loop config of ``--bundled``'s ``mode`` ("on"/"off") from the study config's ``text``: ``[loop] discovery``
    set; off, without the fields only discovery reads (a ``generic_rank`` pin, a ``--set``), which [loop] refuses
    without it."""
    from pyomo_heli.settings.identification import DISCOVERY_ONLY_LOOP_FIELDS

    text = re.sub(r"(?m)^discovery\s*=.*\n", "", text)
    text = text.replace("\n[loop]\n", f"\n[loop]\ndiscovery = {'true' if mode == 'on' else 'false'}\n", 1)
    if mode == "off":
        text = re.sub(rf"(?m)^({'|'.join(DISCOVERY_ONLY_LOOP_FIELDS)})\s*=.*\n", "", text)
    return text


def run_bundled(out: Path, config: Path, dataset: Path, modes=("on", "off")) -> dict:
    """The bundled flight test through the closed loop of ``config`` twice in this one process: discovery on and
    off (the config's text with ``[loop] discovery`` set), each timed (wall and CPU seconds, load average).
    ``OUT/bundled/{on,off}/loop`` and ``OUT/bundled/cost.json``, written after each loop; a loop already
    finished (its time recorded) is not rerun; ``modes`` runs only some (two invocations may run "on" and "off"
    at the same time: the file is merged on every write). Returns the cost record with the wake-naming check."""
    import os

    from pyomo_heli.diagnosis.candidates import CANDIDATES
    from pyomo_heli.report.loop import final_index
    from pyomo_heli.workflows.close_loop import LoopMismatchError, finished_loop

    base = out / "bundled"
    base.mkdir(parents=True, exist_ok=True)
    cost_file = base / "cost.json"

    def merged(mine: dict) -> dict:
        old = json.loads(cost_file.read_text()) if cost_file.is_file() else {}
        return {**old, **mine}

    cost = merged({})
    truth = json.loads((dataset / "truth.json").read_text())["parameters"]
    for mode in modes:
        loop, cfg = base / mode / "loop", base / mode / "loop.toml"
        wanted = bundled_config_text(config.read_text(), mode)
        if mode in cost and (loop / "loop.json").is_file() and cfg.is_file() and cfg.read_text() != wanted:
            raise StudyFolderError(f"{loop}: its timed loop was made from another config ({cfg}); give this study "
                                   "another folder")
        cfg.parent.mkdir(parents=True, exist_ok=True)
        if not cfg.is_file() or cfg.read_text() != wanted:
            cfg.write_text(wanted)
        try:
            done = mode in cost and finished_loop(loop, cfg, dataset)
        except LoopMismatchError as exc:
            raise StudyFolderError(str(exc)) from None
        if not done:
            load0, t0, c0 = os.getloadavg()[0], time.perf_counter(), _cpu()
            # timed from the start: a loop interrupted before its time was recorded is run again whole
            run_command(["close-loop", str(cfg), "--dataset", str(dataset), "--out", str(loop), "--restart"])
            cost[mode] = {"wall_s": time.perf_counter() - t0, "cpu_s": _cpu() - c0,
                          "load_start": load0, "load_end": os.getloadavg()[0]}
            cost = merged({mode: cost[mode]})
            cost_file.write_text(json.dumps(cost, indent=1))
        doc = json.loads((loop / "loop.json").read_text())
        its = doc["iterations"]
        kept = its[final_index(doc)]
        cost[mode].update(
            decisions=[(it.get("discovery") or {}).get("decision") or (it.get("attribution") or {}).get("decision")
                       for it in its],
            added=[it["discovery"].get("added") if it.get("discovery")
                   else (it.get("attribution") or {}).get("accepted") for it in its],
            kept=kept["extensions"],
            wake_named=bool(mode == "on" and (its[0].get("discovery") or {}).get("decision") == "named"
                            and its[0]["discovery"].get("added") == "rotor_wake_on_tail"),
            other_physical_kept=[n for n in kept["extensions"] if n in CANDIDATES and n != "rotor_wake_on_tail"],
            trim_change_pct=100 * (np.sqrt(np.mean([kept["trim_rms"][c] ** 2 for c in TRIM]))
                                   / np.sqrt(np.mean([its[0]["trim_rms"][c] ** 2 for c in TRIM])) - 1),
            errors_pct={n: 100 * (kept["parameters"][n] - truth[n]) / abs(truth[n]) for n in PARAMETERS})
        cost = merged({mode: cost[mode]})
        cost_file.write_text(json.dumps(cost, indent=1))
        print(f"bundled, discovery {mode}: {cost[mode]}", flush=True)
    cost = merged({})
    if "wall_s" in cost.get("on", {}) and "wall_s" in cost.get("off", {}):
        for k in ("wall_s", "cpu_s"):
            cost[f"ratio_{k}"] = cost["on"][k] / cost["off"][k]
        cost_file.write_text(json.dumps(cost, indent=1))
        print(f"cost ratio (discovery on / off): wall {cost['ratio_wall_s']:.2f}, cpu {cost['ratio_cpu_s']:.2f}")
    return cost


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=positive_int, default=3,
                    help="noise seeds per effect (20261122 + k, k from --first-seed)")
    ap.add_argument("--first-seed", type=nonneg_int, default=0,
                    help="start at seed 20261122 + FIRST_SEED (default 0: the bundled flight test's own seed)")
    ap.add_argument("--effects", nargs="+", default=list(HELD_OUT_EFFECTS),
                    help=f"held-out effects (or none): {', '.join(HELD_OUT_EFFECTS)}")
    ap.add_argument("--config", default=str(CONFIG))
    ap.add_argument("--generic-family", choices=list(FAMILIES),
                    help="set the config's [loop] generic_family (the config is copied, with it, to "
                         "OUT/loop_<family>.toml); extended: + speed products and input scale factors; control: "
                         "extended + control-path feedback")
    ap.add_argument("--input-path-family", choices=["standard", "extended"],
                    help="set the config's [diagnosis] input_path_family (copied to OUT/input_path_<family>.toml): the "
                         "residual analysis's input-path dictionary; extended: + each input's free play and dead zone")
    ap.add_argument("--set", nargs="+", metavar="TABLE.KEY=VALUE", default=[],
                    help="set these fields of the config (copied, with them, to OUT/config_set.toml), e.g. "
                         "data.resample_inputs=record objectives.input_error_ar=4")
    ap.add_argument("--data-config", default=str(ROOT / "data" / "bo105_synthetic.toml"))
    ap.add_argument("--out", required=True)
    ap.add_argument("--bundled", action="store_true",
                    help="instead: the bundled flight test (data/bo105_synthetic) through the loop with discovery on "
                         "and off in this one run, both timed (cost ratio), the wake's naming and the parameter errors "
                         "-> OUT/bundled/cost.json")
    ap.add_argument("--modes", nargs="+", choices=["on", "off"], default=["on", "off"],
                    help="with --bundled: the loops to run (default both, in this order)")
    ap.add_argument("--evaluate-only", action="store_true",
                    help="run nothing: re-evaluate every finished loop in OUT (OUT/<effect>_<seed>/loop) and rewrite "
                         "its row.json and the table")
    ap.add_argument("--workers", type=nonneg_int, default=0,
                    help="run the cases on a Dask LocalCluster of this many processes (default 0: one after the "
                         "other in this process); each finished case's row.json and the table are written as it ends")
    ap.add_argument("--scheduler", metavar="ADDRESS",
                    help="run the cases on the Dask cluster of this scheduler (its workers must see --out)")
    ap.add_argument("--rescore", action="store_true",
                    help="run nothing: re-score OUT/held_out.csv (shape columns and criterion) from the terms it "
                         "reports, for a table whose loops are not at hand")
    ap.add_argument("--reanalyse", metavar="SCRATCH",
                    help="run no loop: the residual analysis of the kept model, made with the current analysis, for "
                         "OUT's rows whose loop kept M0 (their loops gone), the flight tests generated again into "
                         "SCRATCH; rewrites the table")
    ap.add_argument("--rows", metavar="CSV",
                    help="with --reanalyse: start OUT/held_out.csv from this table (another study's, e.g. "
                         "docs/results/held_out/held_out.csv), so that the reanalysis leaves it as it is")
    ap.add_argument("--merge", nargs="+", metavar="FOLDER",
                    help="run nothing: replace (or add) the rows of OUT/held_out.csv by the rows of the same truth "
                         "and seed in these folders' held_out.csv (rows rerun elsewhere); the others stay as they are")
    ap.add_argument("--summary", nargs="+", metavar="FOLDER",
                    help="run nothing: the tallies of these studies' held_out.csv (wrong acceptances, criterion met, "
                         "truth's form significant, M0 + noise) as one table -> OUT/summary.md")
    a = ap.parse_args(argv)
    try:
        check_dask_flags(a.workers, a.scheduler)
    except ValueError as exc:
        ap.error(str(exc))
    out = out_folder(ap, a.out)
    if a.modes != ["on", "off"] and not a.bundled:
        ap.error("--modes: only with --bundled (the loops of the bundled flight test)")
    if a.summary:
        folders = [Path(f) for f in a.summary]
        missing = [str(f / "held_out.csv") for f in folders if not (f / "held_out.csv").is_file()]
        if missing:
            ap.error(f"--summary: {missing[0]} not found")
        out.mkdir(parents=True, exist_ok=True)
        (out / "summary.md").write_text(summary(folders))
        print((out / "summary.md").read_text())
        return 0
    if a.merge:
        missing = [str(f) for f in [out, *map(Path, a.merge)] if not (f / "held_out.csv").is_file()]
        if missing:
            ap.error(f"--merge: {Path(missing[0]) / 'held_out.csv'} not found")
        for f in [out, *map(Path, a.merge)]:
            cols = pd.read_csv(f / "held_out.csv", nrows=0).columns
            if not {"truth", "seed"} <= set(cols):
                ap.error(f"--merge: {f / 'held_out.csv'} has no 'truth' and 'seed' columns: not a study table")
        merge(out, [Path(f) for f in a.merge])
        print((out / "held_out.md").read_text())
        return 0
    config = in_file(ap, a.config, "--config")
    if a.generic_family:
        config = with_generic_family(config, a.generic_family, out)
    if a.input_path_family:
        config = with_input_path_family(config, a.input_path_family, out)
    if a.set:
        from pyomo_heli.config import ConfigError, load_identification_config

        try:
            sets = [parse_set(s) for s in a.set]
        except ValueError as exc:
            ap.error(f"--set: {exc}")
        config = with_settings(config, sets, out / "config_set.toml")
        try:  # the [loop] table too: the table this study is about, read by close-loop only
            from pyomo_heli.workflows.close_loop import loop_settings

            loop_settings(load_identification_config(config))
        except ConfigError as exc:
            config.unlink()  # not left behind as this study's settings
            ap.error(f"--set: {exc}")
    template = in_file(ap, a.data_config, "--data-config").read_text()

    def setup():  # the signature setup of the flight tests this study generates
        return signature_setup(str(config), template, str(signature_cache(template)))

    if a.rescore:
        if not (out / "held_out.csv").is_file():
            ap.error(f"--rescore: {out / 'held_out.csv'} not found")
        rescore(out, setup())
        print((out / "held_out.md").read_text())
        return 0
    if a.rows and not a.reanalyse:
        ap.error("--rows: only with --reanalyse")
    if a.reanalyse:
        if a.rows:
            rows = in_file(ap, a.rows, "--rows")
            out.mkdir(parents=True, exist_ok=True)
            if rows.resolve() != (out / "held_out.csv").resolve():
                shutil.copyfile(rows, out / "held_out.csv")
        if not (out / "held_out.csv").is_file():
            ap.error(f"--reanalyse: {out / 'held_out.csv'} not found")
        from pyomo_heli.config import load_identification_config

        free = sorted(p.name for p in load_identification_config(config).free)
        if free != sorted(PARAMETERS):
            ap.error(f"--config {config}: --reanalyse rebuilds the kept parameters {', '.join(PARAMETERS)} from the "
                     f"table; this config frees {', '.join(free)}")
        try:
            reanalyse(out, Path(a.reanalyse), config, template, setup())
        except StudyFolderError as exc:
            ap.error(f"--reanalyse: {exc}")
        print((out / "held_out.md").read_text())
        return 0
    if a.evaluate_only:
        if not any(json.loads(d.read_text()).get("stopped") for d in out.glob("*_*/loop/loop.json")):
            ap.error(f"--evaluate-only: no finished loop in {out} (OUT/<effect>_<seed>/loop/loop.json)")
        for loop in sorted(out.glob("*_*/loop")):
            doc = loop / "loop.json"
            if doc.is_file() and json.loads(doc.read_text()).get("stopped"):
                effect, seed = loop.parent.name.rsplit("_", 1)
                try:
                    save_row(loop.parent, evaluate(effect, int(seed), loop, config, setup()))
                except StudyConfigError as exc:
                    ap.error(f"--config: {exc}")
        write_table(out)
        print((out / "held_out.md").read_text())
        return 0
    if a.bundled:
        try:
            run_bundled(out, config, ROOT / "data" / "bo105_synthetic", a.modes)
        except StudyFolderError as exc:
            ap.error(f"--bundled: {exc}")
        return 0
    bad = [e for e in a.effects if e != "none" and e not in HELD_OUT_EFFECTS]
    if bad:
        ap.error(f"--effects: unknown held-out effect(s) {bad}; choose from {', '.join(HELD_OUT_EFFECTS)} or none")
    from pyomo_heli.parallel import dask_executor, run_tasks

    tasks = [(effect, seed, out.resolve(), config.resolve(), template)
             for effect in a.effects for seed in seeds_of(a.first_seed, a.seeds)]
    # one case per task: here one after the other (--workers 0), on a LocalCluster of --workers processes or on the
    # cluster of --scheduler; a case's files depend on nothing else, so its row is the same wherever it ran
    def finished(task, result):  # the table of every row in OUT, as each case ends
        if result[1] == 0:
            write_table(out)

    with dask_executor(a.workers, a.scheduler, paths=[str(Path(__file__).resolve().parent)]) as ex:
        done = run_tasks(case_task, tasks, ex, on_result=finished)
    failed = [(t[0], t[1], code) for t, (_, code) in zip(tasks, done) if code != 0]
    if (out / "held_out.md").is_file():
        print((out / "held_out.md").read_text())
    if failed:
        print("failed (see their messages above): " + ", ".join(f"{e} {s}" for e, s, _ in failed), file=sys.stderr)
        return failed[0][2]
    return 0


def with_generic_family(config: Path, family: str, out: Path) -> Path:
    """``OUT/loop_<family>.toml``: CONFIG with ``[loop] generic_family = family`` and its dataset path made absolute."""
    return with_setting(config, "loop", "generic_family", family, out / f"loop_{family}.toml")


def with_input_path_family(config: Path, family: str, out: Path) -> Path:
    """``OUT/input_path_<family>.toml``: CONFIG with ``[diagnosis] input_path_family = family``."""
    return with_setting(config, "diagnosis", "input_path_family", family, out / f"input_path_{family}.toml")


def with_setting(config: Path, table: str, key: str, value: str, path: Path) -> Path:
    """``path``: CONFIG with ``[table] key = "value"`` (a string; :func:`with_settings`)."""
    return with_settings(config, [(table, key, json.dumps(value))], path)


def with_settings(config: Path, settings, path: Path) -> Path:
    """``path``: CONFIG with each ``(table, key, literal)`` of ``settings`` set, ``literal`` a TOML value (the key
    replaced in that table, the table added if CONFIG has none), and its dataset path made absolute."""
    lines = config.read_text().splitlines()
    for table, key, literal in settings:
        head = f"[{table}]"
        if head not in (ln.strip() for ln in lines):
            lines += ["", head]
        start = next(i for i, ln in enumerate(lines) if ln.strip() == head)
        end = next((i for i in range(start + 1, len(lines)) if lines[i].lstrip().startswith("[")), len(lines))
        body = [ln for ln in lines[start + 1:end] if not re.match(rf"\s*{re.escape(key)}\s*=", ln)]
        lines = lines[:start + 1] + [f"{key} = {literal}"] + body + lines[end:]
    text = "\n".join(lines) + "\n"
    text = re.sub(r'(?m)^dataset\s*=\s*"([^"]*)"',
                  lambda m: f'dataset = "{(config.parent / m.group(1)).resolve().as_posix()}"', text, count=1)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


def parse_set(text: str) -> tuple[str, str, str]:
    """``TABLE.KEY=VALUE`` of ``--set`` as (table, key, TOML literal): VALUE as TOML (4, true, "record", [...]), or,
    when it is none, as a string. ValueError naming what is wrong."""
    import tomllib

    name, sep, value = text.partition("=")
    table, dot, key = name.strip().rpartition(".")
    if not (sep and dot and table and key):
        raise ValueError(f"{text!r}: expected TABLE.KEY=VALUE, e.g. objectives.input_error_ar=4")
    value = value.strip()
    try:
        tomllib.loads(f"v = {value}")
    except tomllib.TOMLDecodeError:
        value = json.dumps(value)
    return table, key.strip(), value


def case_task(task: tuple) -> tuple[dict | None, int]:
    """One case of the study (effect, seed, OUT, CONFIG, generator template): its flight test, its loop (resumed if
    stopped part-way) and its evaluated row, written to ``OUT/<effect>_<seed>/row.json``. Returns (row, 0), or
    (None, exit status) where a command failed (it has printed why); the other cases go on."""
    effect, seed, out, config, template = task
    try:
        loop = run_case(effect, seed, out, config, template)
    except SystemExit as exc:
        return None, int(exc.code) if isinstance(exc.code, int) else 1
    except StudyFolderError as exc:  # the --out folder given is at fault: one line, the other cases go on
        print(f"held_out_effects.py: error: {exc}", file=sys.stderr, flush=True)
        return None, 2
    row = evaluate(effect, seed, loop, config, signature_setup(str(config), template, str(signature_cache(template))))
    save_row(loop.parent, row)
    return row, 0


def seeds_of(first: int, n: int) -> list[int]:
    """The noise seeds 20261122 + k, k = first .. first + n - 1 (k = 0: the bundled flight test's own seed)."""
    return [20261122 + k for k in range(first, first + n)]


def save_row(case: Path, row: dict) -> None:
    """``case/row.json``: one evaluated case (numpy scalars as plain numbers)."""
    plain = json.dumps(row, indent=1, default=lambda o: o.item() if hasattr(o, "item") else str(o))
    (case / "row.json").write_text(plain)


def write_table(out: Path) -> pd.DataFrame:
    """``OUT/held_out.csv`` and ``OUT/held_out.md`` from every ``OUT/*/row.json``, sorted by truth and seed."""
    rows = [json.loads(f.read_text()) for f in sorted(out.glob("*/row.json"))]
    tab = pd.DataFrame(rows).sort_values(["truth", "seed"], kind="stable").reset_index(drop=True)
    tab.to_csv(out / "held_out.csv", index=False)
    (out / "held_out.md").write_text(markdown(tab))
    return tab


def markdown(tab: pd.DataFrame) -> str:
    cols = [c for c in ("truth", "seed", "verdict", "added (kept)", "final residual", "generic term",
                        "shape matches truth", "kept terms", "kept model matches truth",
                        "trim RMS before [deg]", "trim RMS after [deg]", "trim change %",
                        "trim RMS truth model [deg]", "trim change possible %", "share of possible trim cut %",
                        "val RMS / truth model's, worst output",
                        "significant val rise (kept steps)", "val joint p (kept vs M0)", "unexplained verdict",
                        "unexplained shape",
                        "unexplained shape matches truth", "record biases differ", "record bias shape matches truth",
                        "input path", "input path shape matches truth", "residual analysis of",
                        "direct solve failed", "wrong acceptance", "criterion met",
                        "truth form at M0", "truth form p", "truth form significant", "truth form significant from",
                        "theta_twist err0 %", "theta_twist err1 %", "CL_alpha_HT err0 %", "CL_alpha_HT err1 %",
                        "Iyy err0 %", "Iyy err1 %") if c in tab]

    def fmt(v):  # a value the row does not have (a noise-only row's truth form) is an empty cell
        return "" if isinstance(v, float) and math.isnan(v) else f"{v:+.3g}" if isinstance(v, float) else str(v)

    L = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    L += ["| " + " | ".join(fmt(v) for v in r) + " |" for r in tab[cols].itertuples(index=False)]
    L.append("")
    n = tallies(tab)
    if n["rows"]:
        L.append(f"wrong acceptances: {n['wrong']} of {n['rows']}; criterion met: {n['met']} of {n['rows']}"
                 + (f"; a trim cut of 50 % possible at all (truth model's trim RMS <= half of M0's): "
                    f"{n['cut_possible']} of {n['rows']}" if "cut_possible" in n else "")
                 + (f"; criterion met with the trim cut measured above the noise floor (at least half of the truth "
                    f"model's cut): {n['met_floor']} of {n['rows']}" if "met_floor" in n else "")
                 + (f"; the truth's own form significant over the library at M0: {n['form']} of {n['rows']} "
                    f"(criterion met in {n['met_where_form']} of them)" if "form" in n else ""))
    if n["noise_rows"]:
        L.append(f"M0 + noise only: wrong acceptances: {n['noise_wrong']} of {n['noise_rows']}"
                 + (f"; nothing added: {n['noise_nothing']} of {n['noise_rows']}" if "noise_nothing" in n else ""))
    L.append("")
    return "\n".join(L)


def _true(col: pd.Series) -> pd.Series:
    """A column of booleans, also as a csv read back holds them (text)."""
    return col.astype(str).eq("True")


def tallies(tab: pd.DataFrame) -> dict:
    """The study's counts over one table: held-out rows (``rows``), wrong acceptances, criterion met, a 50 % trim cut
    possible, the truth's own form significant and the criterion met among those; M0 + noise rows, their wrong
    acceptances and how many added nothing. A count whose column the table lacks is left out."""
    held, none = tab[tab["truth"] != "none"], tab[tab["truth"] == "none"]
    n = {"rows": len(held), "wrong": int(_true(held["wrong acceptance"]).sum()),
         "met": int(_true(held["criterion met"]).sum()) if "criterion met" in held else 0,
         "noise_rows": len(none), "noise_wrong": int(_true(none["wrong acceptance"]).sum())}
    if "trim change possible %" in held:
        n["cut_possible"] = int((pd.to_numeric(held["trim change possible %"], errors="coerce") <= -50.0).sum())
    if "share of possible trim cut %" in held and "kept discovered term" in held:
        floor_met = [criterion_met_above_floor({**r, "wrong acceptance": str(r["wrong acceptance"]) == "True"})
                     for r in held.to_dict("records")]
        n["met_floor"] = sum(m is True for m in floor_met)
    if "truth form significant" in held:
        form = _true(held["truth form significant"])
        n["form"], n["met_where_form"] = int(form.sum()), int((form & _true(held["criterion met"])).sum())
    if "added (kept)" in none:
        n["noise_nothing"] = int((none["added (kept)"].astype(str) == "-").sum())
    return n


def summary(folders: list[Path]) -> str:
    """One markdown table of the tallies of several studies' ``held_out.csv``, one row per folder (no total: the
    folders differ in size and library, and a table may rerun another's effects)."""
    cols = ("table", "effects", "held-out rows", "wrong acceptances", "criterion met", "truth's form significant",
            "met where significant", "met, trim cut above the noise floor", "M0 + noise rows",
            "wrong acceptances (noise)", "nothing added (noise)")
    L = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for f in folders:
        tab = pd.read_csv(f / "held_out.csv", keep_default_na=False)
        n = tallies(tab)
        cells = (f.name, len(set(tab["truth"]) - {"none"}), n["rows"], n["wrong"], n["met"], n.get("form", "-"),
                 n.get("met_where_form", "-"), n.get("met_floor", "-"), n["noise_rows"], n["noise_wrong"],
                 n.get("noise_nothing", "-"))
        L.append("| " + " | ".join(str(c) for c in cells) + " |")
    return "\n".join(L) + "\n"

if __name__ == "__main__":
    raise SystemExit(exit_status(main, "held_out_effects"))
