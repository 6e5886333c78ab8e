"""Seeded noise realizations of a data set: known white noise added to its outputs and trims.

Realization k of seed s draws from ``numpy.random.default_rng([s, k])``, so
each realization is the same whichever process computes it and in whatever
order. Maneuver outputs get independent Gaussian white noise of standard
deviation ``sigma[output]`` at every sample; trim points get
``trim_sigma[output]`` per point. The sigmas of a generated flight test:
:func:`pyomo_heli.flighttest.config.flight_test_noise`.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from ..nlp.identification import IdentificationData


def noisy_copy(data: IdentificationData, sigma: dict, trim_sigma: dict, seed: int, k: int,
               low_speed: tuple[float, dict] | None = None) -> IdentificationData:
    """Realization ``k`` of ``data`` plus white noise (SI units; outputs not named get none). ``low_speed``:
    (speed [m/s], {output: sigma}), the sigmas of maneuvers trimmed below that speed (a generated flight test's
    airspeed noise at low speed, :func:`~pyomo_heli.flighttest.config.flight_test_noise`)."""
    rng = np.random.default_rng([int(seed), int(k)])
    maneuvers = []
    for mv in data.maneuvers:
        df = mv.data.copy()
        slow = low_speed is not None and mv.trim_speed < low_speed[0]
        for o in sorted(sigma):
            if o in df:
                s = low_speed[1].get(o, sigma[o]) if slow else sigma[o]
                df[o] = df[o].to_numpy() + rng.standard_normal(len(df)) * float(s)
        maneuvers.append(dataclasses.replace(mv, data=df))
    trims = data.trims.copy()
    for o in sorted(trim_sigma):
        if o in trims:
            trims[o] = trims[o].to_numpy(dtype=float) + rng.standard_normal(len(trims)) * float(trim_sigma[o])
    return IdentificationData(maneuvers=maneuvers, trims=trims, speed_tol=data.speed_tol)
