"""Truth effects held out from the diagnosis: none of them is in the candidate library.

The closed loop's library (:mod:`pyomo_heli.diagnosis.candidates`) and its generic
discrepancy family (:mod:`pyomo_heli.physics.discrepancy`) never import this module
(``tests/test_discovery.py`` checks it). These effects stand in for what a real aircraft
holds and nobody listed: each has its own dependence on speed, state or time, and plugs
into M0 through the extension seam (:mod:`pyomo_heli.physics.extensions`) with a strength
whose zero value gives M0 exactly. Use them in a generator config like the other truth
effects, e.g. ``[truth.effects.fuselage_download] k_fd = 0.03``.

Conventions: body axes at the CG, x forward, z down, M nose-up; X, Z in N, M in N m.
A force dZ acting x_p forward of the CG adds the moment dM = -x_p dZ.

Nominal strengths (:data:`HELD_OUT_STRENGTHS`) are chosen so that each effect moves the
bundled flight test's trims or maneuvers by a few sensor sigmas, as real model errors do. H8-H10 were
added later as a fresh blind set, and H11-H13 after the record-bias test: the strengths of each set were fixed
from physics (float trims against the trim sigmas) before any loop ran on them. H14-H16 were added later still as
a third blind set, with their strengths fixed the same way (float trims and noise-free maneuver records against
the trim and sensor sigmas) before any loop ran on them. H17-H19 were added later still as a fourth blind set, their
strengths fixed the same way (float trims and noise-free doublets of the bundled maneuvers against the trim and
sensor sigmas) before any loop ran on them.
"""
from __future__ import annotations

import math

from ..physics.extensions import Extension
from ..physics.parameters import ParameterSpec
from ..physics import fuselage, rotor
from ..physics.tail import tail_forces


class FuselageDownload(Extension):
    """H1: rotor wake on the fuselage: a download at low speed that the skewed wake leaves behind.

        f = exp(-(mu / mu_fd)^2)                    (1 in hover, 0.37 at mu = mu_fd)
        dZ = k_fd T f            [N]   (down, T the rotor thrust)
        dM = x_fd dZ             [N m] (the download's centroid x_fd aft of the CG: nose-up)

    Strength k_fd [-] (fraction of the thrust); mu_fd = 0.06 (about 25 kt), x_fd = 0.8 m.
    """

    name = "fuselage_download"
    strength = "k_fd"

    def parameters(self):
        return [ParameterSpec("k_fd", 0.0, "-", "held-out truth: fuselage download / thrust in hover", "held out"),
                ParameterSpec("mu_fd", 0.06, "-", "held-out truth: advance ratio where the download fades", "held out"),
                ParameterSpec("x_fd", 0.8, "m", "held-out truth: download centroid aft of the CG", "held out")]

    def extra_forces(self, ctx):
        p, ops = ctx.p, ctx.ops
        f = ops.exp(-((ctx.flow.mu / p["mu_fd"]) ** 2))
        dZ = p["k_fd"] * ctx.thrust * f
        return 0.0, dZ, p["x_fd"] * dZ


class DragRise(Extension):
    """H2: drag rise at high speed (advancing-tip compressibility, hub and blade-root drag).

        dX = -k_dr 0.5 rho f_e V^2 (mu / 0.25)^4     [N]

    Strength k_dr [-]; negligible below about 80 kt, growing as V^6.
    """

    name = "drag_rise"
    strength = "k_dr"

    def parameters(self):
        return [ParameterSpec("k_dr", 0.0, "-", "held-out truth: drag rise factor at mu = 0.25", "held out")]

    def extra_forces(self, ctx):
        p, x = ctx.p, ctx.x
        V2 = x["u"] ** 2 + x["w"] ** 2
        return -p["k_dr"] * 0.5 * p["rho"] * p["f_e"] * V2 * (ctx.flow.mu / 0.25) ** 4, 0.0, 0.0


