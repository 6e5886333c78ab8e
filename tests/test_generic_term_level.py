"""The generic-term level study (pyomo_heli.studies.generic_term_level): generic terms estimated alone in the NLP on
flight tests of M0 + noise, where every true strength is zero."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

ROOT = Path(__file__).resolve().parent.parent


def test_summary_gives_the_estimates_and_z_moments_over_the_seeds():
    """Mean and sd of c and z, the mean's t statistic and the |z| shares, computed by hand; a failed fit is left
    out of its term's row."""
    from pyomo_heli.studies.generic_term_level import per_seed, summary

    def doc(seed, c, z, ok=True):
        return {"seed": seed, "fits": {"col_scale": {"estimate": c, "z": z, "LR": z * z, "success": ok}}}
    docs = [doc(1, -0.01, -3.4), doc(2, 0.002, 0.5), doc(3, -0.004, -2.1), doc(4, 0.5, 9.0, ok=False)]
    row = summary(docs, ["col_scale"]).iloc[0]
    c = np.array([-0.01, 0.002, -0.004])
    assert row["seeds"] == 3
    assert row["mean c"] == pytest.approx(c.mean()) and row["sd c"] == pytest.approx(c.std(ddof=1))
    assert row["t of mean c"] == pytest.approx(c.mean() / (c.std(ddof=1) / math.sqrt(3)))
    assert row["mean z"] == pytest.approx(-5.0 / 3)
    assert row["z beyond +-2 [%]"] == pytest.approx(200 / 3) and row["z beyond +-3 [%]"] == pytest.approx(100 / 3)
    assert list(per_seed(docs, ["col_scale"])["col_scale z"]) == [-3.4, 0.5, -2.1, 9.0]


def test_level_study_writes_each_seed_and_resumes(tmp_path):
    """One seed of the small held-out flight test (three records), M0 + noise: both input scale factors estimated
    about their true zero (|c| well inside the family's +-0.2 bounds, |z| < 4), z = sign(c) sqrt(LR), the seed's data
    removed once done, and a rerun reads the seed back instead of solving again."""
    from pyomo_heli.studies.generic_term_level import main

    argv = ["--seeds", "7", "--config", str(ROOT / "studies" / "held_out_small.toml"),
            "--data-config", str(ROOT / "studies" / "held_out_small_gen.toml"), "--out", str(tmp_path)]
    assert main(argv) == 0
    doc = json.loads((tmp_path / "seed_7.json").read_text())
    for n in ("col_scale", "lon_scale"):
        f = doc["fits"][n]
        assert f["success"] and abs(f["estimate"]) < 0.05 and abs(f["z"]) < 4.0, (n, f)
        assert f["z"] == pytest.approx(math.copysign(math.sqrt(max(f["LR"], 0.0)), f["estimate"]))
    assert not (tmp_path / "data").exists()
    assert list(pd.read_csv(tmp_path / "summary.csv")["term"]) == ["col_scale", "lon_scale"]
    doc["fits"]["col_scale"]["estimate"] = 0.123  # a rerun reads the stored seed
    (tmp_path / "seed_7.json").write_text(json.dumps(doc))
    assert main(argv) == 0
    assert pd.read_csv(tmp_path / "summary.csv").set_index("term").loc["col_scale", "mean c"] == 0.123
