"""The library of candidate model extensions the closed loop may add to M0.

Each candidate is an :class:`~pyomo_heli.physics.extensions.Extension`: a
parametric physical effect with one *strength* parameter whose zero value
gives M0 exactly, plugged in through the model's extension seam. The forms
are this project's own modelling choices (docs/model.md, section
"Candidate extensions"); they are deliberately written without reference to
the truth simulator's effects (:mod:`pyomo_heli.flighttest.truth_effects`),
because a user's aircraft will not follow our truth simulator.

Every strength has bounds and a scale (used when the loop frees it) and,
for state-adding or stiff candidates, ``score_step``: the absolute
finite-difference step used by the score test (see
:mod:`pyomo_heli.diagnosis.attribution`).

Registry: :data:`CANDIDATES` (name -> class); :func:`make_candidate` builds one.
"""
from __future__ import annotations

from ..physics.extensions import Extension
from ..physics.model import HelicopterModel
from ..physics.parameters import DEG, ParameterSpec

LN2 = 0.6931471805599453
XI_EPS = 1e-12  # [wake radii^2] keeps |xi|^n smooth at xi = 0


class Candidate(Extension):
    """An extension offered to the diagnosis: one strength, a physical reason, a score-test step."""

    #: absolute step of the score-test finite difference (None: the default relative step)
    score_step: float | None = None
    #: True when only one sign of the strength is physical (lower bound 0): one-sided score test
    one_sided: bool = False
    #: what the effect does to the data, shown in reports
    signature: str = ""
    #: shape parameters (not the strength): at their defaults the candidate has its documented form; the
    #: closed loop may free them at the time-domain anchor only, with a likelihood-ratio test against the
    #: defaults, and then holds them for the whole front (pyomo_heli.workflows.close_loop.select_shape)
    shape_parameters: tuple[str, ...] = ()


class RotorWakeOnTail(Candidate):
    """Rotor wake on the horizontal tail: downwash w_dw = k_wt g(xi) 2 lambda_i Omega R at the tail.

    The wake is a cylinder of radius R leaving the tip-path plane (TPP) along
    the skew angle chi, tan(chi) = mu_d / lambda_d. That angle is measured in
    the disc frame, so the tail's position is taken into the same frame: the
    stabiliser, l_th = l_t + x_h aft of the hub and z_ht below it in body axes,
    is, in the frame of the disc tilted forward by a = gamma_s + beta_1c_tpp
    (the tilt that carries the thrust),

        aft   = l_th cos a - z_ht sin a      (along the disc plane)
        depth = z_ht cos a + l_th sin a      (below the disc plane)

    A forward-tilted disc thus puts the tail deeper below the wake origin
    (by about l_th a, 0.2-0.3 m). At that depth the wake centre line is
    depth tan(chi) aft of the hub, and the tail is
    xi = (aft - depth tan chi) / R wake radii from it.

    Immersion is a smooth top hat g = 2^(-xi^6) = exp(-ln 2 xi^6): 1 on the
    centre line, 1/2 on the wake boundary |xi| = 1 (a point on a vortex sheet
    sees the mean of the velocities on its two sides) and, outside, falling
    faster than exponentially: the axial velocity induced by a vortex
    cylinder is zero outside it. An algebraic tail such as 1/(1 + xi^6)
    would leave a downwash gradient at high speed, where the wake lies
    almost in the disc plane and a 1 m/s change of w moves its boundary past
    the tail by 0.6-0.8 wake radii (60-100 kt). The fully developed wake carries twice
    the disc-induced velocity, hence 2 lambda_i Omega R; k_wt scales it.

    n_wt is a shape parameter: how sharp the wake boundary is depends on the
    roll-up of the tip vortices, which this model does not resolve. It is
    held at 6 unless the time series show otherwise (the closed loop's
    shape rule); |xi|^n is written (xi^2 + 1e-12)^(n/2), smooth in n and xi.
    """

    name = "rotor_wake_on_tail"
    strength = "k_wt"
    one_sided = True
    signature = "low-speed bump (10-50 kt) in trim lon/theta; q/theta in low-speed maneuvers"
    shape_parameters = ("n_wt",)

    def parameters(self):
        return [
            ParameterSpec("k_wt", 0.0, "-", "candidate: wake downwash at the tail / twice the induced velocity",
                          "choice", (0.0, 5.0), 1.0),
            ParameterSpec("z_ht", 1.7, "m", "candidate: stabiliser depth below the hub (drawing value)", "choice"),
            ParameterSpec("n_wt", 6.0, "-", "candidate: order of the immersion profile 2^(-|xi|^n) (shape)",
                          "choice (the sharpness of the first form, 1/(1 + xi^6))", (2.0, 24.0), 1.0),
        ]

    @staticmethod
    def immersion(ctx):
        """xi (distance of the tail from the wake centre line in wake radii) and g(xi), at ``ctx``."""
        p, ops = ctx.p, ctx.ops
        a = p["gamma_s"] + ctx.beta_1c_tpp
        l_th = ctx.l_t + ctx.x_h
        aft = l_th * ops.cos(a) - p["z_ht"] * ops.sin(a)
        depth = p["z_ht"] * ops.cos(a) + l_th * ops.sin(a)
        tan_chi = ctx.disc.mu_d / ctx.disc.lambda_d
        xi = (aft - depth * tan_chi) / p["R"]
        # |xi|^n as (xi^2 + eps)^(n/2): differentiable in n also on the centre line
        return xi, ops.exp(-LN2 * (xi**2 + XI_EPS) ** (0.5 * p["n_wt"]))

    def tail_downwash(self, ctx):
        _, g = self.immersion(ctx)
        return ctx.p["k_wt"] * g * 2.0 * ctx.x["lambda_i"] * ctx.flow.v_tip