class CantedTailRotor(Extension):
    """H3: a canted tail rotor: part of the anti-torque thrust lifts the tail (bucket-shaped with speed).

    Main-rotor power, induced + profile + parasite:
        P = T lambda_i Omega R + P_0 (1 + 4.65 mu^2) + 0.5 rho f_e V^3,
        P_0 = rho pi R^2 (Omega R)^3 sigma c_d0 / 8,  sigma = N_b c / (pi R),  c_d0 = 0.01
    Tail-rotor thrust T_tr = P / (Omega l_tr) at l_tr = l_t + 0.9 m behind the CG, its lift k_tr T_tr:
        dZ = -k_tr T_tr [N],   dM = -l_tr k_tr T_tr = -k_tr P / Omega [N m] (nose-down)
    Strength k_tr = sin(cant angle) [-].
    """

    name = "canted_tail_rotor"
    strength = "k_tr"

    def parameters(self):
        return [ParameterSpec("k_tr", 0.0, "-", "held-out truth: sine of the tail-rotor cant angle", "held out")]

    def extra_forces(self, ctx):
        p, ops, x = ctx.p, ctx.ops, ctx.x
        v_tip = ctx.flow.v_tip
        sigma = p["Nb"] * p["c"] / (math.pi * p["R"])
        P0 = p["rho"] * math.pi * p["R"] ** 2 * v_tip**3 * sigma * 0.01 / 8.0
        V2 = x["u"] ** 2 + x["w"] ** 2 + p["eps_v"] ** 2
        P = (ctx.thrust * x["lambda_i"] * v_tip + P0 * (1 + 4.65 * ctx.flow.mu**2)
             + 0.5 * p["rho"] * p["f_e"] * V2 * ops.sqrt(V2))
        l_tr = ctx.l_t + 0.9
        T_tr = P / (p["Omega"] * l_tr)
        return 0.0, -p["k_tr"] * T_tr, -l_tr * p["k_tr"] * T_tr


class ControlMixing(Extension):
    """H4: mechanical collective-to-cyclic mixing in the control path.

        theta_1s = lon + k_mx (col - col_ref)     [rad], col_ref = 0.17 rad

    A lon offset that follows the collective's bucket over speed and its steps in maneuvers.
    Strength k_mx [rad/rad].
    """

    name = "control_mixing"
    strength = "k_mx"

    def parameters(self):
        return [ParameterSpec("k_mx", 0.0, "-", "held-out truth: collective-to-cyclic mixing gain", "held out"),
                ParameterSpec("col_ref", 0.17, "rad", "held-out truth: collective of zero mixing", "held out")]

    def adjust_controls(self, ctx):
        ctx.lon = ctx.lon + ctx.p["k_mx"] * (ctx.col - ctx.p["col_ref"])


class ActuatorLag(Extension):
    """H5: first-order lag of the longitudinal swashplate actuator.

        tau_a d(lon_act)/dt = lon - lon_act,   the rotor sees theta_1s = lon_act
    Nothing in trim; the response to cyclic inputs is delayed. Strength tau_a [s].
    """

    name = "actuator_lag"
    strength = "tau_a"
    states = ("lon_act",)

    def parameters(self):
        return [ParameterSpec("tau_a", 0.0, "s", "held-out truth: lon actuator time constant", "held out")]

    def adjust_controls(self, ctx):
        ctx.lon_commanded = ctx.lon
        ctx.lon = ctx.x["lon_act"]

    def state_equations(self, ctx):
        return {"lon_act": (ctx.p["tau_a"], ctx.lon_commanded - ctx.x["lon_act"])}


class AccelerometerFilter(Extension):
    """H6: first-order anti-aliasing filter in the normal accelerometer channel.

        tau_nz d(n_zf)/dt = n_z - n_zf,   n_z = -Z/(m g),   the sensor reports n_zf
    Nothing in trim; n_z transients delayed and smoothed. Strength tau_nz [s].
    """

    name = "accelerometer_filter"
    strength = "tau_nz"
    states = ("nz_filt",)

    def parameters(self):
        return [ParameterSpec("tau_nz", 0.0, "s", "held-out truth: n_z sensor filter time constant", "held out")]

    def state_equations(self, ctx):
        n_z = -ctx.forces.Z / (ctx.p["m"] * ctx.p["g"])
        return {"nz_filt": (ctx.p["tau_nz"], n_z - ctx.x["nz_filt"])}

    def adjust_outputs(self, ctx):
        ctx.outputs["n_z"] = ctx.x["nz_filt"]


