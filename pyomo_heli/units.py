"""Unit conversions used at the edges (command line, reports). SI and radians inside."""
import math

KT = 1852.0 / 3600.0  # m/s per knot
FT = 0.3048  # m per foot
DEG = math.pi / 180.0  # rad per degree


def kt_to_ms(v_kt: float) -> float:
    return v_kt * KT


def ms_to_kt(v: float) -> float:
    return v / KT
