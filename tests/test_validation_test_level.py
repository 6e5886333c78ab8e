"""The validation rule's level study (pyomo_heli.studies.validation_test_level) on the small held-out flight test."""
import json
from pathlib import Path

import pytest

from pyomo_heli.studies.validation_test_level import main

ROOT = Path(__file__).resolve().parent.parent


def test_level_study_writes_each_seed_and_its_two_directions_are_complementary(tmp_path):
    """One seed of M0 + noise with the small test's single validation doublet (cut into six batches). The two
    directions of one pair are the same z with opposite signs: their one-sided p-values add up to 1 (Student's t
    is symmetric). A rerun reads the seed back instead of computing it, and computes a damaged one again."""
    argv = ["--seeds", "7", "--config", str(ROOT / "studies" / "held_out_small.toml"),
            "--data-config", str(ROOT / "studies" / "held_out_small_gen.toml"), "--out", str(tmp_path)]
    assert main(argv) == 0
    doc = json.loads((tmp_path / "seed_7.json").read_text())
    assert doc["records"] == 1 and len(doc["p"]) == 2 * 6
    for a, b in doc["p"].values():
        assert 0.0 <= a <= 1.0 and a + b == pytest.approx(1.0, abs=1e-9)
    # the joint test: each direction in units of its own model 0's mean squares, so not complementary
    assert set(doc["joint"]) == {"whole records", "1 s"}
    assert all(0.0 <= p <= 1.0 for v in doc["joint"].values() for p in v)
    summary = (tmp_path / "summary.csv").read_text().splitlines()  # per batch choice: 6 outputs, all, joint
    assert summary[0].startswith("batches,output,tests") and len(summary) == 1 + 2 * 8
    (tmp_path / "seed_7.json").write_text(json.dumps({**doc, "records": 99}))
    assert main(argv) == 0 and "(99 validation records each)" in (tmp_path / "summary.md").read_text()
    (tmp_path / "seed_7.json").write_text('{"seed": 7, "rec')
    assert main(argv) == 0 and json.loads((tmp_path / "seed_7.json").read_text()) == doc