class VerticalDrag(Extension):
    """H7: quadratic vertical drag of fuselage and stabilisers in heave.

        dZ = -k_vd 0.5 rho A_v w sqrt(w^2 + 0.01)  [N],  A_v = 12 m^2 (plan area)
        dM = -x_v dZ,  x_v = -1.5 m (centre of plan area aft of the CG)
    Strength k_vd [-] (drag coefficient in heave).
    """

    name = "vertical_drag"
    strength = "k_vd"

    def parameters(self):
        return [ParameterSpec("k_vd", 0.0, "-", "held-out truth: heave drag coefficient of the plan area", "held out")]

    def extra_forces(self, ctx):
        p, ops, w = ctx.p, ctx.ops, ctx.x["w"]
        dZ = -p["k_vd"] * 0.5 * p["rho"] * 12.0 * w * ops.sqrt(w**2 + 0.01)
        return 0.0, dZ, 1.5 * dZ


class PitotDownwash(Extension):
    """H8: rotor downwash on the airspeed probe: the pitot reads high at low speed.

        TAS_meas = TAS + k_pd v_i exp(-(mu / 0.08)^2)    [m/s],  v_i = lambda_i Omega R

    The probe sits in the wake at hover and low speed; the wake is swept clear of it by about 35 kt
    (mu = 0.08). A position error with its own dependence on speed and on the wake's strength, nothing
    in the forces. Strength k_pd [-] (share of the induced velocity that reaches the probe).
    """

    name = "pitot_downwash"
    strength = "k_pd"

    def parameters(self):
        return [ParameterSpec("k_pd", 0.0, "-", "held-out truth: share of the induced velocity at the pitot",
                              "held out")]

    def adjust_outputs(self, ctx):
        v_i = ctx.x["lambda_i"] * ctx.flow.v_tip
        ctx.outputs["TAS"] = ctx.outputs["TAS"] + ctx.p["k_pd"] * v_i * ctx.ops.exp(-((ctx.flow.mu / 0.08) ** 2))


class TailStall(Extension):
    """H9: the horizontal tail's lift curve bends over towards stall (a cubic lift loss).

        alpha_t = (u alpha_t0 + w_t) / sqrt(u^2 + w_t^2 + 1 m^2/s^2),  w_t = w + q l_t
        Z_T,truth = Z_T (1 - k_ts (alpha_t / 0.2)^2)
        dZ = -k_ts (alpha_t / 0.2)^2 Z_T  [N],   dM = l_t dZ  [N m]   (Z_T: M0's tail lift, tail.py)

    Small in level flight (alpha_t near the incidence), it grows with the tail's angle of attack in
    pitch and heave manoeuvres. Strength k_ts [-] (lift lost at alpha_t = 0.2 rad).
    """

    name = "tail_stall"
    strength = "k_ts"

    def parameters(self):
        return [ParameterSpec("k_ts", 0.0, "-", "held-out truth: tail lift lost at 0.2 rad tail angle of attack",
                              "held out")]

    def extra_forces(self, ctx):
        p, x = ctx.p, ctx.x
        w_t = x["w"] + x["q"] * ctx.l_t
        alpha_t = (x["u"] * p["alpha_t0"] + w_t) / ctx.ops.sqrt(x["u"] ** 2 + w_t**2 + 1.0)
        Z_T = tail_forces(x["u"], x["w"], x["q"], 0.0, p, l_t=ctx.l_t)[1]  # M0's tail lift
        dZ = -p["k_ts"] * (alpha_t / 0.2) ** 2 * Z_T
        return 0.0, dZ, ctx.l_t * dZ


class FuselagePitchDamping(Extension):
    """H10: aerodynamic pitch damping of the fuselage and skids, growing with airspeed.

        dM = -k_fq 0.25 rho V S_p l_p^2 q    [N m],  V = sqrt(u^2 + w^2 + eps_v^2)
        S_p = 12 m^2 (plan area), l_p = 4 m (half the fuselage length)

    The classic C_m_q form (M = q_dyn S c C_m_q q c / (2V)); nothing in trim. Strength k_fq [-].
    """

    name = "fuselage_pitch_damping"
    strength = "k_fq"

    def parameters(self):
        return [ParameterSpec("k_fq", 0.0, "-", "held-out truth: fuselage pitch-damping coefficient", "held out")]

    def extra_forces(self, ctx):
        p, x = ctx.p, ctx.x
        V = ctx.ops.sqrt(x["u"] ** 2 + x["w"] ** 2 + p["eps_v"] ** 2)
        return 0.0, 0.0, -p["k_fq"] * 0.25 * p["rho"] * V * 12.0 * 4.0**2 * x["q"]


