"""The generic discrepancy family: force, moment and sensor corrections that name no physics.

Every term is one extension (:mod:`.extensions`) with one coefficient ``c`` whose zero value
gives M0 exactly; the same object serves the float simulator, the trim blocks and the
collocation blocks (its hooks only do arithmetic on ``ctx``). Normalised by the weight
W = m g [N] and, for the moment, the rotor radius R [m]:

    dX = c W phi(x, u)      dZ = c W phi(x, u)      dM = c W R phi(x, u)

with ``phi`` a dimensionless regressor of order one over the envelope (:data:`REGRESSORS`):

    one              1
    mu, mu2, mu4     mu/0.3, (mu/0.3)^2, (mu/0.3)^4        growth with speed (mu: hub advance ratio)
    bump00..bump15   exp(-((mu - mu_c)/0.05)^2), mu_c = 0, 0.05, 0.10, 0.15  a low-speed bump (0, 21, 43, 64 kt)
    alpha            (w / V) / 0.1                          fuselage angle of attack
    w                w / 5 m/s                              heave velocity
    q                q / 0.2 rad/s                          pitch rate
    lam              lambda_i / 0.05                        induced inflow (the wake's strength)
    col, lon         col / 0.2 rad, lon / 0.05 rad          the controls the rotor sees (after rigging,
                                                            scale, delay or feedback terms)

Extended family only (``generic_names("extended")``), the speed products of the state and control
regressors (the classic dimensional form of a derivative, e.g. a pitch damping that grows with V):

    alphamu, wmu, qmu, colmu, lonmu    the regressor above x mu/0.3

Sensor side (data compatibility of flight-path reconstruction), per channel:

    TAS_scale        TAS_meas = (1 + c) TAS                 airspeed calibration (position error)
    nx_scale         n_x,meas = (1 + c) n_x
    lon_scale,       the rotor sees (1 + c) u: a scale factor of the control channel's
      col_scale      calibration (extended family only)
    beta0_bias       beta_0,meas = beta_0 + c [rad]
    lon_delay,       c d(u_d)/dt = u - u_d, the rotor sees u_d: a time shift c [s] of the measured
      col_delay      control (first order), a lag state added only when c is not zero
    nx_delay, nz_delay, c d(y_d)/dt = y - y_d, the record holds y_d: a time shift c [s] of the output
      TAS_delay,     (first order, the same lag state; y before any other sensor effect, which
      beta0_delay    then acts on y_d)

Control family only (``generic_names("control")``: extended + these), feedback in the control path
between the recorded control and the rotor, e.g. a damper or an attitude hold the model lacks:

    lon_q, lon_theta   the rotor sees lon + c (0.05 rad) q/(0.2 rad/s), or + c (0.05 rad) theta/(0.1 rad)
    col_q, col_theta   the rotor sees col + c (0.2 rad) q/(0.2 rad/s), or + c (0.2 rad) theta/(0.1 rad)

(No n_x / n_z bias: the candidate library already holds those as named sensor effects. No time shift
of q or theta: they are states as well as outputs, and the float simulator's frame holds one column
for each, the state; :func:`pyomo_heli.simulation.integrate.simulate` refuses a sensor effect on them.)

A term's name is ``d<channel>_<regressor>`` (e.g. ``dM_bump05``), its coefficient
``c_<channel>_<regressor>``; :func:`generic_term` builds one, :func:`generic_names` lists a
family: ``"standard"`` (the default library of the discovery loop), ``"extended"`` (standard +
the speed products + the input scale factors) or ``"control"`` (extended + the control-path
feedback terms), ``[loop] generic_family``. In an identification
every coefficient is an ordinary parameter: fixed at zero until the structure determination frees
it (:mod:`pyomo_heli.diagnosis.discovery`).
"""
from __future__ import annotations

from ..channels import INPUTS
from ..units import DEG
from .extensions import Extension
from .parameters import ParameterSpec

MU_REF = 0.3
BUMP_WIDTH = 0.05
BUMP_CENTRES = {"bump00": 0.0, "bump05": 0.05, "bump10": 0.10, "bump15": 0.15}

