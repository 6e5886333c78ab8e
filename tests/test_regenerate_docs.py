"""The docs/results regeneration list (pyomo_heli.studies.regenerate, run by studies/regenerate_docs.py).

Nothing is regenerated here: the default suite checks the bookkeeping (inputs before the entries that read
them, pruning to the committed files, the command mapping); the slow check parses every listed
``pyomo-heli`` command with the CLI's own parser and finds every config and script it names.
"""
from __future__ import annotations

import json
import shutil
import sys

import pytest

from pyomo_heli.studies import regenerate as R
from pyomo_heli.studies.compare_results import compare_folder


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


def test_held_out_tables_end_reanalysed_and_rescored_with_their_runs_flags():
    """Every held-out table is made as the committed ones were: its runs, then the residual analysis made again on
    the kept models (``--reanalyse``, with the runs' config, data config and family) and the re-scoring (with the
    same flags)."""
    import shlex

    def flags(command):  # the options that choose the config the loop (and so its analysis) was run with
        args = shlex.split(command)
        return {a: args[i + 1] for i, a in enumerate(args) if a in ("--config", "--data-config", "--generic-family")}

    tables = [e for e in R.ENTRIES if e.commands[0].startswith(R.HELD_OUT)
              and not any(x in e.commands[0] for x in ("--reanalyse", "--summary"))]
    assert {e.folder for e in tables} == set(R.HELD_OUT_TABLES) | {"held_out_control", "record_inputs/projected",
                                                                   "record_inputs/record"}
    for e in tables:
        *runs, again, score = e.commands
        score_args = shlex.split(score)
        assert score_args[:3] == ["python", "studies/held_out_effects.py", "--rescore"] and score_args[-2:] == [
            "--out", f"{{out}}/{e.folder}"], e.folder
        assert flags(score) == flags(again), e.folder  # the data config decides the records a signature is judged on
        args = shlex.split(again)
        assert args[2:4] == ["--reanalyse", f"{{out}}/{e.folder}/scratch"] and args[-2:] == ["--out",
                                                                                              f"{{out}}/{e.folder}"]
        studies = [c for c in runs if "--bundled" not in c]
        assert studies and all(f"--out {{out}}/{e.folder}" in c for c in runs), e.folder
        assert all(flags(c) == flags(again) for c in studies), e.folder


def test_unknown_folder_is_one_line_exit_2(capsys):
    with pytest.raises(SystemExit) as exc:
        R.main(["--run", "case9"])
    assert exc.value.code == 2 and "--run: unknown folder 'case9'" in capsys.readouterr().err


@pytest.mark.slow
def test_every_listed_command_parses_and_its_files_exist(capsys):
    """A regeneration check of the checkout: reads studies/ (configs, scripts); runs nothing."""
    assert R.main(["--check"]) == 0, capsys.readouterr().err


def _folder(root, chosen_J, wall_time, n_x, table_cell, status="Solve_Succeeded"):
    """A tiny results folder: a JSON, a CSV and a Markdown table, plus a figure (never compared)."""
    root.mkdir()
    (root / "chosen.json").write_text(json.dumps({
        "chosen": {"J_time": chosen_J, "status": status, "wall_time": wall_time, "iterations": 5,
                   "parameters": {"theta_twist": -3.9e-08, "CL_alpha_HT": 6.284}},
        "dataset": str(root)}))
    (root / "front.csv").write_text(f"index,J_time,n_x,wall_time\n0,-54368.2,{n_x},{wall_time}\n")
    (root / "report.md").write_text(f"- total time {wall_time} s\n\n| point | J_trim | wall time [s] |\n|---|---|---|\n"
                                    f"| C | {table_cell} | {wall_time} |\n")
    (root / "front.png").write_bytes(b"\x89PNG" + bytes([int(wall_time) % 256]))


KEEP = ("chosen.json", "front.csv", "report.md", "front.png")


def test_compare_passes_within_1e6_and_skips_timings(tmp_path):
    ref, new = tmp_path / "ref", tmp_path / "new"
    _folder(ref, -54271.0, 16.2, 0.005, "0.2008")
    # J_time 3e-7 relative off; theta_twist (at its bound, ~0) 2e-10 off: under the 1e-9 floor; the table's
    # 0.2009 is one unit of its last printed digit from 0.2008 (a value on the rounding edge); timings, the
    # dataset path and the figure differ freely
    _folder(new, -54271.0 * (1 + 3e-7), 99.9, 0.005, "0.2009")
    doc = json.loads((new / "chosen.json").read_text())
    doc["chosen"]["parameters"]["theta_twist"] = -3.92e-08
    doc["chosen"]["unreliable"] = None  # a field newer code writes: listed, not compared
    (new / "chosen.json").write_text(json.dumps(doc))
    c = compare_folder(ref, new, KEEP)
    assert c.ok, c.mismatches
    assert c.added == ["chosen.json.chosen.unreliable"]
    assert c.files == 3
    # json: J_time, iterations, theta_twist, CL_alpha_HT; csv: index, J_time, n_x; md: 0.2008 (+ none in header)
    assert c.numbers == 8
    assert c.worst == pytest.approx(3e-7, rel=1e-6) and c.where == "chosen.json.chosen.J_time"