class CyclicGearing(Extension):
    """H11: a gearing (scale) error in the longitudinal cyclic's control path.

        theta_1s = (1 + k_cg) lon     [rad]

    The rigging check found the zero but not the gain: the swashplate tilts k_cg more than the
    recorded stick says, in trim (lon's own curve over speed) and in every cyclic input.
    Strength k_cg [-] (relative gearing error).
    """

    name = "cyclic_gearing"
    strength = "k_cg"

    def parameters(self):
        return [ParameterSpec("k_cg", 0.0, "-", "held-out truth: relative error of the longitudinal cyclic gearing",
                              "held out")]

    def adjust_controls(self, ctx):
        ctx.lon = (1.0 + ctx.p["k_cg"]) * ctx.lon


class StaticPortError(Extension):
    """H12: a static-source position error that follows the angle of attack.

        TAS_meas = TAS + k_sp V sin(alpha) = TAS + k_sp w     [m/s]

    The static pressure the air-data system reads changes with the flow angle at the port,
    dp_s = -c_p,alpha alpha q_dyn, so the airspeed it computes is off by about (c_p,alpha / 2) V alpha.
    Nothing in the forces; it grows with the heave velocity of level flight at high speed (nose down)
    and follows w in every manoeuvre. Strength k_sp = c_p,alpha / 2 [-].
    """

    name = "static_port_error"
    strength = "k_sp"

    def parameters(self):
        return [ParameterSpec("k_sp", 0.0, "-", "held-out truth: airspeed error per unit heave velocity",
                              "held out")]

    def adjust_outputs(self, ctx):
        ctx.outputs["TAS"] = ctx.outputs["TAS"] + ctx.p["k_sp"] * ctx.x["w"]


class RotorSpeedDroop(Extension):
    """H13: a proportional engine governor: the rotor speed droops as collective (power demand) rises.

        tau_g d(delta)/dt = -k_rd (col - col_rd) - delta,    delta = dOmega / Omega [-]
        dX, dZ, dM = (2 delta + delta^2) (X_R, Z_R, M_R)     [N, N, N m]

    The rotor's forces and hub moment scale with Omega^2 at fixed coefficients (the change of the
    advance ratio and inflow ratio with Omega is left out). In trim delta = -k_rd (col - col_rd): less
    thrust where the collective is above col_rd = 0.12 rad (near the power bucket's), i.e. at hover and
    high speed; after a collective input the speed settles with tau_g = 0.8 s (rotor inertia and
    governor). Strength k_rd [-/rad].
    """

    name = "rotor_speed_droop"
    strength = "k_rd"
    states = ("rpm_droop",)

    def parameters(self):
        return [ParameterSpec("k_rd", 0.0, "1/rad", "held-out truth: governor droop per radian of collective",
                              "held out"),
                ParameterSpec("tau_g", 0.8, "s", "held-out truth: rotor-speed time constant", "held out"),
                ParameterSpec("col_rd", 0.12, "rad", "held-out truth: collective of nominal rotor speed",
                              "held out")]

    def extra_forces(self, ctx):
        X_R, Z_R, M_R = rotor.rotor_forces(ctx.thrust, ctx.beta_1c_tpp, ctx.p, ctx.ops, x_h=ctx.x_h)
        d = ctx.x["rpm_droop"]
        f = 2.0 * d + d**2
        return f * X_R, f * Z_R, f * M_R

    def state_equations(self, ctx):
        p = ctx.p
        return {"rpm_droop": (p["tau_g"], -p["k_rd"] * (ctx.col - p["col_rd"]) - ctx.x["rpm_droop"])}


