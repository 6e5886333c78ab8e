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


def _records(r0, r1, name: str) -> tuple[list[np.ndarray], list[np.ndarray]]:
    r0, r1 = [np.asarray(a, float) for a in r0], [np.asarray(a, float) for a in r1]
    if len(r0) != len(r1) or not r0:
        raise ValueError(f"{name}: need the same non-empty list of records for both models")
    for k, (a, b) in enumerate(zip(r0, r1)):
        if a.shape != b.shape:
            raise ValueError(f"{name}: record {k} has {a.size} samples for model 0, {b.size} for 1")
    return r0, r1


def _batch_test(d_records: list[np.ndarray], n_segment, min_batches: int, name: str):
    """The batch-means test of mean(d) > 0 over the loss differentials ``d_records`` (one array per record):
    (mean, se, z, batches, p)."""
    cuts = -(-min_batches // len(d_records)) if len(d_records) < min_batches else 1  # batches per record
    segs = n_segment if isinstance(n_segment, list) else [n_segment] * len(d_records)
    batches = []
    for k, d in enumerate(d_records):
        if d.size == 0:
            raise ValueError(f"{name}: record {k} has no finite samples")
        n = max(d.size // cuts if segs[k] is None else int(segs[k]), 1)
        edges = list(range(0, d.size, n))
        if len(edges) > 1 and d.size - edges[-1] < n:
            edges.pop()  # merge the last partial segment
        edges.append(d.size)
        batches += [d[i:j] for i, j in zip(edges[:-1], edges[1:])]
    d = np.concatenate(d_records)
    mean = float(d.mean())
    # the batch-means variance of the grand mean, B / (B - 1) sum_b (S_b - n_b mean)^2 / N^2 (S_b: batch b's sum):
    # for equal batches var(batch means, ddof=1) / B, so that z is t-distributed on B - 1 df for normal batches
    nb = len(batches)
    se = (nb / max(nb - 1, 1) * sum(float((s - mean).sum()) ** 2 for s in batches) / d.size**2) ** 0.5
    z = mean / se if se > 0 else (np.inf if mean > 0 else 0.0)
    p = float(student_t.sf(z, df=max(nb - 1, 1)))
    return mean, se, float(z), nb, p


def mean_square_change(r0, r1, n_segment: int | list[int] | None = None, alpha: float = 0.01,
                       min_batches: int = MIN_BATCHES) -> MeanSquareChange:
    """Paired test of ``r1`` against ``r0``: lists of residual arrays, one pair per record (same samples).

    ``n_segment``: None (default) for whole records as batches (cut into equal parts when there are fewer
    than ``min_batches`` records); or samples per batch (one number, or one per record), a record's last
    partial batch merged into the one before it. Raises ValueError for records of unequal length or
    without finite samples.
    """
    r0, r1 = _records(r0, r1, "mean_square_change")
    ok = [np.isfinite(a) & np.isfinite(b) for a, b in zip(r0, r1)]
    d = [b[m] ** 2 - a[m] ** 2 for a, b, m in zip(r0, r1, ok)]
    mean, se, z, nb, p = _batch_test(d, n_segment, min_batches, "mean_square_change")
    ms0 = float(np.mean(np.concatenate([a[m] ** 2 for a, m in zip(r0, ok)])))
    ms1 = ms0 + mean
    return MeanSquareChange(ms0=ms0, ms1=ms1, se=se, z=z, segments=nb,
                            rms_change_pct=100.0 * ((ms1 / ms0) ** 0.5 - 1.0) if ms0 > 0 else float("nan"),
                            p_rise=p, rise_significant=bool(p < alpha))


def joint_mean_square_change(r0: dict, r1: dict, n_segment: int | list[int] | None = None, alpha: float = 0.01,
                             min_batches: int = MIN_BATCHES) -> MeanSquareChange:
    """The same paired test for all outputs at once: ``r0``, ``r1`` map each output to its list of residual
    arrays (the same records and samples for every output).

    The loss of a sample is the sum over the outputs of its squared residuals, each in units of model 0's mean
    square of that output, L(t) = sum_o r_o(t)^2 / ms0_o, so that the differential d(t) = L1(t) - L0(t) has
    mean D = sum_o (ms1_o / ms0_o - 1): a broad small rise, on every output and significant on none alone,
    adds up. A sample enters where every output is finite. The batches are those of :func:`mean_square_change`
    (whole records by default); the batch means carry the correlation between the outputs of one record.
    Returned in standardised units: ms0 = the number of outputs, ms1 = ms0 + D, and ``rms_change_pct`` is the
    change of the standardised RMS. Swapping the models changes the units, so the test is not antisymmetric
    (sum_o (x_o - 1) against sum_o (1/x_o - 1), x_o = ms1_o / ms0_o). Raises ValueError for different outputs
    or records in ``r0`` and ``r1``.
    """
    name = "joint_mean_square_change"
    if set(r0) != set(r1) or not r0:
        raise ValueError(f"{name}: need the same non-empty set of outputs for both models")
    outs = sorted(r0)
    recs = {o: _records(r0[o], r1[o], f"{name} ({o})") for o in outs}
    n_rec = {len(recs[o][0]) for o in outs}
    if len(n_rec) != 1 or len({tuple(a.size for a in recs[o][0]) for o in outs}) != 1:
        raise ValueError(f"{name}: the outputs have different records or sample counts")
    ok = [np.logical_and.reduce([np.isfinite(recs[o][0][k]) & np.isfinite(recs[o][1][k]) for o in outs])
          for k in range(n_rec.pop())]
    ms0 = {o: float(np.mean(np.concatenate([a[m] ** 2 for a, m in zip(recs[o][0], ok)]))) if any(
        m.any() for m in ok) else 0.0 for o in outs}
    if any(v <= 0 for v in ms0.values()):
        raise ValueError(f"{name}: model 0 fits an output exactly or no sample is finite; nothing to standardise by")
    d = [sum((recs[o][1][k][m] ** 2 - recs[o][0][k][m] ** 2) / ms0[o] for o in outs) for k, m in enumerate(ok)]
    mean, se, z, nb, p = _batch_test(d, n_segment, min_batches, name)
    n = float(len(outs))
    return MeanSquareChange(ms0=n, ms1=n + mean, se=se, z=z, segments=nb,
                            rms_change_pct=100.0 * (((n + mean) / n) ** 0.5 - 1.0), p_rise=p,
                            rise_significant=bool(p < alpha))
