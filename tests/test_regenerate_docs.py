"""The docs/results regeneration list (pyomo_heli.studies.regenerate, run by studies/regenerate_docs.py).

Nothing is regenerated here: the default suite checks the bookkeeping (inputs before the entries that read
them, pruning to the committed files, the command mapping); the slow check parses every listed
``pyomo-heli`` command with the CLI's own parser and finds every config and script it names.
"""
from __future__ import annotations

import sys

import pytest

from pyomo_heli.studies import regenerate as R


def test_inputs_come_first_and_in_list_order():
    names = [e.folder for e in R.with_inputs(["envelope_validation"])]
    assert names == ["close_loop", "close_loop_eiv", "close_loop_seeds", "close_loop_seeds_eiv", "envelope_validation"]
    assert [e.folder for e in R.with_inputs(["case1_diagnosis", "case1"])] == ["case1", "case1_diagnosis"]
    order = [e.folder for e in R.ENTRIES]
    for e in R.ENTRIES:  # an entry's inputs are listed before it, so --run all needs no reordering
        assert all(order.index(n) < order.index(e.folder) for n in e.needs), e.folder
    assert len(set(order)) == len(order)


def test_prune_keeps_only_the_committed_files(tmp_path):
    for f in ("loop.json", "loop_report.md", "loop_validation.png", "iter_0/chosen.json", "iter_0/checkpoint.json",
              "data_1/trims.csv", "loop_1/iter_0/front.csv"):
        (tmp_path / f).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / f).write_text("x")
    removed = R.prune(tmp_path, R.LOOP_FILES)
    assert sorted(p.relative_to(tmp_path).as_posix() for p in removed) == [
        "data_1/trims.csv", "iter_0/checkpoint.json", "loop_1/iter_0/front.csv", "loop_validation.png"]
    assert sorted(p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*")) == [
        "iter_0", "iter_0/chosen.json", "loop.json", "loop_report.md"]


def test_commands_map_to_this_interpreter():
    assert R.argv_of("pyomo-heli identify a.toml --out {out}/x", "R") == [
        sys.executable, "-m", "pyomo_heli.cli", "identify", "a.toml", "--out", "R/x"]
    argv = R.argv_of("python studies/monte_carlo.py --out {out}/m", "R")
    assert argv[:2] == [sys.executable, "studies/monte_carlo.py"]
    with pytest.raises(ValueError, match="cannot run"):
        R.argv_of("make all", "R")


def test_unknown_folder_is_one_line_exit_2(capsys):
    with pytest.raises(SystemExit) as exc:
        R.main(["--run", "case9"])
    assert exc.value.code == 2 and "--run: unknown folder 'case9'" in capsys.readouterr().err


@pytest.mark.slow
def test_every_listed_command_parses_and_its_files_exist(capsys):
    """A regeneration check of the checkout: reads studies/ (configs, scripts); runs nothing."""
    assert R.main(["--check"]) == 0, capsys.readouterr().err