class SkewedInflowGradient(Extension):
    """H14: a longitudinal gradient of the induced inflow over the disc, from the skewed wake (Coleman).

        lambda(r, psi) = lambda_i (1 + kappa_x (r/R) cos psi)     (psi from the tail: more inflow at the rear)
        kappa_x = k_ig tan(chi/2) = k_ig mu / (sqrt(mu^2 + lam^2) + lam)     [-]
    chi is the wake skew angle from the hub-plane flow, tan chi = mu / lam (lam = lambda_i - mu_z, M0's net
    inflow). The gradient's first harmonic adds -gamma kappa_x lambda_i / 8 to the cosine row of M0's flap
    equation (rotor.flapping_system), which changes the tip-path plane's forward tilt by
        d(beta_1c) = -(gamma/8) kappa_x lambda_i (lambda_b^2 - 1) / D     [rad]   (aft)
        D = (lambda_b^2 - 1)^2 + gamma^2 (1/64 - mu^4/256)
    (gamma the Lock number, lambda_b^2 the flap frequency^2 of rotor.rotor_constants; the larger lateral
    flapping lies outside the longitudinal model, coning and thrust do not change). Rotor forces, hub moment
    and the disc-frame inflow use the tilted plane. Nothing in hover (no skew); through transition kappa_x
    lambda_i peaks near 30 kt, and it keeps about 40 % of that at 120 kt: lon moves forward to hold the disc.
    Strength k_ig [-] (share of Coleman's tan(chi/2); Pitt-Peters' form has 15 pi / 32 = 1.47 of it).
    At k_ig = 0.3 the level trims record lon 0.14 deg further forward at 30 kt (nearly 3 trim sigmas of
    0.05 deg) and 0.06 deg at 120 kt, col at most 0.02 deg higher, theta unchanged (the disc moves, not the
    attitude); the speed gained in the hover lon doublets skews the wake and moves their theta by up to 1 deg.
    """

    name = "skewed_inflow_gradient"
    strength = "k_ig"

    def parameters(self):
        return [ParameterSpec("k_ig", 0.0, "-", "held-out truth: share of Coleman's longitudinal inflow gradient",
                              "held out")]

    def tip_path_plane(self, ctx):
        p, ops = ctx.p, ctx.ops
        lock, _, lb2 = rotor.rotor_constants(p)
        mu, lam = ctx.flow.mu, ctx.lam
        kappa_x = p["k_ig"] * mu / (ops.sqrt(mu**2 + lam**2) + lam)
        det = (lb2 - 1) ** 2 + lock**2 * (1 / 64 - mu**4 / 256)
        ctx.beta_1c_tpp = ctx.beta_1c_tpp - (lock / 8) * kappa_x * ctx.x["lambda_i"] * (lb2 - 1) / det


class CyclicFreePlay(Extension):
    """H15: free play in the longitudinal cyclic linkage, taken up towards zero cyclic: a smooth dead band.

        theta_1s = lon - b_fp lon / sqrt(lon^2 + s_fp^2)     [rad],  s_fp = 0.3 deg

    The blades' propeller moment loads the pitch links towards zero pitch, so the play of half-width b_fp
    (swashplate and rod-end clearances) is always taken up on the side of zero cyclic: without hysteresis,
    the rotor sees lon - b_fp sign(lon) for |lon| >> s_fp, and around lon = 0 (the hover trim) the gearing
    drops to 1 - b_fp / s_fp (s_fp: how gradually the centring load takes the play up; b_fp <= s_fp).
    Strength b_fp [rad]. At b_fp = 0.1 deg every level trim from 20 kt up records lon 0.094-0.100 deg further
    forward (2 trim sigmas of 0.05 deg; the hover trim, at lon = 0, only 0.007 deg), and the hover lon
    doublets (0.5 deg) reach the rotor 17 % smaller, which moves their theta by up to 0.9 deg.
    """

    name = "cyclic_free_play"
    strength = "b_fp"

    def parameters(self):
        return [ParameterSpec("b_fp", 0.0, "rad", "held-out truth: half-width of the lon linkage free play",
                              "held out"),
                ParameterSpec("s_fp", 0.3 * math.pi / 180, "rad", "held-out truth: smoothing width of the "
                              "free play's take-up", "held out")]

    def adjust_controls(self, ctx):
        p, lon = ctx.p, ctx.lon
        ctx.lon = lon - p["b_fp"] * lon / ctx.ops.sqrt(lon**2 + p["s_fp"] ** 2)