def _bump(centre: float):
    """exp(-((mu - centre)/BUMP_WIDTH)^2) as a function of ctx."""
    return lambda ctx: ctx.ops.exp(-(((ctx.flow.mu - centre) / BUMP_WIDTH) ** 2))


#: regressor -> (formula shown in reports, function of ctx)
REGRESSORS = {
    "one": ("1", lambda ctx: 1.0),
    "mu": ("mu/0.3", lambda ctx: ctx.flow.mu / MU_REF),
    "mu2": ("(mu/0.3)^2", lambda ctx: (ctx.flow.mu / MU_REF) ** 2),
    "mu4": ("(mu/0.3)^4", lambda ctx: (ctx.flow.mu / MU_REF) ** 4),
    **{k: (f"exp(-((mu-{c:.2f})/0.05)^2)", _bump(c)) for k, c in BUMP_CENTRES.items()},
    "alpha": ("(w/V)/0.1",
              lambda ctx: ctx.x["w"] / ctx.ops.sqrt(ctx.x["u"] ** 2 + ctx.x["w"] ** 2 + ctx.p["eps_v"] ** 2)
              / 0.1),
    "w": ("w/(5 m/s)", lambda ctx: ctx.x["w"] / 5.0),
    "q": ("q/(0.2 rad/s)", lambda ctx: ctx.x["q"] / 0.2),
    "lam": ("lambda_i/0.05", lambda ctx: ctx.x["lambda_i"] / 0.05),
    "col": ("col/(0.2 rad)", lambda ctx: ctx.col / 0.2),
    "lon": ("lon/(0.05 rad)", lambda ctx: ctx.lon / 0.05),
}
#: state and control regressors whose product with mu/0.3 the extended family adds (``qmu``...)
SPEED_PRODUCTS = ("alpha", "w", "q", "col", "lon")


def _times_mu(regressor):
    """regressor(ctx) x mu/0.3 as a function of ctx."""
    return lambda ctx: regressor(ctx) * ctx.flow.mu / MU_REF


EXTENDED_REGRESSORS = {f"{r}mu": (f"{REGRESSORS[r][0]} (mu/0.3)", _times_mu(REGRESSORS[r][1])) for r in SPEED_PRODUCTS}
REGRESSORS = {**REGRESSORS, **EXTENDED_REGRESSORS}
FORCE_CHANNELS = ("X", "Z", "M")
#: sensor terms: name -> (output or input, kind, formula)
SENSOR_TERMS = {
    "TAS_scale": ("TAS", "scale", "TAS_meas = (1 + c) TAS"),
    "nx_scale": ("n_x", "scale", "n_x,meas = (1 + c) n_x"),
    "beta0_bias": ("beta_0", "bias", "beta_0,meas = beta_0 + c [rad]"),
    "lon_delay": ("lon", "delay", "c d(lon_d)/dt = lon - lon_d, the rotor sees lon_d (input time shift c [s])"),
    "col_delay": ("col", "delay", "c d(col_d)/dt = col - col_d, the rotor sees col_d (input time shift c [s])"),
    "lon_scale": ("lon", "scale", "the rotor sees (1 + c) lon (input scale factor)"),
    "col_scale": ("col", "scale", "the rotor sees (1 + c) col (input scale factor)"),
    **{f"{k}_delay": (out, "delay", f"c d({out}_d)/dt = {out} - {out}_d, the record holds {out}_d "
                                    "(output time shift c [s])")
       for k, out in (("nx", "n_x"), ("nz", "n_z"), ("TAS", "TAS"), ("beta0", "beta_0"))},
}
#: terms only in the extended family
EXTENDED_ONLY = (*(f"d{ch}_{r}" for ch in FORCE_CHANNELS for r in EXTENDED_REGRESSORS), "lon_scale", "col_scale")
#: the control path's feedback terms (control family only): name -> (control, state, state's normalisation)
CONTROL_NORM = {"lon": 0.05, "col": 0.2}  # [rad], as the "lon" and "col" regressors
FEED_STATES = {"q": ("q/(0.2 rad/s)", 0.2), "theta": ("theta/(0.1 rad)", 0.1)}
FEED_TERMS = {f"{u}_{x}": (u, x) for u in CONTROL_NORM for x in FEED_STATES}
FAMILIES = ("standard", "extended", "control")
#: coefficient bounds and scale: force (X, Z: fraction of W), moment (fraction of W R), sensor
BOUNDS = {"X": (-0.2, 0.2, 0.005), "Z": (-0.2, 0.2, 0.005), "M": (-0.02, 0.02, 0.001),
          "scale": (-0.2, 0.2, 0.01), "bias": (-0.05, 0.05, 0.005), "delay": (0.0, 0.3, 0.05),
          "feed": (-1.0, 1.0, 0.05)}


