"""Corrupt or foreign state on disk: a damaged stored point, a damaged checkpoint.json, a results folder of
another command, a --dataset that is not a flight test (docs/robustness.md; pyomo_heli.pareto.store).

Behaviour under test:

- an unreadable stored point (truncated, empty, not an .npz of the store) is treated as unfinished: a warning
  names it, it is kept as ``<key>.npz.corrupt`` and the point is solved again; the rerun resumes from every other
  finished point and ends with the numbers of an uninterrupted run;
- a checkpoint.json that is not a JSON object (or finished points without one): one line naming the file and
  --restart, exit status 2, nothing changed;
- identify / multistart / close-loop into another of these commands' --out folder: one line naming the folder and
  what it holds, exit status 2, nothing written (--restart or not);
- close-loop --dataset DIR without manifest.json: one line naming the option, --out not created.

One identification of the tiny Case 1 with 3 front points (about 2 s) serves every test; the rest is file work.
"""
import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pyomo_heli.cli import main
from pyomo_heli.pareto.store import PointStore, StoreMismatchError, claim_folder, folder_kind

HERE = Path(__file__).parent
ROOT = HERE.parent
TINY = HERE / "configs" / "tiny_case1_noisy.toml"
TIMING = ["wall_time", "setup_time", "cold_wall_time"]


@pytest.fixture(scope="module")
def config(tmp_path_factory) -> Path:
    """The tiny Case 1 with 3 front points, its dataset path absolute (the config may live anywhere)."""
    text = TINY.read_text().replace("points = 4", "points = 3").replace('"../../data/', f'"{ROOT / "data"}/')
    assert "points = 3" in text and str(ROOT / "data") in text
    path = tmp_path_factory.mktemp("cfg") / "tiny.toml"
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def reference(config, tmp_path_factory) -> Path:
    """An uninterrupted identify run (A, B, one interior point, the direct solve)."""
    out = tmp_path_factory.mktemp("ref") / "out"
    assert main(["identify", str(config), "--out", str(out), "--no-report", "--uncertainty", "none"]) == 0
    assert sorted(p.name for p in (out / "points").glob("*.npz")) == ["A.npz", "B.npz", "direct.npz", "eps001.npz"]
    return out


def _copy(reference, tmp_path, name="out") -> Path:
    out = tmp_path / name
    shutil.copytree(reference, out)
    return out


def _identify(config, out, *extra):
    return main(["identify", str(config), "--out", str(out), "--no-report", "--uncertainty", "none", *extra])


def _one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert "Traceback" not in err
    return lines[0]


def _tree(folder: Path) -> dict:
    return {str(p.relative_to(folder)): (p.read_bytes() if p.is_file() else None) for p in sorted(folder.rglob("*"))}


# ---------------------------------------------------------------- 1. a corrupt stored point
def test_corrupt_points_are_solved_again_and_the_results_are_those_of_an_uninterrupted_run(
        config, reference, tmp_path, capsys):
    out = _copy(reference, tmp_path)
    a = out / "points" / "A.npz"
    a.write_bytes(a.read_bytes()[:100])  # truncated (head -c 100): zipfile.BadZipFile before the fix
    (out / "points" / "eps001.npz").write_bytes(b"")  # empty: EOFError before the fix
    capsys.readouterr()
    assert _identify(config, out) == 0
    cap = capsys.readouterr()
    assert "Traceback" not in cap.err
    warnings = [line for line in cap.err.splitlines() if line.startswith("warning:")]
    assert len(warnings) == 2, cap.err
    assert str(out / "points" / "A.npz") in warnings[0] and "solving it again" in warnings[0]
    assert str(out / "points" / "eps001.npz") in warnings[1]
    # the damaged files are kept aside, the points are stored afresh, the others came from disk
    assert (out / "points" / "A.npz.corrupt").read_bytes() == (reference / "points" / "A.npz").read_bytes()[:100]
    assert (out / "points" / "eps001.npz.corrupt").read_bytes() == b""
    assert PointStore(out, json.loads((out / "checkpoint.json").read_text())["fingerprint"],
                      what="identification").keys() == ["A", "B", "direct", "eps001"]
    resumed = [line for line in cap.out.splitlines() if "(from disk)" in line]
    assert len(resumed) == 1 and " B " in resumed[0], cap.out  # A and eps001 solved again, B (and direct) loaded
    # same numbers as the uninterrupted run (the re-solved points start from the same values as before)
    drop = lambda f: pd.read_csv(f).drop(columns=TIMING, errors="ignore")  # noqa: E731
    pd.testing.assert_frame_equal(drop(out / "front.csv"), drop(reference / "front.csv"), check_exact=True)
    got, want = (json.loads((d / "chosen.json").read_text()) for d in (out, reference))
    for key in ("chosen", "direct"):
        assert {k: v for k, v in got[key].items() if k not in TIMING} == \
               {k: v for k, v in want[key].items() if k not in TIMING}
    assert got["utopia"] == want["utopia"] and got["nadir"] == want["nadir"]