class RotorPylonMode(Extension):
    """H16: the hub moment reaches the airframe through a compliant mast and transmission mount (a pylon mode).

        tau_p^2 y'' + 2 zeta_p tau_p y' + y = beta_1c      [rad],  zeta_p = 0.25
    as two states, tau_p d(y)/dt = v and tau_p d(v)/dt = beta_1c - y - 2 zeta_p v (v [rad]), and
        dM = (N_b/2) K_beta (beta_1c - y)     [N m]
    so the airframe feels the hub-spring moment -(N_b/2) K_beta y: M0's -(N_b/2) K_beta beta_1c (beta_1c the
    tip-path-plane tilt the rotor forces use) through a second-order mode of natural frequency 1/tau_p, the
    rotor and gearbox pitching on the mount; the thrust's line of action is left as it is. Nothing in
    trim (y = beta_1c, v = 0); every cyclic input and pitch rate rings the mode. Strength tau_p [s].
    At tau_p = 0.05 s (20 rad/s, 3.2 Hz) the noise-free q of the lon doublets (0.5 deg, hover to 80 kt) and of
    the 80 kt col doublet moves by up to 1.5 deg/s at their steps (7 sigmas of 0.2 deg/s, about 1 sigma RMS
    over the record), as the actuator lag H5 does at its strength.
    """

    name = "rotor_pylon_mode"
    strength = "tau_p"
    states = ("pylon_tilt", "pylon_rate")

    def parameters(self):
        return [ParameterSpec("tau_p", 0.0, "s", "held-out truth: 1 / natural frequency of the pylon mode",
                              "held out"),
                ParameterSpec("zeta_p", 0.25, "-", "held-out truth: damping ratio of the pylon mode", "held out")]

    def extra_forces(self, ctx):
        p = ctx.p
        return 0.0, 0.0, (p["Nb"] / 2) * p["K_beta"] * (ctx.beta_1c_tpp - ctx.x["pylon_tilt"])

    def state_equations(self, ctx):
        p, x = ctx.p, ctx.x
        return {"pylon_tilt": (p["tau_p"], x["pylon_rate"]),
                "pylon_rate": (p["tau_p"], ctx.beta_1c_tpp - x["pylon_tilt"] - 2 * p["zeta_p"] * x["pylon_rate"])}


class AdvancingBladeCompressibility(Extension):
    """H17: the blade's lift-curve slope rises with the section Mach number: more on the advancing side.

        a(psi) = a (1 + k_ma mu sin psi)     (a: M0's lift-curve slope, its hover value)
    (psi from the tail, 90 deg on the advancing side). Multiplying M0's blade-element flap moment by it, the
    mean aerodynamic flap moment
        F_0 = gamma (theta_0 (1 + mu^2)/8 + theta_tw (1/10 + mu^2/12) + mu theta_1s/6 - lam/6)     [-]
    (M0's coning row without its spring term) reappears in the sine row of M0's flap equation
    (rotor.flapping_system): d(b_1s) = k_ma mu F_0, the advancing side's extra lift, which tilts the tip-path
    plane aft:
        d(beta_1c) = -gamma (1/8 + mu^2/16) k_ma mu F_0 / D     [rad]
        D = (lambda_b^2 - 1)^2 + gamma^2 (1/64 - mu^4/256)
    (gamma the Lock number, lambda_b^2 the flap frequency^2 of rotor.rotor_constants; products with the 1/rev
    moments go to coning and 2/rev and are left out, as is the lateral flapping; coning and thrust do not
    change). Rotor forces, hub moment and the disc-frame inflow use the tilted plane. Nothing in hover; it grows
    with speed and with the blade loading, so a collective input at speed also tilts the disc aft.
    Strength k_ma [-] (relative rise of the lift-curve slope per unit of mu sin psi). Prandtl-Glauert,
    a ~ 1 / sqrt(1 - M^2), at 0.75 R of the Bo-105 (tip Mach number 0.64) gives
    d(ln a)/d(mu sin psi) = 0.75 M_tip^2 / (1 - (0.75 M_tip)^2) = 0.40 (Leishman, Principles of Helicopter
    Aerodynamics, 2nd ed. 2006, rotor airfoil aerodynamics; Johnson, Rotorcraft Aeromechanics, 2013, section
    aerodynamics): the section's lift-curve slope in the rotating, three-dimensional flow rises less, about half
    of it.
    At k_ma = 0.2 the level trims record lon further forward by 0.04 deg at 20 kt, 0.15 deg at 80 kt and
    0.24 deg at 120 kt (nearly 5 trim sigmas of 0.05 deg), col at most 0.09 deg higher, theta unchanged (the disc
    moves, not the attitude), nothing in hover; in the noise-free 80 and 100 kt records (lon and col 3211s and
    doublets) q moves by up to 0.7 deg/s at the steps (3.5 sigmas of 0.2 deg/s), n_z by up to 0.05 g (5 sigmas)
    and theta by up to 1.2 deg over the 15 s records (the speed stability changes); the hover and 20 kt records
    by little (theta up to 0.25 deg).
    """

    name = "advancing_blade_compressibility"
    strength = "k_ma"

    def parameters(self):
        return [ParameterSpec("k_ma", 0.0, "-", "held-out truth: rise of the lift-curve slope per unit mu sin psi",
                              "held out")]

    def tip_path_plane(self, ctx):
        p, pitch, mu, lam = ctx.p, ctx.pitch, ctx.flow.mu, ctx.lam
        lock, _, lb2 = rotor.rotor_constants(p)
        F0 = lock * (pitch.theta_0 * (1 + mu**2) / 8 + pitch.theta_tw * (1 / 10 + mu**2 / 12)
                     + mu * pitch.theta_1s / 6 - lam / 6)
        det = (lb2 - 1) ** 2 + lock**2 * (1 / 64 - mu**4 / 256)
        ctx.beta_1c_tpp = ctx.beta_1c_tpp - lock * (1 / 8 + mu**2 / 16) * p["k_ma"] * mu * F0 / det