class GenericTerm(Extension):
    """One term of the generic discrepancy family (module docstring): dX, dZ or dM = c x norm x phi, a
    data-compatibility term, or a control-path feedback term."""

    score_step = None
    one_sided = False
    shape_parameters: tuple[str, ...] = ()
    generic = True

    def __init__(self, channel: str, regressor: str):
        if channel in FORCE_CHANNELS:
            if regressor not in REGRESSORS:
                raise KeyError(f"unknown regressor {regressor!r}; choose from {', '.join(REGRESSORS)}")
            self.name = f"d{channel}_{regressor}"
            self.kind = channel
        elif channel == "control":
            if regressor not in FEED_TERMS:
                raise KeyError(f"unknown control-path term {regressor!r}; choose from {', '.join(FEED_TERMS)}")
            self.name = regressor
            self.kind = "feed"
        elif channel == "sensor":
            if regressor not in SENSOR_TERMS:
                raise KeyError(f"unknown sensor term {regressor!r}; choose from {', '.join(SENSOR_TERMS)}")
            self.name = regressor
            self.kind = SENSOR_TERMS[regressor][1]
            if self.kind == "delay":  # a lag state; one-sided; the score test's secant step as for a time constant
                self.states = (f"{SENSOR_TERMS[regressor][0]}_delayed",)
                self.one_sided = True
                self.score_step = 0.02
        else:
            raise KeyError(f"unknown discrepancy channel {channel!r}; choose from X, Z, M, sensor, control")
        self.channel, self.regressor = channel, regressor
        self.strength = f"c_{self.name}"
        self.signature = self.formula()

    def formula(self) -> str:
        """The term as an equation with the coefficient written c."""
        if self.channel == "sensor":
            return SENSOR_TERMS[self.regressor][2]
        if self.channel == "control":
            u, x = FEED_TERMS[self.regressor]
            return f"the rotor sees {u} + c ({CONTROL_NORM[u]:g} rad) {FEED_STATES[x][0]} (control-path feedback)"
        norm = "m g R" if self.channel == "M" else "m g"
        return f"d{self.channel} = c {norm} {REGRESSORS[self.regressor][0]}"

    def describe(self) -> str:
        return f"generic discrepancy {self.formula()}"

    def parameters(self):
        lo, hi, scale = BOUNDS[self.kind]
        unit = {"bias": "rad", "delay": "s"}.get(self.kind, "-")
        return [ParameterSpec(self.strength, 0.0, unit, f"generic discrepancy coefficient: {self.formula()}",
                              "discrepancy family", (lo, hi), scale,
                              display=("deg", 1.0 / DEG) if unit == "rad" else None)]

    def value(self, ctx):
        """The force [N] or moment [N m] this term adds at ``ctx`` (0 for a sensor or control-path term)."""
        if self.channel not in FORCE_CHANNELS:
            return 0.0
        p = ctx.p
        return p[self.strength] * force_scale(p, self.channel) * REGRESSORS[self.regressor][1](ctx)

    def extra_forces(self, ctx):
        if self.channel not in FORCE_CHANNELS:
            return 0.0, 0.0, 0.0
        d = self.value(ctx)
        return (d, 0.0, 0.0) if self.channel == "X" else (0.0, d, 0.0) if self.channel == "Z" else (0.0, 0.0, d)

    @property
    def on_input(self) -> bool:
        """A data-compatibility or control-path term of a control channel (the rotor sees a changed control)."""
        return self.channel == "control" or (self.channel == "sensor" and SENSOR_TERMS[self.regressor][0] in INPUTS)

    @property
    def delays_input(self) -> bool:
        return self.kind == "delay" and self.on_input

    @property
    def output_stage(self) -> int:
        """0 for an output's time shift: it runs before the other sensor effects (module docstring)."""
        return 0 if self.kind == "delay" and self.channel == "sensor" and not self.on_input else 1

    def adjust_controls(self, ctx):
        if not self.on_input:
            return
        if self.kind == "feed":
            u, x = FEED_TERMS[self.regressor]
            setattr(ctx, u, getattr(ctx, u) + ctx.p[self.strength] * CONTROL_NORM[u] * ctx.x[x] / FEED_STATES[x][1])
            return
        inp = SENSOR_TERMS[self.regressor][0]
        if self.kind == "scale":
            setattr(ctx, inp, (1 + ctx.p[self.strength]) * getattr(ctx, inp))
            return
        setattr(ctx, f"{inp}_commanded", getattr(ctx, inp))
        setattr(ctx, inp, ctx.x[self.states[0]])

    def state_equations(self, ctx):
        if self.kind != "delay":
            return {}
        ch, d = SENSOR_TERMS[self.regressor][0], ctx.x[self.states[0]]
        return {self.states[0]: (ctx.p[self.strength],
                                 (getattr(ctx, f"{ch}_commanded") if self.delays_input else ctx.true_outputs[ch]) - d)}

    def adjust_outputs(self, ctx):
        if self.channel != "sensor" or self.on_input:
            return
        out, kind, _ = SENSOR_TERMS[self.regressor]
        if kind == "delay":  # the record holds the lagged output; other sensor effects act on it as on the output
            ctx.outputs[out] = ctx.outputs[out] + (ctx.x[self.states[0]] - ctx.true_outputs[out])
            return
        c = ctx.p[self.strength]
        ctx.outputs[out] = ctx.outputs[out] * (1 + c) if kind == "scale" else ctx.outputs[out] + c


