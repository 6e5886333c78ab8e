"""The small generated instances' flight-test cache (pyomo_heli.studies.small_instances.generate_cached)."""
from __future__ import annotations

import pytest

import pyomo_heli.studies.small_instances as si
from pyomo_heli.flighttest.generate import OutputFolderError

GEN = """[dataset]
name = "tiny"
aircraft = "Bo-105 (cache test)"
seed = {seed}

[truth]
parameters = {{}}

[sensors]
noise = true

[trims]
speeds_kt = [20, 80]

[[maneuvers]]
name = "lon_80kt"
role = "identification"
speed_kt = 80
channel = "lon"
shape = "doublet"
amplitude_deg = 0.5
step_s = 0.5
duration_s = 1.5
t_start_s = 0.5
"""


def _files(folder):
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_a_cached_flight_test_is_the_generated_one_and_another_text_is_generated(tmp_path, monkeypatch):
    cfg, cache = tmp_path / "gen.toml", tmp_path / "cache"
    cache.mkdir()
    cfg.write_text(GEN.format(seed=3))
    si.generate_cached(cfg, tmp_path / "a", cache)  # generated, then stored
    assert len(list(cache.iterdir())) == 1
    si.generate_cached(cfg, tmp_path / "plain")  # no cache: generated again
    assert _files(tmp_path / "a") == _files(tmp_path / "plain")

    def refuse(*_a, **_k):
        raise AssertionError("generated although the cache holds it")

    monkeypatch.setattr(si, "generate_from_file", refuse)
    si.generate_cached(cfg, tmp_path / "b", cache)  # copied
    assert _files(tmp_path / "b") == _files(tmp_path / "a")
    with pytest.raises(OutputFolderError):  # a folder holding a flight test is refused, as generation refuses it
        si.generate_cached(cfg, tmp_path / "b", cache)
    cfg.write_text(GEN.format(seed=4))  # another noise realisation: not in the cache
    with pytest.raises(AssertionError, match="generated although"):
        si.generate_cached(cfg, tmp_path / "c", cache)