class FuselageWakeIncidence(Extension):
    """H18: the fuselage sits in the main rotor's downwash: its drag and Munk moment see a deflected flow.

        v_d = k_fw lambda_i Omega R                    [m/s]  (downwash at the fuselage, down)
        (dX, dZ, dM) = F(u, w - v_d) - F(u, w)          [N, N, N m]
    with F M0's fuselage forces (fuselage.fuselage_forces: X_F = -0.5 rho f_e V u, Z_F = -0.5 rho f_e V w,
    M_F = rho K_f Vol_f u w, V = sqrt(u^2 + w^2 + eps_v^2)): the air reaching the fuselage moves down by v_d,
    so its incidence drops, and mostly the destabilising Munk moment changes, by -rho K_f Vol_f u v_d
    (nose-down). Nothing in hover but a small download (u = 0), it builds up through transition and keeps
    about -K_f Vol_f k_fw T / (2 pi R^2) at high speed (u v_i tends to T / (2 rho pi R^2)); in manoeuvres it
    follows the inflow, so a collective input pitches the nose down in proportion to the speed.
    (Padfield, Helicopter Flight Dynamics, 2nd ed. 2007, ch. 3: the fuselage's incidence in the rotor wake;
    Prouty, Helicopter Performance, Stability, and Control, 1986: fuselage aerodynamics in the downwash.)
    Strength k_fw [-] (share of the rotor's induced velocity at the fuselage; about 1 under the disc, 2 in the
    fully developed wake).
    At k_fw = 1 the level trims record lon 0.08 deg further aft at 10 kt, 0.14 deg at 20 kt and 0.15-0.17 deg
    from 30 kt up (over 3 trim sigmas of 0.05 deg), theta 0.11-0.16 deg lower from 10 kt up (1.5 trim sigmas of
    0.1 deg), col at most 0.02 deg higher; the hover trim moves by less than 0.02 deg. In the noise-free records
    the speed gained in the hover lon doublets meets the Munk moment's new speed dependence: their theta moves by
    up to 1 deg (10 sigmas of 0.1 deg), q by up to 0.4 deg/s (2 sigmas), n_x by up to 0.8 sigma from 20 kt up.
    """

    name = "fuselage_wake_incidence"
    strength = "k_fw"

    def parameters(self):
        return [ParameterSpec("k_fw", 0.0, "-", "held-out truth: share of the induced velocity at the fuselage",
                              "held out")]

    def extra_forces(self, ctx):
        p, ops, x = ctx.p, ctx.ops, ctx.x
        v_d = p["k_fw"] * x["lambda_i"] * ctx.flow.v_tip
        X1, Z1, M1 = fuselage.fuselage_forces(x["u"], x["w"] - v_d, p, ops)
        X0, Z0, M0 = fuselage.fuselage_forces(x["u"], x["w"], p, ops)
        return X1 - X0, Z1 - Z0, M1 - M0