class FlappingLag(Candidate):
    """Flapping lag: first-order tip-path-plane response tau_b db/dt = beta_1c,qs - b.

    The rotor force direction, the hub moment and the disc-frame inflow use
    the lagged longitudinal tilt b instead of the quasi-steady beta_1c.
    Physical value about 16/(gamma Omega) = 0.07 s for the Bo-105.
    """

    name = "flapping_lag"
    strength = "tau_b"
    states = ("b1c_lag",)
    one_sided = True
    # RK4 needs tau well above the sample step; the difference is a secant over 0..0.04 s
    score_step = 0.02
    signature = "no trim residual; q residual at cyclic input edges (2-15 rad/s)"

    def parameters(self):
        return [ParameterSpec("tau_b", 0.0, "s", "candidate: tip-path-plane lag time constant", "choice",
                              (0.0, 0.3), 0.05)]

    def tip_path_plane(self, ctx):
        ctx.beta_1c_tpp = ctx.x["b1c_lag"]

    def state_equations(self, ctx):
        return {"b1c_lag": (ctx.p["tau_b"], ctx.beta[1] - ctx.x["b1c_lag"])}


class InflowTimeConstant(Candidate):
    """Inflow time constant: tau_lambda -> tau_lambda exp(k_ti) (log scale keeps it positive).

    k_ti = ln(0.019/0.1) = -1.66 would be Pitt-Peters' 8/(3 pi Omega) against M0's 0.1 s.
    """

    name = "inflow_time_constant"
    strength = "k_ti"
    signature = "no trim residual; n_z/beta_0 transients after collective steps"

    def parameters(self):
        return [ParameterSpec("k_ti", 0.0, "-", "candidate: log of the inflow time-constant factor", "choice",
                              (-3.0, 1.5), 1.0)]

    def adjust_inflow(self, ctx):
        ctx.tau_lambda = ctx.tau_lambda * ctx.ops.exp(ctx.p["k_ti"])


