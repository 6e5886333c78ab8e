"""Effects of the truth simulator that the identification model M0 does not declare.

Each effect plugs into M0 through the extension seam
(:mod:`pyomo_heli.physics.extensions`) and has a strength parameter whose
zero value gives M0 exactly. They follow model_spec.md section 4 and are
*not* the candidate extensions the closed-loop diagnosis offers: those are
the project's own modelling choices, written independently.

Identifiers used in configs: ``E1`` wake_on_tail, ``E2`` flapping_lag,
``E3`` inflow_lag, ``E4a`` cg_offset, ``E4b`` lon_rigging, ``E5a``
accelerometer_offset.
"""
from __future__ import annotations

from ..physics.extensions import Extension
from ..physics.parameters import DEG, ParameterSpec


def _sigmoid(z, ops):
    return 1.0 / (1.0 + ops.exp(-z))


class WakeOnTail(Extension):
    """E1: main-rotor wake impinging on the horizontal tail (rigid skewed-cylinder wake).

    Wake skew from the disc-frame flow, tan(chi) = mu_d / lambda_d. The tail,
    l_th = l_t + x_h behind the hub and z_d = d_t + l_th (gamma_s + beta_1c)
    below the disc, is immersed when x_1 < tan(chi) < x_2 with
    x_1 = (l_th - R)/z_d, x_2 = (l_th + R)/z_d; a smooth switch
    f_w = S((tan chi - x_1)/s_w) S((x_2 - tan chi)/s_w), S the logistic
    function, gives the downwash w_dw = K_lamT f_w lambda_i Omega R [m/s].
    """

    name = "wake_on_tail"
    strength = "K_lamT"

    def parameters(self):
        return [
            ParameterSpec("K_lamT", 0.0, "-", "truth: wake downwash factor at the tail (E1)",
                          "TUD code 'K_hs = 1.5' (model_spec 4, E1)"),
            ParameterSpec("d_t", 1.8, "m", "truth: stabiliser depth below the hub", "model_spec 4 [L]"),
            ParameterSpec("s_w", 0.5, "-", "truth: smoothing width of the immersion switch (in tan chi)",
                          "model_spec 4"),
        ]

    def tail_downwash(self, ctx):
        p, ops = ctx.p, ctx.ops
        tan_chi = ctx.disc.mu_d / ctx.disc.lambda_d
        l_th = ctx.l_t + ctx.x_h
        z_d = p["d_t"] + l_th * (p["gamma_s"] + ctx.beta_1c_tpp)
        x1 = (l_th - p["R"]) / z_d
        x2 = (l_th + p["R"]) / z_d
        f_w = _sigmoid((tan_chi - x1) / p["s_w"], ops) * _sigmoid((x2 - tan_chi) / p["s_w"], ops)
        ctx.wake_fraction = f_w
        return p["K_lamT"] * f_w * ctx.x["lambda_i"] * ctx.flow.v_tip


class FlappingLag(Extension):
    """E2: first-order tip-path-plane lag, tau_f d(beta_1c,tpp)/dt = beta_1c,qs - beta_1c,tpp.

    Rotor forces, hub moment and the disc-frame inflow use the lagged tilt.
    Strength tau_f [s]; the spec value is 16/(gamma Omega) = 0.071 s.
    """

    name = "flapping_lag"
    strength = "tau_f"
    states = ("beta_1c_tpp",)

    def parameters(self):
        return [ParameterSpec("tau_f", 0.0, "s", "truth: tip-path-plane lag time constant (E2)",
                              "16/(gamma Omega), model_spec 4 E2")]

    def tip_path_plane(self, ctx):
        ctx.beta_1c_tpp = ctx.x["beta_1c_tpp"]

    def state_equations(self, ctx):
        return {"beta_1c_tpp": (ctx.p["tau_f"], ctx.beta[1] - ctx.x["beta_1c_tpp"])}


class InflowLag(Extension):
    """E3: an inflow time constant different from M0's, tau = tau_lambda (1 + k_tau).

    The spec's truth uses Pitt-Peters, 8/(3 pi Omega) = 0.019 s against
    M0's 0.1 s, i.e. k_tau = -0.809.
    """

    name = "inflow_lag"
    strength = "k_tau"

    def parameters(self):
        return [ParameterSpec("k_tau", 0.0, "-", "truth: relative change of the inflow time constant (E3)",
                              "Pitt-Peters vs TUD, model_spec 4 E3")]

    def adjust_inflow(self, ctx):
        ctx.tau_lambda = ctx.tau_lambda * (1 + ctx.p["k_tau"])