class PitchRateDamper(Extension):
    """H19: a limited-authority pitch-rate damper (SAS) with washout whose series actuator is not recorded.

        tau_w d(q_w)/dt = q - q_w                        [rad/s],  tau_w = 2 s
        theta_1s = lon - K_q (q - q_w)                   [rad]
    The recorded lon is the pilot's stick; the SAS adds its own cyclic through a series actuator downstream,
    from the washed-out pitch rate (nose-up rate, forward cyclic). Nothing in trim (q = q_w = 0); every
    manoeuvre is damped through the rotor, at every speed, hover included, and the washout lets a held rate
    through after a few seconds. A common flight-test pitfall: identifying from the stick when the SAS acts
    downstream of it (Tischler and Remple, Aircraft and Rotorcraft System Identification, 2nd ed. 2012: the
    bare airframe is identified from the mixer or swashplate inputs, not the stick, when a SAS is engaged).
    Strength K_q [s] (rad of swashplate cyclic per rad/s of pitch rate).
    At K_q = 0.02 s (0.02 deg of cyclic per deg/s, 1.15 deg per rad/s) no trim moves; the noise-free q of every
    lon doublet and 3211 (0.5 deg, hover to 100 kt) moves by 1.1-1.3 deg/s at the steps (5.5-6.6 sigmas of
    0.2 deg/s; 1.3 deg/s in the first 3 s of the hover doublet), of the col inputs at speed by up to 1.2 deg/s, and
    theta by up to 1 deg over the records; nothing in the hover col doublets (no pitch rate).
    """

    name = "pitch_rate_damper"
    strength = "K_q"
    states = ("sas_washout",)

    def parameters(self):
        return [ParameterSpec("K_q", 0.0, "s", "held-out truth: pitch-rate damper gain (cyclic per pitch rate)",
                              "held out"),
                ParameterSpec("tau_w", 2.0, "s", "held-out truth: washout time constant of the rate damper",
                              "held out")]

    def adjust_controls(self, ctx):
        x = ctx.x
        ctx.lon = ctx.lon - ctx.p["K_q"] * (x["q"] - x["sas_washout"])

    def state_equations(self, ctx):
        x = ctx.x
        return {"sas_washout": (ctx.p["tau_w"], x["q"] - x["sas_washout"])}


HELD_OUT_EFFECTS = {c.name: c for c in (FuselageDownload, DragRise, CantedTailRotor, ControlMixing, ActuatorLag,
                                        AccelerometerFilter, VerticalDrag, PitotDownwash, TailStall,
                                        FuselagePitchDamping, CyclicGearing, StaticPortError, RotorSpeedDroop,
                                        SkewedInflowGradient, CyclicFreePlay, RotorPylonMode,
                                        AdvancingBladeCompressibility, FuselageWakeIncidence, PitchRateDamper)}

#: nominal strengths of the held-out studies (studies/held_out_effects.py)
HELD_OUT_STRENGTHS = {
    "fuselage_download": {"k_fd": 0.03},
    "drag_rise": {"k_dr": 0.15},
    "canted_tail_rotor": {"k_tr": 0.1},
    "control_mixing": {"k_mx": 0.05},
    "actuator_lag": {"tau_a": 0.06},
    "accelerometer_filter": {"tau_nz": 0.08},
    "vertical_drag": {"k_vd": 1.0},
    "pitot_downwash": {"k_pd": 0.2},
    "tail_stall": {"k_ts": 0.2},
    "fuselage_pitch_damping": {"k_fq": 1.0},
    "cyclic_gearing": {"k_cg": 0.05},
    "static_port_error": {"k_sp": 0.2},
    "rotor_speed_droop": {"k_rd": 0.3},
    "skewed_inflow_gradient": {"k_ig": 0.3},
    "cyclic_free_play": {"b_fp": 0.1 * math.pi / 180},
    "rotor_pylon_mode": {"tau_p": 0.05},
    "advancing_blade_compressibility": {"k_ma": 0.2},
    "fuselage_wake_incidence": {"k_fw": 1.0},
    "pitch_rate_damper": {"K_q": 0.02},
}
