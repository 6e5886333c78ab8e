"""The channel vocabulary: which quantities are inputs, recorded outputs and trim channels, and how
each is displayed. Defined here once; every module imports it (SI and radians inside, display units
only at the edges).
"""
from .units import DEG, KT

#: control inputs [rad]: collective and longitudinal cyclic pitch
INPUTS = ("col", "lon")
#: recorded time outputs of a maneuver (SI: rad/s, rad, g, g, m/s, rad)
OUTPUTS = ("q", "theta", "n_x", "n_z", "TAS", "beta_0")
#: channels of a trim point [rad]: collective, longitudinal cyclic, pitch attitude
TRIM_CHANNELS = ("col", "lon", "theta")

#: display unit and SI -> display factor of every plotted or tabled quantity
DISPLAY_UNITS = {
    "q": ("deg/s", 1 / DEG),
    "theta": ("deg", 1 / DEG),
    "n_x": ("g", 1.0),
    "n_z": ("g", 1.0),
    "TAS": ("kt", 1 / KT),
    "beta_0": ("deg", 1 / DEG),
    "col": ("deg", 1 / DEG),
    "lon": ("deg", 1 / DEG),
    "V": ("kt", 1 / KT),
}
#: the residual analysis's display units: as :data:`DISPLAY_UNITS`, but airspeed residuals in m/s
RESIDUAL_DISPLAY_UNITS = {k: DISPLAY_UNITS[k] for k in (*OUTPUTS, *INPUTS)} | {"TAS": ("m/s", 1.0)}