class CGOffset(Candidate):
    """CG offset: the CG dx_fwd forward of its nominal station (hub aft: x_h - dx, tail arm l_t + dx)."""

    name = "cg_offset"
    strength = "dx_fwd"
    signature = "constant lon and theta trim offsets of opposite sign, growing little with speed"

    def parameters(self):
        return [ParameterSpec("dx_fwd", 0.0, "m", "candidate: CG forward shift", "choice", (-0.5, 0.5), 0.1)]

    def adjust_geometry(self, ctx):
        ctx.x_h = ctx.x_h - ctx.p["dx_fwd"]
        ctx.l_t = ctx.l_t + ctx.p["dx_fwd"]


class LonRiggingBias(Candidate):
    """Cyclic rigging bias: the rotor sees theta_1s = lon_measured + b_lon."""

    name = "lon_rigging"
    strength = "b_lon"
    signature = "constant lon trim offset, no attitude change"

    def parameters(self):
        return [ParameterSpec("b_lon", 0.0, "rad", "candidate: longitudinal cyclic rigging bias", "choice",
                              (-3 * DEG, 3 * DEG), 0.5 * DEG, display=("deg", 1 / DEG))]

    def adjust_controls(self, ctx):
        ctx.lon = ctx.lon + ctx.p["b_lon"]


class ColRiggingBias(Candidate):
    """Collective rigging bias: the rotor sees col_measured + b_col (at r_ref)."""

    name = "col_rigging"
    strength = "b_col"
    signature = "constant collective trim offset"

    def parameters(self):
        return [ParameterSpec("b_col", 0.0, "rad", "candidate: collective rigging bias", "choice",
                              (-3 * DEG, 3 * DEG), 0.5 * DEG, display=("deg", 1 / DEG))]

    def adjust_controls(self, ctx):
        ctx.col = ctx.col + ctx.p["b_col"]


class AccelerometerPositionX(Candidate):
    """Accelerometer dx_acc forward of the CG: specific force at r = (dx, 0, 0) of a body pitching at q.

    a_meas = a_cg + dq/dt x r + q x (q x r) gives n_z += dq/dt dx/g and n_x -= q^2 dx/g.
    """

    name = "accel_position_x"
    strength = "dx_acc"
    signature = "n_z residual proportional to pitch acceleration; nothing in trim"

    def parameters(self):
        return [ParameterSpec("dx_acc", 0.0, "m", "candidate: accelerometer forward of the CG", "choice",
                              (-3.0, 3.0), 1.0)]

    def adjust_outputs(self, ctx):
        dx, g = ctx.p["dx_acc"], ctx.p["g"]
        q, dq = ctx.x["q"], ctx.rates["q"]
        ctx.outputs["n_z"] = ctx.outputs["n_z"] + dq * dx / g
        ctx.outputs["n_x"] = ctx.outputs["n_x"] - q**2 * dx / g


class AccelerometerPositionZ(Candidate):
    """Accelerometer dz_acc below the CG: n_x += dq/dt dz/g, n_z += q^2 dz/g (same kinematics)."""

    name = "accel_position_z"
    strength = "dz_acc"
    signature = "n_x residual proportional to pitch acceleration; nothing in trim"

    def parameters(self):
        return [ParameterSpec("dz_acc", 0.0, "m", "candidate: accelerometer below the CG", "choice",
                              (-3.0, 3.0), 1.0)]

    def adjust_outputs(self, ctx):
        dz, g = ctx.p["dz_acc"], ctx.p["g"]
        q, dq = ctx.x["q"], ctx.rates["q"]
        ctx.outputs["n_x"] = ctx.outputs["n_x"] + dq * dz / g
        ctx.outputs["n_z"] = ctx.outputs["n_z"] + q**2 * dz / g


