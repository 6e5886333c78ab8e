"""Issue 32, data and consistency: nothing overwritten unasked, results and config agree, implausible input named.

Every test runs on a tiny config or fixture and checks one guarantee of docs/robustness.md, section
"Data never overwritten, results and config agree".
"""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from pyomo_heli.cli import main

ROOT = Path(__file__).resolve().parent.parent
CONFIGS = ROOT / "tests" / "configs"

TINY_GEN = """\
[dataset]
name = "tiny"
aircraft = "Bo-105 (tiny test config)"
seed = {seed}

[truth]
parameters = {{}}

[sensors]
noise = true

[trims]
speeds_kt = [20, 60]

{maneuvers}
"""

MANEUVER = """\
[[maneuvers]]
name = "{name}"
role = "identification"
speed_kt = 80
channel = "lon"
shape = "doublet"
amplitude_deg = 0.5
step_s = 0.5
duration_s = 2
t_start_s = 0.5
"""


def _gen_config(tmp_path: Path, names, seed: int = 1, file: str = "gen.toml") -> Path:
    path = tmp_path / file
    path.write_text(TINY_GEN.format(seed=seed, maneuvers="\n".join(MANEUVER.format(name=n) for n in names)))
    return path


def _one_line(capsys, *fragments) -> str:
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err, err
    for f in fragments:
        assert f in err, (f, err)
    return err


def _tree(root: Path) -> dict:
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


# ============================================================== data never overwritten without being asked
def test_generate_data_refuses_an_existing_flight_test_and_force_leaves_no_orphans(tmp_path, capsys):
    out = tmp_path / "ft"
    old_cfg = _gen_config(tmp_path, ["a_80kt", "b_80kt"], file="old.toml")
    assert main(["generate-data", "--config", str(old_cfg), "--out", str(out)]) == 0
    before = _tree(out)
    assert {"manifest.json", "trims.csv", "truth.json", "maneuvers/a_80kt.csv", "maneuvers/b_80kt.csv"} <= set(before)
    capsys.readouterr()

    new_cfg = _gen_config(tmp_path, ["c_80kt"], seed=2, file="new.toml")
    assert main(["generate-data", "--config", str(new_cfg), "--out", str(out)]) == 2
    _one_line(capsys, str(out), "already holds a flight test", "--force")
    assert _tree(out) == before  # nothing touched

    assert main(["generate-data", "--config", str(new_cfg), "--out", str(out), "--force"]) == 0
    after = _tree(out)
    # exactly the new flight test: the old maneuver files are gone, not orphaned
    assert sorted(after) == ["maneuvers/c_80kt.csv", "manifest.json", "trims.csv", "truth.json"]
    fresh = tmp_path / "fresh"
    assert main(["generate-data", "--config", str(new_cfg), "--out", str(fresh)]) == 0
    assert after == _tree(fresh)  # and byte for byte what a new folder gets
    assert main(["check-data", str(out)]) == 0


def test_generate_data_refuses_a_folder_of_other_files_and_results(tmp_path, capsys):
    cfg = _gen_config(tmp_path, ["a_80kt"])
    other = tmp_path / "notes"
    other.mkdir()
    (other / "mine.txt").write_text("keep me\n")
    assert main(["generate-data", "--config", str(cfg), "--out", str(other)]) == 2
    _one_line(capsys, str(other), "mine.txt", "--force")
    assert sorted(_tree(other)) == ["mine.txt"]
    results = tmp_path / "results"
    results.mkdir()
    (results / "front.csv").write_text("index,kind\n")
    for extra in ([], ["--force"]):  # --force replaces data, never results
        assert main(["generate-data", "--config", str(cfg), "--out", str(results)] + extra) == 2
        _one_line(capsys, str(results), "front.csv")
    assert main(["generate-data", "--config", str(cfg), "--out", str(other), "--force"]) == 0
    assert (other / "mine.txt").read_text() == "keep me\n" and (other / "manifest.json").is_file()
