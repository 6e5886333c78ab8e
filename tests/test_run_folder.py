"""The run folder the orchestrators share (pyomo_heli.workflows.run_folder): claim, lock, store, front table, log.

Small and fast: no NLP is built. The end-to-end runs of identify, multistart and close-loop on real folders are in
tests/test_pareto_store.py, tests/test_pareto_resume.py, tests/test_pareto_lock.py and tests/test_interrupts.py.
"""
import json
import signal
from pathlib import Path
from types import SimpleNamespace

import pandas as pd
import pytest

from pyomo_heli.log import info
from pyomo_heli.pareto.store import LOCK_FILE, FolderBusyError, StoreMismatchError
from pyomo_heli.workflows.run_folder import FrontWriter, RunFolder
from test_pareto_lock import _holder as lock_holder

ROOT = Path(__file__).parent.parent


def _holder(folder: Path):
    """Another process running in ``folder`` (claimed and locked) until killed."""
    return lock_holder(folder, "from pyomo_heli.workflows.run_folder import RunFolder",
                       "RunFolder({folder!r}, 'identification') as run, run.locked()")


def test_a_second_run_on_a_busy_folder_is_refused_in_one_line_and_writes_nothing(tmp_path):
    out = tmp_path / "out"
    proc = _holder(out)
    try:
        with pytest.raises(FolderBusyError) as err:
            with RunFolder(out, "identification") as run, run.locked():
                pass
        msg = str(err.value)
        assert "\n" not in msg
        assert msg == (f"{out}: in use by another run (pid {proc.pid}: -c identify cfg.toml); wait for it to end or "
                       f"choose another --out")
        assert sorted(p.name for p in out.iterdir()) == [LOCK_FILE]  # no log, no provenance, no checkpoint
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    with RunFolder(out, "identification") as run, run.locked():  # freed with its holder
        with run.locked():  # re-entrant within one process (close-loop runs identify in its own folder)
            pass


def test_another_commands_folder_is_refused_before_anything_is_written(tmp_path):
    with RunFolder(tmp_path, "multi-start") as run, run.locked():
        run.store("fp").save("start000", {"start": 0})
    before = sorted(p.name for p in tmp_path.iterdir())
    for restart in (False, True):
        with pytest.raises(StoreMismatchError) as err:
            with RunFolder(tmp_path, "identification", restart=restart):
                raise AssertionError("not reached")
        msg = str(err.value)
        assert "\n" not in msg and msg.startswith(f"{tmp_path}: holds the results of `pyomo-heli multistart`")
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_resume_reads_back_what_was_stored_and_restart_discards_it(tmp_path):
    cfg = SimpleNamespace(path=tmp_path / "case.toml", dataset=tmp_path / "data")
    record = {"index": 0, "kind": "A", "J_time": 0.1 + 0.2, "parameters": {"a": -1.0 / 3.0}}
    with RunFolder(tmp_path / "out", "identification", cfg) as run, run.locked():
        store = run.store("fp-1")
        assert store.keys() == []
        store.save("A", record)
        table = run.front("front.csv")
        table.add({"index": 2, "J_time": 1.0 / 7.0})
        table.add({"index": 0, "J_time": 0.1 + 0.2})
        info("a message of the run")
    out = tmp_path / "out"
    # what the run left: its point, its table (rows in the order they finished), its log and provenance
    from pyomo_heli.provenance import source_sha256

    assert json.loads((out / "checkpoint.json").read_text()) == {"fingerprint": "fp-1", "what": "identification",
                                                                 "source": source_sha256()}  # the code that solved
    front = pd.read_csv(out / "front.csv")
    assert front["index"].tolist() == [2, 0] and front["J_time"].tolist() == [float(f"{1 / 7:.12g}"), 0.3]
    log = (out / "pyomo_heli.log").read_text()
    assert "a message of the run" in log and "finished in" in log
    prov = json.loads((out / "provenance.json").read_text())
    assert prov["config"] == "../case.toml" and prov["datasets_relative_to_config"] == ["data"]

    said = []
    with RunFolder(out, "identification", cfg) as run, run.locked():
        store = run.store("fp-1", said.append)
        assert said == [f"resuming: 1 finished point(s) in {out / 'points'}"]
        assert store.has("A") and store.record("A") == record  # floats round-trip exactly
        assert not (run.front("front.csv").path.exists())  # a fresh table: the points are added again
    prov = json.loads((out / "provenance.json").read_text())
    assert len(prov["previous"]) == 1  # the first run's record kept

    with pytest.raises(StoreMismatchError, match="holds finished points of a different identification"):
        with RunFolder(out, "identification") as run, run.locked():
            run.store("fp-2")
    with RunFolder(out, "identification", restart=True) as run, run.locked():
        assert run.store("fp-2").keys() == []


def test_front_writer_sorts_by_its_column_and_keeps_an_old_table_unless_fresh(tmp_path):
    path = tmp_path / "starts.csv"
    path.write_text("start\n9\n")
    w = FrontWriter(path, fresh=False, order="start")
    assert path.read_text() == "start\n9\n"  # kept until the first row is written
    for k in (2, 0, 1):
        w.add({"start": k, "objective": k / 3.0})
    assert pd.read_csv(path)["start"].tolist() == [0, 1, 2]
    assert [r["start"] for r in w.rows] == [2, 0, 1]
    FrontWriter(path)  # fresh: the old table is gone at once
    assert not path.exists()


def test_a_folder_the_run_refused_gets_no_log_and_a_failed_run_keeps_its_log(tmp_path):
    busy = tmp_path / "busy"
    with RunFolder(busy, "close-loop") as run, run.locked():
        run.mark()
    files = {p.name: p.read_bytes() for p in busy.iterdir()}
    assert {"pyomo_heli.log", "provenance.json", "checkpoint.json"} <= set(files)
    with pytest.raises(StoreMismatchError):
        with RunFolder(busy, "multi-start"):
            pass
    assert {p.name: p.read_bytes() for p in busy.iterdir()} == files  # the refused run added no log line

    with pytest.raises(RuntimeError):
        with RunFolder(tmp_path / "failed", "identification") as run, run.locked():
            info("half way")
            raise RuntimeError("solver crashed")
    assert "half way" in (tmp_path / "failed" / "pyomo_heli.log").read_text()
    assert (tmp_path / "failed" / "provenance.json").is_file()  # the folder says what made it, even so