def test_compare_fails_on_a_difference_over_1e6_and_exits_1(tmp_path, capsys):
    ref, new = tmp_path / "docs_results" / "case2", tmp_path / "out" / "case2"
    ref.parent.mkdir()
    new.parent.mkdir()
    _folder(ref, -54271.0, 16.2, 0.005, "0.2008")
    _folder(new, -54271.0, 16.2, 0.005 * (1 + 2e-6), "0.2008", status="Maximum_Iterations_Exceeded")
    c = compare_folder(ref, new, KEEP)
    assert not c.ok
    assert c.worst == pytest.approx(2e-6, rel=1e-6) and c.where == "front.csv row 1 n_x"
    assert len(c.mismatches) == 2 and "Maximum_Iterations_Exceeded" in c.mismatches[0]
    # a printed number more than one unit of its last digit away
    (new / "report.md").write_text((ref / "report.md").read_text().replace("0.2008", "0.2010"))
    assert "report.md row 1 J_trim: 0.2008 -> 0.201" in compare_folder(ref, new, KEEP).mismatches[-1]
    (new / "report.md").unlink()
    assert compare_folder(ref, new, KEEP).mismatches[-1] == "report.md: missing"
    code = R.main(["--compare", "case2", "--out", str(tmp_path / "out"), "--reference", str(tmp_path / "docs_results")])
    out = capsys.readouterr().out
    assert code == 1 and "| case2 | 2 | 7 | 2.00e-06 | front.csv row 1 n_x | FAIL (3) |" in out
    # a reference root that does not exist is bad input (one line, exit 2), not a folder that "differs"
    with pytest.raises(SystemExit) as exc:
        R.main(["--compare", "case2", "--out", str(tmp_path / "out"), "--reference", str(tmp_path / "nope")])
    assert exc.value.code == 2 and f"--reference {tmp_path / 'nope'}: no such folder" in capsys.readouterr().err


def test_a_benchmark_rerun_is_compared_on_its_iterations_and_estimates_not_its_timings(tmp_path):
    """docs/results/scaling (benchmark JSON): another machine's timings, load and command line pass; one more Ipopt
    iteration or another estimate fails."""
    ref = R.ROOT / "docs" / "results" / "scaling"
    new = tmp_path / "scaling"
    shutil.copytree(ref, new)
    f = new / "scaling_case1.json"
    doc = json.loads(f.read_text())
    doc["sizes"][0]["a_solve_time"] *= 1.5
    doc["sizes"][0]["setup_breakdown"]["nl_write"] *= 2
    doc["command"] = doc["command"].replace("--out ", "--out /elsewhere/")
    doc["ratios"]["scaled_front_time_ratio"] *= 2
    doc["machine"]["load_average_start"] = [9.0, 9.0, 9.0]
    f.write_text(json.dumps(doc))
    c = compare_folder(ref, new, R.BY_NAME["scaling"].keep)
    assert c.ok and c.numbers > 100, c.mismatches
    doc["ratios"]["scaled_front_iterations_ratio"] *= 1 + 1e-3
    f.write_text(json.dumps(doc))
    c = compare_folder(ref, new, R.BY_NAME["scaling"].keep)
    assert c.mismatches == ["scaling_case1.json.ratios.scaled_front_iterations_ratio: "
                            + c.mismatches[0].split(": ", 1)[1]] and not c.ok


# appends one "x" to OUT/<folder>/runs.txt, then exits with the status given after the folder
COUNT = ('python -c "import pathlib, sys; f = pathlib.Path(sys.argv[1]) / \'runs.txt\'; '
         'f.parent.mkdir(parents=True, exist_ok=True); f.write_text((f.read_text() if f.exists() else \'\') + \'x\'); '
         'sys.exit(int(sys.argv[2]))" {out}/%s %d')


