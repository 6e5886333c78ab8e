"""Eq. 11 of the paper, written once for any number of objectives, and the nadir rules it is normalised by.

    d(J) = sqrt( sum_k ((J_k - U_k) / (N_k - U_k))^2 )

U is the utopia point (each objective's own minimum, from the anchors) and N the nadir, estimated by
one of :data:`NADIR_RULES`: the payoff table (each objective's worst value over the anchors) or the
non-dominated points of the front (:func:`nondominated_nadir`). With more than two objectives the
payoff table can misjudge the front's range both ways: an anchor's value of another objective can lie
far beyond the useful front, and the front can reach beyond every anchor.
"""
from __future__ import annotations

import numpy as np

#: nadir rules of Eq. 11: "payoff" (worst value of each objective over the anchors) or
#: "nondominated" (worst value over the non-dominated converged points inside the grid's box)
NADIR_RULES = ("payoff", "nondominated")


def utopia_distance_n(J, utopia, nadir) -> np.ndarray:
    """Eq. 11 for any number of objectives: sqrt(sum_k ((J_k - U_k)/(N_k - U_k))^2); J is (points, k).

    An objective whose nadir equals its utopia value (no spread on the front) adds nothing.
    """
    J = np.atleast_2d(np.asarray(J, float))
    U, N = np.asarray(utopia, float), np.asarray(nadir, float)
    spread = N != U
    terms = np.where(spread, (J - U) / np.where(spread, N - U, 1.0), 0.0)
    return np.sqrt(np.sum(terms**2, axis=1))


def utopia_distance_weights(J, utopia, nadir) -> np.ndarray | None:
    """The weights w (summing to 1) for which the point J of the direct Eq. 11 solve is stationary for sum_k w_k J_k:
    it minimises sum_k ((J_k - U_k)/(N_k - U_k))^2, so w_k is proportional to (J_k - U_k)/(N_k - U_k)^2. None when an
    objective has no spread on the front (or a value is not finite) or J is at utopia."""
    J, U, N = (np.asarray(x, float) for x in (J, utopia, nadir))
    if not (np.isfinite(J).all() and np.isfinite(U).all() and np.isfinite(N).all()) or np.any(N == U):
        return None
    w = np.maximum(J - U, 0.0) / (N - U) ** 2
    return w / w.sum() if w.sum() > 0 else None


def nondominated(J) -> np.ndarray:
    """Mask of the rows of J (points, objectives; all minimised) that no other row dominates.

    Row q dominates row p when it is no worse in every objective and better in one; equal rows keep
    each other.
    """
    J = np.atleast_2d(np.asarray(J, float))
    keep = np.ones(len(J), dtype=bool)
    for p in range(len(J)):
        others = np.delete(J, p, axis=0)
        keep[p] = not np.any(np.all(others <= J[p], axis=1) & np.any(others < J[p], axis=1))
    return keep


def dominating(j, J, rtol: float = 1e-6) -> int | None:
    """The index of a row of J (points, objectives; all minimised) that dominates the point j beyond solver
    noise: worse in no objective by more than the noise, better in one by more than it; the noise is ``rtol``
    times the larger magnitude (at least ``rtol``). None if no row does."""
    j, J = np.asarray(j, float), np.atleast_2d(np.asarray(J, float))
    tol = rtol * np.maximum(np.maximum(np.abs(J), np.abs(j)), 1.0)
    hit = np.all(J <= j + tol, axis=1) & np.any(J < j - tol, axis=1)
    return int(np.argmax(hit)) if hit.any() else None


def nondominated_nadir(J) -> tuple:
    """The nadir estimated from points: each objective's worst value over the non-dominated rows of J."""
    J = np.atleast_2d(np.asarray(J, float))
    return tuple(float(v) for v in J[nondominated(J)].max(axis=0))


def payoff_nadir(J) -> tuple:
    """The nadir of a payoff table (one row per anchor): each objective's worst value over the anchors."""
    return tuple(float(v) for v in np.atleast_2d(np.asarray(J, float)).max(axis=0))
