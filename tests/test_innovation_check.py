"""The innovation check (pyomo_heli.studies.innovation_check): the truth model's whiteness tests pooled over noise
realisations of one flight test."""
from __future__ import annotations

import pandas as pd
import pytest


def test_pooled_table_counts_the_p_values_of_every_dataset_and_the_noise_only_verdicts():
    """Two datasets, the innovations and the plain series: the shares below 0.05, 0.01 and 0.001 are over all the
    p-values of a series (counted by hand), the verdicts over the datasets."""
    from pyomo_heli.studies.innovation_check import pooled_table

    p = {("a", "innovations"): [0.5, 0.04, 0.2, 0.9], ("b", "innovations"): [0.0005, 0.3, 0.7, 0.6],
         ("a", "plain"): [1e-9, 0.008, 0.5, 0.3], ("b", "plain"): [0.02, 0.6, 1e-4, 0.9]}
    tests = pd.concat([pd.DataFrame({"p": v, "model": "truth model", "whiteness_of": s, "dataset": d})
                       for (d, s), v in p.items()], ignore_index=True)
    summary = pd.DataFrame([{"dataset": d, "model": "truth model", "whiteness of": s,
                             "noise only": s == "innovations" and d == "a"} for d, s in p])
    rows = pooled_table(summary, tests).set_index("whiteness of")
    inn, plain = rows.loc["innovations"], rows.loc["plain"]
    assert inn["datasets"] == 2 and inn["tests"] == 8 and inn["noise only (datasets)"] == 1
    assert inn["p < 0.05 [%]"] == pytest.approx(25.0) and inn["p < 0.01 [%]"] == pytest.approx(12.5)
    assert inn["p < 0.001 [%]"] == pytest.approx(12.5)
    assert plain["p < 0.05 [%]"] == pytest.approx(50.0) and plain["p < 0.01 [%]"] == pytest.approx(37.5)
    assert plain["p < 0.001 [%]"] == pytest.approx(25.0) and plain["noise only (datasets)"] == 0