@pytest.mark.parametrize("content", ["npy", "record_list", "no_record", "garbage"])
def test_store_treats_any_unreadable_point_as_unfinished(tmp_path, capsys, content):
    store = PointStore(tmp_path, "fp", what="identification")
    store.save("A", {"x": 1.0})
    path = store.dir / "A.npz"
    if content == "npy":
        np.save(open(path, "wb"), np.arange(3.0))
    elif content == "record_list":
        np.savez(open(path, "wb"), record=np.array("[1, 2]"))
    elif content == "no_record":
        np.savez(open(path, "wb"), values=np.arange(3.0))
    else:
        path.write_bytes(b"\x00not a zip at all" * 10)
    assert store.has("A") is False
    err = capsys.readouterr().err
    assert _one_line(err).startswith(f"warning: {path}: unreadable stored point")
    assert not path.exists() and (store.dir / "A.npz.corrupt").is_file()
    assert store.keys() == []  # the .corrupt file is not a finished point
    store.save("A", {"x": 2.0})
    assert store.has("A") and store.record("A") == {"x": 2.0}
    assert PointStore(tmp_path, "fp", what="identification").keys() == ["A"]  # resumes normally afterwards


# ---------------------------------------------------------------- 2. a damaged checkpoint.json
@pytest.mark.parametrize("content", [b"[]", b"{not json", b"", b"\xff\xfe\x00", b"42"])
def test_damaged_checkpoint_is_named_in_one_line(config, reference, tmp_path, capsys, content):
    out = _copy(reference, tmp_path)
    (out / "checkpoint.json").write_bytes(content)
    before = _tree(out)
    capsys.readouterr()
    assert _identify(config, out) == 2
    line = _one_line(capsys.readouterr().err)
    assert line.startswith("pyomo-heli identify: error: ")
    assert str(out / "checkpoint.json") in line and "--restart" in line
    assert _tree(out) == before  # nothing touched
    # --restart discards the points and rewrites the checkpoint (on the store: no second run needed)
    store = PointStore(out, "new", restart=True, what="identification")
    assert store.keys() == [] and json.loads((out / "checkpoint.json").read_text())["fingerprint"] == "new"


def test_points_without_checkpoint_are_refused(tmp_path):
    store = PointStore(tmp_path, "fp", what="identification")
    store.save("A", {"x": 1.0})
    (tmp_path / "checkpoint.json").unlink()
    with pytest.raises(StoreMismatchError, match="checkpoint.json is missing.*--restart"):
        PointStore(tmp_path, "fp", what="identification")
    assert PointStore(tmp_path, "fp", restart=True, what="identification").keys() == []


