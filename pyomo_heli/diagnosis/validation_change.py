"""Did the validation error really rise? A paired test of two models' prediction errors on the same records.

Two models replayed on the same validation records give residuals r0(t), r1(t) (data minus model).
Their mean squares differ by D = mean(r1^2 - r0^2). With r = e + n (model error e, sensor noise n, the
same n for both models), r1^2 - r0^2 = (e1^2 - e0^2) + 2 n (e1 - e0): the noise does not cancel, and at
a sensor-noise floor a change of a fraction of a percent in RMS can be the second term alone. Whether D
is larger than that is the question of the Diebold-Mariano test for equal predictive accuracy
(Diebold & Mariano 1995, J. Bus. Econ. Stat. 13(3)) with squared-error loss: z = D / se(D), the loss
differential d(t) = r1^2 - r0^2 being autocorrelated, se(D) is estimated by batch means. The batches are
whole records: the records are separate flights with independent noise, while within one record the
noise term is coloured far beyond a second (the measured-input noise integrates through the dynamics
into theta, TAS and n_z), so shorter batches underestimate se(D). With fewer than ``min_batches``
records each record is cut into equal batches, ``min_batches`` in all (a liberal test when the noise
stays correlated over a batch: it then flags a rise more often than alpha). With few batches the
variance estimate is itself uncertain, so z is referred to Student's t with (batches - 1) degrees of
freedom, the small-sample correction of Harvey, Leybourne & Newbold (1997, Int. J. Forecasting 13(2)).
A rise is significant when the one-sided p < alpha.

Evaluation needs no truth; on synthetic data the model-minus-truth-replay error (report.loop) is the
noise-free counterpart (the expectation of D over the noise is mean(e1^2 - e0^2)).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy.stats import t as student_t


@dataclass
class MeanSquareChange:
    """Change of one output's validation mean square from model 0 to model 1 (SI units squared)."""

    ms0: float
    ms1: float
    se: float  # batch-means standard error of ms1 - ms0
    z: float
    segments: int
    rms_change_pct: float  # 100 (RMS1 / RMS0 - 1)
    p_rise: float  # one-sided p-value of "model 1's error is larger"
    rise_significant: bool

    def to_dict(self) -> dict:
        return asdict(self)


#: fewer validation records than this: each record is cut into equal batches, this many in all
MIN_BATCHES = 6


def mean_square_change(r0, r1, n_segment: int | list[int] | None = None, alpha: float = 0.01,
                       min_batches: int = MIN_BATCHES) -> MeanSquareChange:
    """Paired test of ``r1`` against ``r0``: lists of residual arrays, one pair per record (same samples).

    ``n_segment``: None (default) for whole records as batches (cut into equal parts when there are fewer
    than ``min_batches`` records); or samples per batch (one number, or one per record), a record's last
    partial batch merged into the one before it. Raises ValueError for records of unequal length or
    without finite samples.
    """
    r0, r1 = [np.asarray(a, float) for a in r0], [np.asarray(a, float) for a in r1]
    if len(r0) != len(r1) or not r0:
        raise ValueError("mean_square_change: need the same non-empty list of records for both models")
    cuts = -(-min_batches // len(r0)) if len(r0) < min_batches else 1  # batches per record (n_segment None)
    segs = n_segment if isinstance(n_segment, list) else [n_segment] * len(r0)
    d_all, batches = [], []
    for k, (a, b) in enumerate(zip(r0, r1)):
        if a.shape != b.shape:
            raise ValueError(f"mean_square_change: record {k} has {a.size} samples for model 0, {b.size} for 1")
        ok = np.isfinite(a) & np.isfinite(b)
        d = b[ok] ** 2 - a[ok] ** 2
        if d.size == 0:
            raise ValueError(f"mean_square_change: record {k} has no finite samples")
        n = max(d.size // cuts if segs[k] is None else int(segs[k]), 1)
        edges = list(range(0, d.size, n))
        if len(edges) > 1 and d.size - edges[-1] < n:
            edges.pop()  # merge the last partial segment
        edges.append(d.size)
        batches += [d[i:j] for i, j in zip(edges[:-1], edges[1:])]
        d_all.append(d)
    d = np.concatenate(d_all)
    n_tot = d.size
    mean = float(d.mean())
    var = sum(float((s - mean).sum()) ** 2 for s in batches) / n_tot**2
    se = var**0.5
    ms0 = float(np.mean(np.concatenate([a[np.isfinite(a) & np.isfinite(b)] ** 2 for a, b in zip(r0, r1)])))
    ms1 = ms0 + mean
    z = mean / se if se > 0 else (np.inf if mean > 0 else 0.0)
    p = float(student_t.sf(z, df=max(len(batches) - 1, 1)))
    return MeanSquareChange(ms0=ms0, ms1=ms1, se=se, z=float(z), segments=len(batches),
                            rms_change_pct=100.0 * ((ms1 / ms0) ** 0.5 - 1.0) if ms0 > 0 else float("nan"),
                            p_rise=p, rise_significant=bool(p < alpha))
