"""Shape of a trim residual against airspeed: noise only, constant, ~V^2, low-speed bump, or V^2 + bump.

Which shape a residual has says what kind of effect is missing: a constant
offset points at a rigging bias or a CG offset, a smooth trend over the whole
speed range at parameters the model already has (twist, tail lift slope, drag),
a localised low-speed bump at something that acts only at low speed (the rotor
wake reaching the tail), and noise only at nothing.

Method (model_spec.md section 4.8, step 2), per channel, with the residuals
e_k at speeds V_k:

1. Nested least-squares fits of the shapes (x = V / 120 kt)

   =============  ================================  =====================
   shape          basis                             parameters counted
   =============  ================================  =====================
   noise          none (e = noise)                  0
   constant       1                                 1
   V^2            1, x^2                            2
   bump           1, g(V)                           4 (amplitude, offset, centre, width)
   V^2 + bump     1, x^2, g(V)                      5
   =============  ================================  =====================

   g(V) = exp(-(V - V_c)^2 / (2 w^2)) is a Gaussian bump; its centre V_c
   (0..50 kt: low speed) and width w (5..20 kt) are chosen from a grid by least squares;
   a grid bump must cover at least 3 distinct speeds (g >= 0.5), so that a
   single outlying point is not called a bump.
   The bump is a generic localised shape, not the form of any particular
   physical effect.

   Optionally every model, the noise-only one included, also carries
   nuisance columns: the trim sensitivities of the identified parameters. The
   test then asks for structure beyond what those parameters can absorb (the
   Pareto choice trades trim fit against time fit, which leaves a residual
   along those directions without any missing physics); "noise" then means
   "noise plus a parameter shift". A shape whose basis lies almost inside
   the span of those sensitivities (less than 10 % of its norm outside, e.g.
   V^2 in lon, which twist and tail lift slope produce) cannot be told apart
   from a parameter shift and is not tested (``absorbed``).

2. Is there any structure? For each shape, the F statistic against noise only,
   F = ((RSS_0 - RSS_s) / k_s) / (RSS_s / (n - k_s - p)), k_s = linear shape
   coefficients, p = nuisance columns.
   F does not depend on the noise level, so its distribution under "white
   Gaussian noise" depends only on the speeds: it is obtained by a seeded Monte
   Carlo (``n_mc`` draws), which also accounts for the grid search of the bump
   (the maximum of F over the grid). Structure is declared when the smallest
   p-value is below ``alpha / m`` (Bonferroni over the m <= 4 shapes tested).

3. Which structure? Among the shapes tested, the smallest BIC,
   n ln(RSS/n) + k ln(n) with k the parameters counted above.

A Wald-Wolfowitz runs test on the signs of the residuals ordered by speed is
reported alongside (few runs = neighbouring speeds share their sign = structure).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np
from scipy import stats

from ..units import KT

SHAPES = ("noise", "constant", "V^2", "bump", "V^2+bump")
#: bump grid: centres and widths [kt]
BUMP_CENTRES_KT = tuple(float(c) for c in np.arange(0.0, 50.0 + 1e-9, 5.0))
BUMP_WIDTHS_KT = (5.0, 10.0, 15.0, 20.0)
V_REF = 120 * KT
#: distinct speeds a bump must cover (basis >= 0.5) to count as a localised shape
MIN_BUMP_SPEEDS = 3
#: a shape column whose part outside the nuisance span is below this fraction of its norm is absorbed
ABSORBED = 0.1
#: parameters counted by the information criterion (bump: + centre and width)
N_PARAMS = {"noise": 0, "constant": 1, "V^2": 2, "bump": 4, "V^2+bump": 5}
DESCRIPTION = {"noise": "noise only", "constant": "constant offset", "V^2": "smooth trend ~V^2",
               "bump": "localised low-speed bump", "V^2+bump": "smooth trend ~V^2 plus a localised low-speed bump"}


@dataclass
class ShapeTest:
    """Result of :func:`trim_shape_test` for one channel (residual units as given, SI)."""

    channel: str
    n: int
    shape: str  # one of SHAPES
    description: str
    structured: bool
    p_values: dict  # shape -> Monte Carlo p-value of F against noise only
    F: dict
    bic: dict
    rss: dict
    rms: float  # RMS of the residual
    rms_after: float  # RMS left after the chosen shape
    explained: float  # 1 - RSS_shape / RSS_noise of the chosen shape
    fit: dict = field(default_factory=dict)  # coefficients of the chosen shape (SI), bump centre/width [m/s]
    bump: dict = field(default_factory=dict)  # best bump-only fit: centre, width [m/s], amplitude, offset
    runs: dict = field(default_factory=dict)  # runs test: runs, expected, z, p
    alpha: float = 0.01
    n_mc: int = 0
    nuisance: list = field(default_factory=list)  # names of the nuisance columns (identified parameters)
    V: list = field(default_factory=list)  # speeds of the points tested [m/s]
    adjusted: list = field(default_factory=list)  # residual minus the nuisance part of the chosen fit (SI)
    absorbed: list = field(default_factory=list)  # shapes not tested: a basis column lies in the nuisance span

    def to_dict(self) -> dict:
        return asdict(self)


def bump_basis(V, centre, width):
    return np.exp(-0.5 * ((np.asarray(V, dtype=float) - centre) / width) ** 2)


def _basis(X: np.ndarray) -> np.ndarray:
    """Orthonormal basis of the column space of X (rank-revealing: collinear columns count once)."""
    if X.shape[1] == 0:
        return X
    U, sv, _ = np.linalg.svd(X / np.maximum(np.linalg.norm(X, axis=0), 1e-300), full_matrices=False)
    return U[:, sv > 1e-9 * sv[0]]


def _absorbed(col: np.ndarray, S: np.ndarray) -> bool:
    """True if ``col`` lies (almost) in the span of the nuisance columns: such a shape cannot be told
    apart from a shift of the identified parameters."""
    if S.shape[1] == 0:
        return False
    Q = _basis(S)
    res = col - Q @ (Q.T @ col)
    return bool(np.linalg.norm(res) < ABSORBED * np.linalg.norm(col))


def _designs(V: np.ndarray, S: np.ndarray) -> tuple[dict, list]:
    """shape -> list of (design matrix [shape columns, then nuisance S], bump (centre, width) or None),
    and the shapes left out because a basis column is absorbed by the nuisance."""
    one = np.ones_like(V)
    x2 = (V / V_REF) ** 2
    out = {"constant": [(np.column_stack([one, S]), None)], "V^2": [(np.column_stack([one, x2, S]), None)],
           "bump": [], "V^2+bump": []}
    for c in BUMP_CENTRES_KT:
        for w in BUMP_WIDTHS_KT:
            g = bump_basis(V, c * KT, w * KT)
            # a bump must be seen by at least MIN_BUMP_SPEEDS distinct speeds: a bump through one
            # speed is an outlier fit, not a localised shape
            if len({round(float(v), 3) for v in V[g >= 0.5]}) < MIN_BUMP_SPEEDS or np.ptp(g) < 1e-3:
                continue
            if _absorbed(g - g.mean(), S):
                continue
            out["bump"].append((np.column_stack([one, g, S]), (c * KT, w * KT)))
            out["V^2+bump"].append((np.column_stack([one, x2, g, S]), (c * KT, w * KT)))
    dropped = []
    if _absorbed(one, S):
        dropped += ["constant"]
    if _absorbed(x2, S) or _absorbed(x2 - x2.mean(), S):
        dropped += ["V^2", "V^2+bump"]
    dropped += [k for k in ("bump", "V^2+bump") if not out[k] and k not in dropped]
    return {k: v for k, v in out.items() if k not in dropped and v}, dropped


def _rss_batch(X: np.ndarray, E: np.ndarray) -> np.ndarray:
    """Residual sum of squares of the LS fit of every column of E on X."""
    Q = _basis(X)
    proj = Q.T @ E
    return np.sum(E**2, axis=0) - np.sum(proj**2, axis=0)


def _best(designs, E):
    """Minimum RSS over a list of designs, per column of E, and the index of the best design."""
    rss = np.vstack([_rss_batch(X, E) for X, _ in designs])
    return rss.min(axis=0), rss.argmin(axis=0)


def runs_test(e) -> dict:
    """Wald-Wolfowitz runs test on the signs of ``e`` (in the given order); p two-sided, normal approx."""
    s = np.sign(np.asarray(e, dtype=float))
    s = s[s != 0]
    n1, n2 = int((s > 0).sum()), int((s < 0).sum())
    n = n1 + n2
    if n1 == 0 or n2 == 0:
        return {"runs": 1, "expected": float("nan"), "z": float("nan"), "p": 0.0 if n > 1 else 1.0}
    runs = 1 + int(np.sum(s[1:] != s[:-1]))
    mu = 2 * n1 * n2 / n + 1
    var = 2 * n1 * n2 * (2 * n1 * n2 - n) / (n**2 * (n - 1))
    z = (runs - mu) / math.sqrt(var) if var > 0 else 0.0
    return {"runs": runs, "expected": mu, "z": z, "p": float(2 * stats.norm.sf(abs(z)))}


def trim_shape_test(V, e, channel: str = "", alpha: float = 0.01, n_mc: int = 4000, seed: int = 0,
                    nuisance=None, nuisance_names=()) -> ShapeTest:
    """Classify the shape of residual ``e`` against speed ``V`` [m/s] (see the module docstring).

    ``nuisance`` (n x p): columns every model may use for free, in the null
    model too: the trim sensitivities of the identified parameters, so that the
    test asks for structure *beyond what those parameters can absorb*
    (re-weighting of the trade-off between time and trim data moves the trims
    along these directions, without any missing physics). ``n_mc``: draws of the null distribution, raised to
    10 x shapes / alpha when fewer (the smallest p they give is 1 / (n_mc + 1)).
    """
    V = np.asarray(V, dtype=float)
    e = np.asarray(e, dtype=float)
    S = np.zeros((len(V), 0)) if nuisance is None else np.asarray(nuisance, dtype=float).reshape(len(V), -1)
    ok = np.isfinite(V) & np.isfinite(e) & np.all(np.isfinite(S), axis=1)
    V, e, S = V[ok], e[ok], S[ok]
    n = len(e)
    p_n = _basis(S).shape[1]
    if n < 8 + p_n:
        raise ValueError(f"trim shape test of {channel or 'a channel'}: {n} points, need at least {8 + p_n}")
    designs, dropped = _designs(V, S)
    if not designs:
        raise ValueError(f"trim shape test of {channel or 'a channel'}: every shape is absorbed by the nuisance")
    k_lin = {"constant": 1, "V^2": 2, "bump": 2, "V^2+bump": 3}
    # the smallest Monte Carlo p is 1 / (n_mc + 1): at least ten draws per Bonferroni level, so that a small alpha
    # can still find structure (the default 4000 at alpha 0.01 and four shapes)
    n_mc = max(int(n_mc), math.ceil(10 * len(designs) / alpha))

    def F_of(rss0, rss, k):
        return ((rss0 - rss) / k) / np.maximum(rss / (n - k - p_n), 1e-300)

    rss0 = float(_rss_batch(S, e[:, None])[0]) if p_n else float(np.sum(e**2))
    rss, idx, F = {"noise": rss0}, {}, {}
    for s, ds in designs.items():
        r, i = _best(ds, e[:, None])
        rss[s], idx[s] = float(r[0]), int(i[0])
        F[s] = float(F_of(rss0, rss[s], k_lin[s]))
    # null distribution of F: white Gaussian residuals (+ any nuisance combination, to which F is
    # invariant, as it is to the noise level) at the same speeds
    rng = np.random.default_rng(seed)
    E = rng.standard_normal((n, n_mc))
    rss0_mc = _rss_batch(S, E) if p_n else np.sum(E**2, axis=0)
    p = {}
    for s, ds in designs.items():
        r_mc, _ = _best(ds, E)
        p[s] = float((1 + np.sum(F_of(rss0_mc, r_mc, k_lin[s]) >= F[s])) / (1 + n_mc))
    bic = {s: n * math.log(max(rss[s], 1e-300) / n) + N_PARAMS[s] * math.log(n) for s in rss}
    structured = min(p.values()) < alpha / len(p)
    shape = min(designs, key=lambda s: bic[s]) if structured else "noise"

    def coefficients(s):
        """Shape coefficients and the nuisance combination of the fit of shape ``s``."""
        if s == "noise":
            X, bw, k = S, None, 0
        else:
            (X, bw), k = designs[s][idx[s]], k_lin[s]
        c = np.linalg.lstsq(X, e, rcond=None)[0] if X.shape[1] else np.zeros(0)
        names = {"noise": [], "constant": ["offset"], "V^2": ["offset", "V2_at_120kt"],
                 "bump": ["offset", "amplitude"], "V^2+bump": ["offset", "V2_at_120kt", "amplitude"]}[s]
        d = dict(zip(names, (float(x) for x in c[:k])))
        if bw is not None:
            d.update({"centre": float(bw[0]), "width": float(bw[1])})
        return d, (S @ c[k:] if p_n else np.zeros(n))

    fit, absorbed = coefficients(shape)
    bump_fit = coefficients("bump")[0] if "bump" in designs else {}
    adjusted = e - absorbed
    rms = math.sqrt(float(np.sum(e**2)) / n)
    return ShapeTest(channel=channel, n=n, shape=shape, description=DESCRIPTION[shape], structured=bool(structured),
                     p_values=p, F=F, bic=bic, rss=rss, rms=rms, rms_after=math.sqrt(rss[shape] / n),
                     explained=1.0 - rss[shape] / rss0 if rss0 > 0 else 0.0, fit=fit,
                     bump=bump_fit, runs=runs_test(adjusted[np.argsort(V, kind="stable")]),
                     alpha=alpha, n_mc=n_mc, nuisance=list(nuisance_names)[: S.shape[1]],
                     V=V.tolist(), adjusted=adjusted.tolist(), absorbed=dropped)


def shape_curve(test: ShapeTest, V) -> np.ndarray:
    """The fitted shape of ``test`` evaluated at speeds ``V`` [m/s] (for figures)."""
    V = np.asarray(V, dtype=float)
    f = test.fit
    y = np.zeros_like(V) + f.get("offset", 0.0)
    if "V2_at_120kt" in f:
        y = y + f["V2_at_120kt"] * (V / V_REF) ** 2
    if "amplitude" in f:
        y = y + f["amplitude"] * bump_basis(V, f["centre"], f["width"])
    return y
