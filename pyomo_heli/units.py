"""Unit conversions used at the edges (command line, reports). SI and radians inside."""
import math

KT = 1852.0 / 3600.0  # m/s per knot
FT = 0.3048  # m per foot
DEG = math.pi / 180.0  # rad per degree


#: SI unit of a parameter -> (display unit, factor SI -> display): angles are shown in degrees at the edges
#: (configs, console, reports), as the parameter table's ``display`` entries say (tests/test_logging.py checks
#: that the two agree); every other unit is shown as it is
DISPLAY_UNITS = {"rad": ("deg", 1 / DEG), "rad/m": ("deg/m", 1 / DEG)}


def display_unit(si_unit: str) -> tuple[str, float]:
    """(display unit, factor SI -> display) of a parameter whose SI unit is ``si_unit``."""
    return DISPLAY_UNITS.get(si_unit, (si_unit, 1.0))


def kt_to_ms(v_kt: float) -> float:
    return v_kt * KT


def ms_to_kt(v: float) -> float:
    return v / KT


#: noise sigma keys of the config files (generator [sensors.sigma], identification [objectives.noise_sigma]):
#: key with its unit -> (channel, factor to SI)
SENSOR_SIGMA_KEYS = {"q_deg_s": ("q", DEG), "theta_deg": ("theta", DEG), "nx_g": ("n_x", 1.0), "nz_g": ("n_z", 1.0),
                     "tas_m_s": ("TAS", 1.0), "beta0_deg": ("beta_0", DEG), "col_deg": ("col", DEG),
                     "lon_deg": ("lon", DEG)}