class NormalAccelBias(Candidate):
    """Normal accelerometer bias: n_z,meas = n_z + b_nz."""

    name = "nz_bias"
    strength = "b_nz"
    signature = "constant n_z residual in every maneuver"

    def parameters(self):
        return [ParameterSpec("b_nz", 0.0, "-", "candidate: normal load-factor sensor bias [g]", "choice",
                              (-0.2, 0.2), 0.01)]

    def adjust_outputs(self, ctx):
        ctx.outputs["n_z"] = ctx.outputs["n_z"] + ctx.p["b_nz"]


class LongitudinalAccelBias(Candidate):
    """Longitudinal accelerometer bias: n_x,meas = n_x + b_nx."""

    name = "nx_bias"
    strength = "b_nx"
    signature = "constant n_x residual in every maneuver"

    def parameters(self):
        return [ParameterSpec("b_nx", 0.0, "-", "candidate: longitudinal load-factor sensor bias [g]", "choice",
                              (-0.2, 0.2), 0.01)]

    def adjust_outputs(self, ctx):
        ctx.outputs["n_x"] = ctx.outputs["n_x"] + ctx.p["b_nx"]


# A pitch-rate gyro bias or an attitude bias is not offered: the float simulator reports q and theta as
# states, not as sensor outputs, so a bias on them would not reach the score test or the report.
CANDIDATES: dict[str, type[Candidate]] = {c.name: c for c in (
    RotorWakeOnTail, FlappingLag, InflowTimeConstant, CGOffset, LonRiggingBias, ColRiggingBias,
    AccelerometerPositionX, AccelerometerPositionZ, NormalAccelBias, LongitudinalAccelBias)}


def candidate_names() -> list[str]:
    return list(CANDIDATES)


def make_candidate(name: str) -> Candidate:
    """The candidate called ``name`` (a physical effect of :data:`CANDIDATES`, or a term of the generic
    discrepancy family, :mod:`pyomo_heli.physics.discrepancy`); KeyError naming the known ones (and close
    matches) otherwise."""
    from ..physics.discrepancy import generic_term, is_generic

    if is_generic(name):
        return generic_term(name)
    try:
        return CANDIDATES[name]()
    except KeyError:
        import difflib

        close = difflib.get_close_matches(name, list(CANDIDATES), n=2)
        hint = f" (did you mean {' or '.join(close)}?)" if close else ""
        raise KeyError(f"unknown candidate extension {name!r}{hint}; choose from {', '.join(CANDIDATES)}") from None


def as_candidate(term) -> Extension:
    """``term`` as an extension to score or estimate: a library name (:func:`make_candidate`), or an extension
    object passed as it is (a study's own effect, e.g. the truth's form for a detectability check). An object
    needs a ``strength`` parameter with bounds (ValueError naming its class otherwise); ``one_sided``,
    ``score_step`` and ``shape_parameters`` default to a two-sided strength, analytic sensitivities and no shape."""
    if not isinstance(term, Extension):
        return make_candidate(term)
    name, strength = type(term).__name__, getattr(term, "strength", None)
    specs = {s.name: s for s in term.parameters()}
    if strength not in specs:
        raise ValueError(f"{name} declares no parameter named by its 'strength' ({strength!r})")
    if specs[strength].bounds is None:
        raise ValueError(f"{name}'s strength {strength!r} has no bounds; declare ParameterSpec(..., bounds=(lower, "
                         f"upper)) so that the NLP can free it within them")
    return term


def model_with_candidates(model: HelicopterModel, names, shape: dict | None = None) -> HelicopterModel:
    """``model`` plus the candidate extensions ``names`` (in order), their shape parameters at ``shape`` (the
    values a loop iteration held; defaults for those not given). The one place a loop iteration's model is
    rebuilt from its record (the loop, ``config_of_result``, the loop report)."""
    out = HelicopterModel(parameters=model.parameters,
                          extensions=tuple(model.extensions) + tuple(make_candidate(n) for n in names))
    return out.with_parameters(**(shape or {}))
