"""Seeded noise realizations of a data set: known white noise added to its outputs and trims.

Realization k of seed s draws from ``numpy.random.default_rng([s, k])``, so
each realization is the same whichever process computes it and in whatever
order. Maneuver outputs get independent Gaussian white noise of standard
deviation ``sigma[output]`` at every sample; trim points get
``trim_sigma[output]`` per point.
"""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from ..nlp.identification import IdentificationData


def noisy_copy(data: IdentificationData, sigma: dict, trim_sigma: dict, seed: int, k: int) -> IdentificationData:
    """Realization ``k`` of ``data`` plus white noise (SI units; outputs not named get none)."""
    rng = np.random.default_rng([int(seed), int(k)])
    maneuvers = []
    for mv in data.maneuvers:
        df = mv.data.copy()
        for o in sorted(sigma):
            if o in df:
                df[o] = df[o].to_numpy() + rng.standard_normal(len(df)) * float(sigma[o])
        maneuvers.append(dataclasses.replace(mv, data=df))
    trims = data.trims.copy()
    for o in sorted(trim_sigma):
        if o in trims:
            trims[o] = trims[o].to_numpy(dtype=float) + rng.standard_normal(len(trims)) * float(trim_sigma[o])
    return IdentificationData(maneuvers=maneuvers, trims=trims, speed_tol=data.speed_tol)


def flight_test_noise(generator_config: str | Path) -> tuple[dict, dict]:
    """(sigma, trim_sigma) in SI of a flight-test generator config (e.g. data/bo105_synthetic.toml).

    A trim point's noise is its averaging noise and its not-quite-steady offset
    together: sqrt(sigma^2 + offset^2).
    """
    from ..flighttest.config import load_config

    cfg = load_config(generator_config)
    sigma = dict(cfg.sensors.sigma)
    trim = {k: math.hypot(cfg.trim_sigma.get(k, 0.0), cfg.trim_offset.get(k, 0.0))
            for k in set(cfg.trim_sigma) | set(cfg.trim_offset)}
    return sigma, trim
