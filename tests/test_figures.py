"""Figures: pareto_front labels clear of the markers, RMS and Theil coefficient on validation plots,
--figure-format."""
from __future__ import annotations

import math
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.text import Text

from pyomo_heli.pareto.result import IdentificationResult
from pyomo_heli.report import plots

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.parametrize("case", ["case1", "case2"])
def test_pareto_front_labels_do_not_cover_markers(case):
    """Every point label (A, B, U, C) is drawn clear of every marker of its panel (bounding boxes in pixels)."""
    r = IdentificationResult.load(ROOT / "tests" / "results" / case)  # copies of the committed runs
    fig = plots.plot_pareto_front(r.front, r.utopia, r.nadir, r.chosen, r.direct)
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    renderer = canvas.get_renderer()
    for ax in fig.axes:
        labels = [t for t in ax.texts if t.get_text() in ("A", "B", "U", "C")]
        assert sorted(t.get_text() for t in labels) == ["A", "B", "C", "U"]
        markers = []
        for line in ax.get_lines():
            if line.get_marker() in (None, "None", "", " "):
                continue
            r_px = line.get_markersize() / 72 * fig.dpi / 2  # marker radius in pixels
            for xy in ax.transData.transform(np.column_stack(line.get_data()).astype(float)):
                markers.append((xy, r_px))
        for t in labels:
            box = Text.get_window_extent(t, renderer)  # the label's box itself, without its arrow
            for (x, y), rad in markers:
                clear = (x + rad < box.x0 or x - rad > box.x1 or y + rad < box.y0 or y - rad > box.y1)
                assert clear, (case, t.get_text(), (x, y), box)


def test_theil_inequality_coefficient():
    t = np.linspace(0, 10, 1001)
    y = np.sin(t)
    assert plots.theil_inequality(y, y) == 0.0
    assert plots.theil_inequality(y, np.zeros_like(y)) == pytest.approx(1.0)
    assert plots.theil_inequality(y, 2 * y) == pytest.approx(1 / 3)  # rms(y) / (2 rms(y) + rms(y))
    assert plots.theil_inequality(y, -y) == pytest.approx(1.0)
    # the model on its own (finer) grid is taken at the data's times
    tm = np.linspace(0, 10, 4001)
    rms, tic = plots.fit_metrics(t, y, tm, np.sin(tm) + 0.1)
    assert rms == pytest.approx(0.1, rel=1e-3)
    assert tic == pytest.approx(0.1 / (np.sqrt(np.mean((y + 0.1) ** 2)) + np.sqrt(np.mean(y ** 2))), rel=1e-3)


def test_validation_plot_annotates_rms_and_theil():
    t = np.linspace(0, 10, 501)
    data = pd.DataFrame({"t": t, "q": 0.05 * np.sin(t), "theta": 0.02 * np.cos(t)})
    model = pd.DataFrame({"t": t, "q": 0.04 * np.sin(t), "theta": 0.02 * np.cos(t)})
    fig = plots.plot_validation({"m": data}, {"model": {"m": model}}, ("q", "theta"))
    texts = [tx.get_text() for ax in fig.axes for tx in ax.texts]
    rms_deg_s = math.degrees(np.sqrt(np.mean((0.01 * np.sin(t)) ** 2)))
    tic = np.sqrt(np.mean((0.01 * np.sin(t)) ** 2)) / (np.sqrt(np.mean((0.04 * np.sin(t)) ** 2))
                                                      + np.sqrt(np.mean((0.05 * np.sin(t)) ** 2)))
    assert f"RMS {rms_deg_s:.3g} deg/s, TIC {tic:.3f}" in texts
    assert "RMS 0 deg, TIC 0.000" in texts


def test_diagnose_writes_figures_in_the_format_asked(tmp_path):
    from pyomo_heli.cli import main

    res = tmp_path / "results"
    shutil.copytree(ROOT / "tests" / "results" / "m0_noise_small", res)
    out = tmp_path / "d"
    assert main(["diagnose", str(res), "--config", str(ROOT / "tests" / "configs" / "m0_noise_small.toml"),
                 "--out", str(out), "--no-residuals", "--figure-format", "svg"]) == 0
    svgs = sorted(p.name for p in out.glob("*.svg"))
    assert svgs == ["diagnosis_coherence.svg", "diagnosis_spectra.svg", "diagnosis_time.svg", "diagnosis_trim.svg",
                    "diagnosis_trim_forces.svg"]
    assert not list(out.glob("*.png"))
    assert (out / "diagnosis_trim.svg").read_text().lstrip().startswith("<?xml")
    assert "(diagnosis_trim.svg)" in (out / "diagnosis.md").read_text()
    assert "(diagnosis_trim_forces.svg)" in (out / "diagnosis.md").read_text()
    assert main(["diagnose", str(res), "--out", str(out), "--figure-format", "gif"]) == 2
