"""``python studies/benchmark.py --tri-vs-bi``: the bi- and the tri-objective identification timed in one process.

The tiny configs (one record cut to 2 s) run both in about half a minute; the ratios are checked against the
times the run records, the fronts against the folders it writes.
"""
import json
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from pyomo_heli.workflows.tri_vs_bi import format_tri_vs_bi, run_tri_vs_bi

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = ROOT / "tests" / "configs"


def test_table_and_ratio_words():
    r = {"bi": {"config": "a/case1.toml", "cpu_s": 100.0, "wall_s": 200.0, "solves": 12, "grid_points": 9,
                "iterations": 80, "max_iterations_grid": 5, "failed": 0},
         "tri": {"config": "a/case1_tri.toml", "cpu_s": 250.0, "wall_s": 700.0, "solves": 28, "grid_points": 24,
                 "iterations": 300, "max_iterations_grid": 40, "failed": 2},
         "cpu_ratio": 2.5, "wall_ratio": 3.5, "limit": 3.0, "met": True}
    text = format_tri_vs_bi(r)
    assert "| tri | case1_tri.toml | 250.0 | 700.0 | 28 | 24 | 300 | 40 | 2 |" in text
    assert "tri / bi: CPU 2.50, wall 3.50 (target: CPU < 3: met)" in text


def test_out_must_be_a_folder_exits_2():
    proc = subprocess.run([sys.executable, "-m", "pyomo_heli.studies.benchmark", "--tri-vs-bi", "--out", "x.json"],
                          capture_output=True, text=True, cwd=ROOT)
    assert proc.returncode == 2 and "--tri-vs-bi writes a folder" in proc.stderr


@pytest.mark.slow
def test_tiny_tri_vs_bi_run(tmp_path):
    r = run_tri_vs_bi(CONFIGS / "tiny_case1_noisy.toml", CONFIGS / "tiny_case1_tri.toml", tmp_path,
                      progress=lambda *_: None)
    assert r["cpu_ratio"] == pytest.approx(r["tri"]["cpu_s"] / r["bi"]["cpu_s"])
    assert r["wall_ratio"] == pytest.approx(r["tri"]["wall_s"] / r["bi"]["wall_s"])
    assert json.loads((tmp_path / "tri_vs_bi.json").read_text())["cpu_ratio"] == pytest.approx(r["cpu_ratio"])
    for name, grid in (("bi", 2), ("tri", 24)):
        front = pd.read_csv(tmp_path / name / "front.csv")
        assert (front.kind == "eps").sum() == grid == r[name]["grid_points"]
        assert int(front.iterations.clip(lower=0).sum()) == r[name]["iterations"]