def test_points_solved_by_other_code_are_resumed_and_flagged(tmp_path):
    """The fingerprint covers config, data and settings; the code that solved the points is recorded beside it.
    Reopened by other code the store still resumes them (the same problem), flags ``other_code`` for the caller to
    say so, and remembers the folder as mixed; the same code resumes silently."""
    store = PointStore(tmp_path, "fp", what="identification", source="code-1")
    store.save("A", {"x": 1.0})
    assert not PointStore(tmp_path, "fp", what="identification", source="code-1").other_code
    again = PointStore(tmp_path, "fp", what="identification", source="code-2")
    assert again.other_code and again.keys() == ["A"]
    assert json.loads((tmp_path / "checkpoint.json").read_text())["source"] == "mixed"
    assert PointStore(tmp_path, "fp", what="identification", source="code-2").other_code  # stays mixed
    # stores written before the record: nothing known, nothing flagged
    legacy = tmp_path / "legacy"
    PointStore(legacy, "fp", what="identification").save("A", {"x": 1.0})
    assert not PointStore(legacy, "fp", what="identification", source="code-1").other_code


def test_damaged_checkpoint_of_a_close_loop_iteration_is_named(config, reference, tmp_path):
    from pyomo_heli.workflows.close_loop import _finished
    from pyomo_heli.config import load_identification_config

    folder = _copy(reference, tmp_path, "iter_0")
    (folder / "checkpoint.json").write_text("[]")
    with pytest.raises(StoreMismatchError, match=r"iter_0/checkpoint.json: expected a JSON object"):
        _finished(load_identification_config(config), folder)


# ---------------------------------------------------------------- 3. another command's results folder
def _loop_folder(tmp_path, marked=True) -> Path:
    """What close-loop leaves (without running it): loop.json, iter_0/ with an identification, its marker."""
    out = tmp_path / "loop"
    (out / "iter_0").mkdir(parents=True)
    (out / "loop.json").write_text(json.dumps({"iterations": [], "stopped": None}))
    if marked:
        (out / "checkpoint.json").write_text(json.dumps({"what": "close-loop"}))
    return out


@pytest.mark.parametrize("marked", [True, False], ids=["marked", "older_version"])
@pytest.mark.parametrize("restart", [False, True], ids=["resume", "restart"])
def test_identify_and_multistart_refuse_a_close_loop_folder(config, tmp_path, capsys, marked, restart):
    out = _loop_folder(tmp_path, marked)
    before = _tree(out)
    extra = ["--restart"] if restart else []
    for argv in (["identify", str(config), "--out", str(out), "--no-report", *extra],
                 ["multistart", str(config), "--out", str(out), "--starts", "2", *extra]):
        capsys.readouterr()
        assert main(argv) == 2
        line = _one_line(capsys.readouterr().err)
        assert line.startswith(f"pyomo-heli {argv[0]}: error: {out}: holds the results of `pyomo-heli close-loop`")
        assert "loop.json" in line and "iter_0/" in line and "another --out" in line
        assert _tree(out) == before  # nothing written: no points/, no front.csv, checkpoint unchanged


@pytest.mark.parametrize("restart", [False, True], ids=["resume", "restart"])
def test_close_loop_and_multistart_refuse_an_identify_folder(config, reference, tmp_path, capsys, restart):
    out = _copy(reference, tmp_path)
    before = _tree(out)
    extra = ["--restart"] if restart else []
    for argv in (["close-loop", str(config), "--out", str(out), "--max-iterations", "0", *extra],
                 ["multistart", str(config), "--out", str(out), "--starts", "2", *extra]):
        capsys.readouterr()
        assert main(argv) == 2
        line = _one_line(capsys.readouterr().err)
        assert line.startswith(f"pyomo-heli {argv[0]}: error: {out}: holds the results of `pyomo-heli identify` "
                               f"(front.csv, chosen.json, points/)")
        assert _tree(out) == before
    # an identify folder without checkpoint.json (a copy, an older version) is recognised by its files
    (out / "checkpoint.json").unlink()
    with pytest.raises(StoreMismatchError, match="holds the results of `pyomo-heli identify`"):
        claim_folder(out, "close-loop")