def generic_names(family: str = "standard") -> list[str]:
    """Every term of a family: the force and moment terms, then the sensor terms (then, in ``"control"``, the
    control-path terms). ``"standard"`` leaves out the terms of :data:`EXTENDED_ONLY`; ``"extended"`` has them;
    ``"control"`` adds :data:`FEED_TERMS`."""
    if family not in FAMILIES:
        raise ValueError(f"unknown discrepancy family {family!r}; choose from {', '.join(FAMILIES)}")
    names = [f"d{ch}_{r}" for ch in FORCE_CHANNELS for r in REGRESSORS] + list(SENSOR_TERMS)
    if family == "standard":
        return [n for n in names if n not in EXTENDED_ONLY]
    return names + (list(FEED_TERMS) if family == "control" else [])


def is_generic(name: str) -> bool:
    return name in set(generic_names("control"))


def is_force_term(name: str) -> bool:
    """Is ``name`` a force or moment term of the family (dX, dZ, dM), not a data-compatibility term?"""
    return is_generic(name) and name[1] in FORCE_CHANNELS and name[0] == "d"


def force_scale(p, channel: str):
    """The family's normalisation of a force or moment channel: W = m g [N] for X and Z, W R [N m] for M."""
    return p["m"] * p["g"] * (p["R"] if channel == "M" else 1.0)


def generic_term(name: str) -> GenericTerm:
    """The term called ``name`` (``dM_bump05``, ``TAS_scale``...); KeyError naming the family otherwise."""
    if name in SENSOR_TERMS:
        return GenericTerm("sensor", name)
    if name in FEED_TERMS:
        return GenericTerm("control", name)
    if len(name) > 3 and name[0] == "d" and name[1] in FORCE_CHANNELS and name[2] == "_" and name[3:] in REGRESSORS:
        return GenericTerm(name[1], name[3:])
    raise KeyError(f"unknown discrepancy term {name!r}; the family is {', '.join(generic_names('control'))}")
