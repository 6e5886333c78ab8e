"""The example of docs/api.md (the same code): a small identification from a dict config, and a flight test
rebuilt from DataFrames. tests/test_api.py runs it in an empty folder."""
import pyomo_heli as ph
from pyomo_heli.resources import bundled_flight_test
from pyomo_heli.units import KT                           # m/s per knot

config = {
    "data": {"dataset": str(bundled_flight_test()),
             "maneuvers": ["lon3211_80kt_a", "coldoublet_hover"], "validation": [], "max_duration_s": 4.0},
    "parameters": {
        "theta_twist": {"unit": "deg/m", "initial": -2.1228, "lower": -10.0, "upper": 0.0},
        "CL_alpha_HT": {"unit": "1/rad", "initial": 4.3516, "lower": 0.1, "upper": 10.0, "scale": 5.0},
    },
    "pareto": {"points": 3},
}
cfg = ph.load_config(config)
res = ph.identify(cfg, out="api_example", uncertainty="chosen", progress=lambda line: None)
est = res.estimates()
print(est[["point", "parameter", "unit", "estimate", "standard_error"]].to_string(index=False))

same = ph.load_results("api_example").estimates()          # read back from the folder
assert same["estimate"].tolist() == est["estimate"].tolist()

ft = ph.load_flight_test(bundled_flight_test())             # SI, radians
names = ["lon3211_80kt_a", "coldoublet_hover"]
manifest = {"aircraft": ft.aircraft, "mass_kg": ft.mass,
            "atmosphere": {"rho_kg_m3": ft.rho, "g_m_s2": ft.g},
            "maneuvers": [{"name": n, "role": "identification", "trim_speed_kt": ft.maneuvers[n].trim_speed / KT,
                           "inputs": ft.maneuvers[n].inputs} for n in names]}
level = ft.trims[ft.trims["source"] == "level"]           # the others name maneuvers left out
mine = ph.FlightTest.from_frames(manifest, {n: ft.maneuvers[n].data for n in names}, level)
ph.write_flight_test("my_flight_test", mine)
print(ph.load_flight_test("my_flight_test").summary())