def test_close_loop_marks_its_folder_and_resumes_into_it(config, tmp_path, monkeypatch):
    """close_loop writes checkpoint.json {"what": "close-loop"} before the first identification (so a killed
    loop is recognised too), and accepts its own folder again."""
    import pyomo_heli.workflows.close_loop as cl
    from pyomo_heli.config import load_identification_config

    class Stop(Exception):
        pass

    def stop(*args, **kw):
        raise Stop

    monkeypatch.setattr(cl, "run_identification", stop)
    cfg = load_identification_config(config)
    out = tmp_path / "loop"
    with pytest.raises(Stop):
        cl.close_loop(cfg, out, cl.loop_settings(cfg), progress=lambda s: None)
    assert json.loads((out / "checkpoint.json").read_text()) == {"what": "close-loop"}
    assert folder_kind(out) == "close-loop"
    with pytest.raises(Stop):  # its own folder: accepted (the loop resumes there)
        cl.close_loop(cfg, out, cl.loop_settings(cfg), progress=lambda s: None)
    with pytest.raises(StoreMismatchError, match="close-loop"):
        claim_folder(out, "identification")


def test_a_fresh_or_own_folder_is_accepted(tmp_path):
    claim_folder(tmp_path / "nowhere", "identification")
    (tmp_path / "empty").mkdir()
    claim_folder(tmp_path / "empty", "close-loop")
    PointStore(tmp_path / "ms", "fp", what="multi-start")
    assert folder_kind(tmp_path / "ms") == "multi-start"
    PointStore(tmp_path / "ms", "fp", what="multi-start")
    with pytest.raises(StoreMismatchError, match="`pyomo-heli multistart`"):
        claim_folder(tmp_path / "ms", "identification")


# ---------------------------------------------------------------- 4. close-loop --dataset that is no flight test
@pytest.mark.parametrize("which", ["empty", "results"])
def test_close_loop_dataset_without_manifest_is_refused_before_out_is_created(config, reference, tmp_path, capsys,
                                                                              which):
    if which == "empty":
        ds = tmp_path / "ds"
        ds.mkdir()
    else:
        ds = _copy(reference, tmp_path, "ds")
    out = tmp_path / "o"
    capsys.readouterr()
    assert main(["close-loop", str(config), "--dataset", str(ds), "--out", str(out)]) == 2
    line = _one_line(capsys.readouterr().err)
    assert line.startswith(f"pyomo-heli close-loop: error: option --dataset: {ds} is not a flight-test folder")
    assert "manifest.json" in line
    if which == "results":
        assert "front.csv" in line
    assert not out.exists()


def test_close_loop_adds_the_standard_errors_a_stopped_iteration_lacks(config, tmp_path):
    """identify saves its front before the standard errors: a loop stopped between the two left a finished
    iteration without them, which a rerun reused as it was (the kept terms read "+- nan" in the held-out tables,
    the report quoted the structure step's standard error as the kept model's). The rerun now computes them: the
    same numbers as the uninterrupted run's."""
    import dataclasses

    import pyomo_heli.workflows.close_loop as cl
    from pyomo_heli.config import load_identification_config

    cfg = load_identification_config(config)
    settings = dataclasses.replace(cl.loop_settings(cfg), max_iterations=0)
    assert settings.uncertainty == "chosen"
    out = tmp_path / "loop"
    first = cl.close_loop(cfg, out, settings, progress=lambda s: None)["iterations"][0]["standard_errors"]
    assert first and all(v > 0 for v in first.values())
    chosen = out / "iter_0" / "chosen.json"
    doc = json.loads(chosen.read_text())
    for point in ("chosen", "direct"):
        doc[point].pop("uncertainty", None)
    chosen.write_text(json.dumps(doc))  # as the identification left it before its standard errors
    a = out / "iter_0" / "time_domain.json"
    a.write_text(json.dumps({k: v for k, v in json.loads(a.read_text()).items() if k != "uncertainty"}))
    lines = []
    again = cl.close_loop(cfg, out, settings, progress=lines.append)["iterations"][0]
    assert any("reusing the finished identification" in s for s in lines)
    assert any("has no standard errors (stopped before them): computing them" in s for s in lines)
    assert again["standard_errors"] == pytest.approx(first, rel=1e-9)
    assert "uncertainty" in json.loads(chosen.read_text())["chosen"]  # saved: a third run reuses them
