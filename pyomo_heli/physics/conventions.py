"""The output side of a trim: the model's trim unknowns in the flight test's recorded conventions.

A flight test declares how its trim channels are recorded (manifest ``conventions``,
:class:`pyomo_heli.dataset.schema.TrimConventions`); the model's trim has its own:

- ``col`` is the blade pitch at the reference station ``r_ref`` (docs/model.md 3.2). With linear
  twist theta(r) = theta_0 + r theta_tw (theta_tw = theta_twist R [rad], r = radius / R), the pitch at
  the recorded station r_c is

      col_rec = col + (r_c - r_ref) theta_tw                       [rad]

  (r_c = 0: the root pitch theta_0 = col - r_ref theta_tw). This is the blade's geometry, not a
  fitted offset: a free twist moves it.
- ``lon`` is theta_1s, positive aft:  lon_rec = s_lon lon, s_lon = +1 or -1.
- ``theta`` is the body-axis pitch attitude; the recorded attitude refers to a fuselage datum at
  ``theta_datum`` to the body x axis:

      theta_rec = theta + theta_datum                              [rad]

  ``theta_datum`` is the model parameter of :class:`TrimOutputDatum`: fixed at the manifest's value
  when it is known, an identification parameter when the manifest says ``"estimate"``.

The functions do arithmetic only, so they serve floats and Pyomo expressions alike.
"""
from __future__ import annotations

from .extensions import Extension
from .parameters import DEG, ParameterSpec

#: the parameter carrying the pitch-attitude datum
THETA_DATUM = "theta_datum"


class TrimOutputDatum(Extension):
    """Pitch-attitude datum of the recorded attitude: theta_rec = theta + theta_datum (no effect on the physics)."""

    name = "trim_output_datum"
    strength = THETA_DATUM

    def parameters(self):
        return [ParameterSpec(THETA_DATUM, 0.0, "rad", "recorded pitch attitude minus body-axis attitude (datum)",
                              "flight-test manifest conventions", (-15 * DEG, 15 * DEG), 1 * DEG,
                              display=("deg", 1 / DEG))]


def recorded_trim(col, lon, theta, p, conventions) -> dict:
    """The model trim (col at r_ref, lon = theta_1s positive aft, body-axis theta; rad) as recorded.

    ``p``: the model's parameters (``theta_twist`` [rad/m], ``R`` [m], ``r_ref`` [-] and, when the model
    carries :class:`TrimOutputDatum`, ``theta_datum`` [rad]); ``conventions``: the flight test's
    :class:`~pyomo_heli.dataset.schema.TrimConventions`. Returns {"col", "lon", "theta"} [rad].
    """
    c = conventions
    if c.collective_station is not None:
        col = col + (c.collective_station - p["r_ref"]) * p["theta_twist"] * p["R"]
    if c.lon_sign != 1:
        lon = c.lon_sign * lon
    if THETA_DATUM in p:
        theta = theta + p[THETA_DATUM]
    elif c.theta_datum:
        theta = theta + c.theta_datum
    return {"col": col, "lon": lon, "theta": theta}


def model_trim(col, lon, theta, p, conventions) -> dict:
    """The inverse of :func:`recorded_trim`: recorded col, lon, theta [rad] taken to the model's (col at r_ref,
    lon = theta_1s positive aft, body-axis theta)."""
    c = conventions
    if c.collective_station is not None:
        col = col - (c.collective_station - p["r_ref"]) * p["theta_twist"] * p["R"]
    lon = c.lon_sign * lon  # lon_sign is +1 or -1: its own inverse
    if THETA_DATUM in p:
        theta = theta - p[THETA_DATUM]
    elif c.theta_datum:
        theta = theta - c.theta_datum
    return {"col": col, "lon": lon, "theta": theta}