class CGOffset(Extension):
    """E4a: CG shifted aft by dx_cg [m]: the hub moves forward and the tail closer.

    x_h -> x_h + dx_cg, l_t -> l_t - dx_cg (model_spec 4 E4 gives the shift
    as x_h 0.08 -> 0.13 m; this sign convention names it an aft CG shift).
    """

    name = "cg_offset"
    strength = "dx_cg"

    def parameters(self):
        return [ParameterSpec("dx_cg", 0.0, "m", "truth: aft CG shift (E4a)", "model_spec 4 E4")]

    def adjust_geometry(self, ctx):
        ctx.x_h = ctx.x_h + ctx.p["dx_cg"]
        ctx.l_t = ctx.l_t - ctx.p["dx_cg"]


class LonRigging(Extension):
    """E4b: cyclic rigging bias: the measured lon is the true theta_1s plus delta_lon [rad]."""

    name = "lon_rigging"
    strength = "delta_lon"

    def parameters(self):
        return [ParameterSpec("delta_lon", 0.0, "rad", "truth: longitudinal cyclic rigging bias (E4b)",
                              "model_spec 4 E4", display=("deg", 1 / DEG))]

    def adjust_controls(self, ctx):
        ctx.lon = ctx.lon - ctx.p["delta_lon"]


class AccelerometerOffset(Extension):
    """E5a: accelerometer x_a forward of and z_a below the CG [m].

    n_z,meas = n_z + (dq/dt x_a + q^2 z_a)/g,  n_x,meas = n_x + (dq/dt z_a - q^2 x_a)/g
    """

    name = "accelerometer_offset"
    strength = "x_a"

    def parameters(self):
        return [ParameterSpec("x_a", 0.0, "m", "truth: accelerometer forward of the CG (E5a)", "model_spec 4 E5"),
                ParameterSpec("z_a", 0.0, "m", "truth: accelerometer below the CG (E5a)", "model_spec 4 E5")]

    def adjust_outputs(self, ctx):
        p, q, dq = ctx.p, ctx.x["q"], ctx.rates["q"]
        ctx.outputs["n_z"] = ctx.outputs["n_z"] + (dq * p["x_a"] + q**2 * p["z_a"]) / p["g"]
        ctx.outputs["n_x"] = ctx.outputs["n_x"] + (dq * p["z_a"] - q**2 * p["x_a"]) / p["g"]


TRUTH_EFFECTS = {
    "E1": WakeOnTail, "wake_on_tail": WakeOnTail,
    "E2": FlappingLag, "flapping_lag": FlappingLag,
    "E3": InflowLag, "inflow_lag": InflowLag,
    "E4a": CGOffset, "cg_offset": CGOffset,
    "E4b": LonRigging, "lon_rigging": LonRigging,
    "E5a": AccelerometerOffset, "accelerometer_offset": AccelerometerOffset,
}

#: strengths at the values of model_spec.md section 4
SPEC_STRENGTHS = {
    "wake_on_tail": {"K_lamT": 1.5},
    "flapping_lag": {"tau_f": 0.071},
    "inflow_lag": {"k_tau": 0.019 / 0.1 - 1.0},
    "cg_offset": {"dx_cg": 0.05},
    "lon_rigging": {"delta_lon": 0.3 * DEG},
    "accelerometer_offset": {"x_a": 1.0},
}


def all_effects() -> dict:
    """Every effect a generator config may name: these and the held-out ones
    (:mod:`.held_out_effects`, imported here lazily so that importing this module does not load them)."""
    from .held_out_effects import HELD_OUT_EFFECTS

    return {**TRUTH_EFFECTS, **HELD_OUT_EFFECTS}


def make_effect(name: str) -> Extension:
    effects = all_effects()
    try:
        return effects[name]()
    except KeyError:
        raise KeyError(f"unknown truth effect {name!r}; choose from {', '.join(sorted(effects))}") from None
