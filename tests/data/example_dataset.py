"""The pandas-only flight-test dataset example (docs/data_format.md, section 9): writes ./bo105_example."""
import json
from pathlib import Path

import numpy as np
import pandas as pd

folder = Path("bo105_example")
(folder / "maneuvers").mkdir(parents=True, exist_ok=True)

rate = 50.0                           # Hz; the spacing must be uniform within 1 %
t = np.arange(301) / rate             # 0 .. 6 s, 301 samples


def pulses(t, t0, widths, amplitude):
    """Alternating pulses +A, -A, +A, ... of the given widths [s], starting at t0."""
    u = np.zeros_like(t)
    start, sign = t0, 1.0
    for w in widths:
        u[(t >= start) & (t < start + w)] = sign * amplitude
        start, sign = start + w, -sign
    return u


# 1) 80 kt longitudinal 3-2-1-1, angles in degrees, airspeed in knots
lon_in = pulses(t, 1.0, [1.5, 1.0, 0.5, 0.5], 0.5)            # deg, increment on trim
pd.DataFrame({
    "t_s": t,
    "col_deg": np.full(t.size, 5.0),
    "lon_deg": 1.0 + lon_in,
    "q_deg_s": 6.0 * np.sin(2.0 * t) * (t > 1.0),
    "theta_deg": -2.0 + 3.0 * np.sin(1.0 * t) * (t > 1.0),
    "nx_g": np.full(t.size, -0.035),
    "nz_g": 1.0 + 0.1 * np.sin(2.0 * t) * (t > 1.0),
    "tas_kt": 80.0 - 2.0 * np.sin(0.5 * t) * (t > 1.0),
}).to_csv(folder / "maneuvers" / "lon3211_80kt.csv", index=False)

# 2) hover collective doublet, angles in radians, airspeed in m/s, with coning
col_in = pulses(t, 1.0, [1.0, 1.0], np.radians(1.0))          # rad
pd.DataFrame({
    "t_s": t,
    "col_rad": 0.15 + col_in,
    "lon_rad": np.full(t.size, 0.01),
    "q_rad_s": 0.02 * np.sin(3.0 * t),
    "theta_rad": 0.05 + 0.01 * np.sin(1.0 * t),
    "nx_g": np.full(t.size, 0.05),
    "nz_g": 1.0 + 0.3 * col_in / np.radians(1.0),
    "tas_m_s": 0.5 * np.cos(0.7 * t),    # pitot noise around hover may even go negative
    "beta0_rad": 0.045 + 0.8 * col_in,
}).to_csv(folder / "maneuvers" / "col_doublet_hover.csv", index=False)

# 3) 80 kt longitudinal doublet kept for validation
pd.DataFrame({
    "t_s": t,
    "col_deg": np.full(t.size, 5.0),
    "lon_deg": 1.0 + pulses(t, 1.0, [1.0, 1.0], 0.5),
    "q_deg_s": 4.0 * np.sin(2.0 * t) * (t > 1.0),
    "theta_deg": -2.0 + 2.0 * np.sin(1.0 * t) * (t > 1.0),
    "nx_g": np.full(t.size, -0.035),
    "nz_g": np.full(t.size, 1.0),
    "tas_kt": np.full(t.size, 80.0),
}).to_csv(folder / "maneuvers" / "lon_doublet_80kt.csv", index=False)

# averaged trim points: level-flight speed sweep plus the start trim of each maneuver
pd.DataFrame({
    "speed_kt": [0.0, 40.0, 80.0, 120.0, 80.0, 0.0, 80.0],
    "gamma_fp_deg": 0.0,
    "col_deg": [8.6, 6.0, 5.0, 7.5, 5.0, 8.6, 5.0],
    "lon_deg": [0.6, 0.4, 1.0, 2.0, 1.0, 0.6, 1.0],
    "theta_deg": [2.9, 0.5, -2.0, -5.0, -2.0, 2.9, -2.0],
    "source": ["level", "level", "level", "level", "lon3211_80kt", "col_doublet_hover", "lon_doublet_80kt"],
}).to_csv(folder / "trims.csv", index=False)

manifest = {
    "format": "pyomo_heli-flighttest",
    "format_version": 1,
    "aircraft": "Bo-105 (synthetic)",
    "description": "Small example dataset",
    "atmosphere": {"rho_kg_m3": 1.225, "g_m_s2": 9.80665},
    "mass_kg": 2200.0,
    "trim_file": "trims.csv",
    "maneuvers": [
        {"name": "lon3211_80kt", "file": "maneuvers/lon3211_80kt.csv", "role": "identification",
         "trim_speed_kt": 80.0, "inputs": ["lon"], "description": "lon 3-2-1-1, 0.5 deg"},
        {"name": "col_doublet_hover", "file": "maneuvers/col_doublet_hover.csv", "role": "identification",
         "trim_speed_kt": 0.0, "inputs": ["col"]},
        {"name": "lon_doublet_80kt", "file": "maneuvers/lon_doublet_80kt.csv", "role": "validation",
         "trim_speed_kt": 80.0, "inputs": ["lon"]},
    ],
}
(folder / "manifest.json").write_text(json.dumps(manifest, indent=2) + "\n")