def test_resume_skips_finished_entries_and_keeps_the_interrupted_folder(tmp_path, capsys):
    out = str(tmp_path)
    a, b_fails = R.Entry("a", (COUNT % ("a", 0),), ("runs.txt",)), R.Entry("b", (COUNT % ("b", 3),), ("runs.txt",))
    with pytest.raises(SystemExit, match=r"\[b\] failed with exit status 3"):
        R.run([a, b_fails], out)
    assert json.loads((tmp_path / R.PROGRESS).read_text()) == {"a": list(a.commands)}
    b = R.Entry("b", (COUNT % ("b", 0),), ("runs.txt",))
    R.run([a, b], out, resume=True)
    assert (tmp_path / "a" / "runs.txt").read_text() == "x"  # finished before: not run again
    assert (tmp_path / "b" / "runs.txt").read_text() == "xx"  # run into its folder as the failed run left it
    assert not (tmp_path / R.PROGRESS).exists()  # a finished run leaves no progress file
    assert "[a] finished by the interrupted run: skipped (--resume)" in capsys.readouterr().out
    R.run([a, b], out, resume=True)  # nothing unfinished: everything runs, into the folders as they are
    assert (tmp_path / "a" / "runs.txt").read_text() == "xx"
    R.run([a, b], out)  # without --resume every folder is written afresh
    assert (tmp_path / "a" / "runs.txt").read_text() == (tmp_path / "b" / "runs.txt").read_text() == "x"


def test_resume_needs_run(capsys):
    with pytest.raises(SystemExit) as exc:
        R.main(["--resume"])
    assert exc.value.code == 2 and "--resume: give --run" in capsys.readouterr().err


def test_compare_reads_printed_output_without_timings_line_by_line(tmp_path):
    ref, new = tmp_path / "ref", tmp_path / "new"
    for d in (ref, new):
        d.mkdir()
    lines = "seed 0: none; p: cg_offset {}, lon_rigging 0.0321\nseed 1: {}\n"
    (ref / "m0.txt").write_text(lines.format("0.227", "none; p: cg_offset 0.81"))
    (ref / "timing.txt").write_text("A solve 8.7 s\n")
    (new / "timing.txt").write_text("A solve 9.9 s\n")  # not among `text`: never compared
    (new / "m0.txt").write_text(lines.format("0.228", "none; p: cg_offset 0.81"))
    c = compare_folder(ref, new, ("*.txt",), text=("m0.txt",))
    assert c.ok and c.files == 1 and c.numbers == 5  # 0.227 -> 0.228: one unit of the last printed digit
    (new / "m0.txt").write_text(lines.format("0.229", "lon_rigging; p: x"))
    assert compare_folder(ref, new, ("*.txt",), text=("m0.txt",)).mismatches == [
        "m0.txt line 1: 0.227 -> 0.229 (rel. 4.41e-03)",
        "m0.txt line 2: 'seed #: none; p: cg_offset #' -> 'seed #: lon_rigging; p: x'"]
    assert compare_folder(ref, new, ("*.txt",)).files == 0  # without `text` printed outputs are skipped


def test_compare_reads_a_path_under_the_regenerated_root_as_under_the_committed_one(tmp_path):
    ref, new = tmp_path / "ref", tmp_path / "new"
    for d, root in ((ref, "docs/results"), (new, "/tmp/r")):
        d.mkdir()
        (d / "seeds.csv").write_text(f"realisation,err %\n{root}/close_loop,1.5\n{root}x/loop,2\n")
    roots = ("docs/results", "/tmp/r")
    c = compare_folder(ref, new, ("seeds.csv",), roots=roots)
    # only a path under the root is mapped: "/tmp/rx/loop" is another folder
    assert c.mismatches == ["seeds.csv row 2 realisation: 'docs/resultsx/loop' -> '/tmp/rx/loop'"]
    assert len(compare_folder(ref, new, ("seeds.csv",)).mismatches) == 2  # without roots both differ


def test_printed_output_lands_in_the_entry_folder_under_the_checkout(tmp_path, monkeypatch):
    """A relative --out is under the checkout for every file, also a command's printed output, wherever the
    command is started from."""
    monkeypatch.setattr(R, "ROOT", tmp_path / "checkout")
    monkeypatch.chdir(tmp_path)
    R.run([R.Entry("p", ('python -c "print(42)"',), ("p.txt",), stdout={0: "p.txt"})], "r")
    assert (tmp_path / "checkout" / "r" / "p" / "p.txt").read_text() == "42\n" and not (tmp_path / "r").exists()


def test_a_root_with_digits_is_mapped_in_markdown_cells_too(tmp_path):
    ref, new = tmp_path / "ref", tmp_path / "new"
    for d, root in ((ref, "docs/results"), (new, "/tmp/r2")):
        d.mkdir()
        (d / "seeds.md").write_text(f"| realisation | err % |\n|---|---|\n| {root}/close_loop | 1.5 |\n")
    c = compare_folder(ref, new, ("seeds.md",), roots=("docs/results", "/tmp/r2"))
    assert c.ok and c.numbers == 1, c.mismatches
