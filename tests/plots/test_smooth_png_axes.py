"""smooth.png of a real recording: the smoother's track fills its panel and time runs from the start (issue 25).

Checks the figure objects (limits, labels, tick offsets), not pixels."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import pytest
from conftest import MODELS

import accelnav
from accelnav.hil_sim.sim.sensor import simulate
from accelnav.model.load import load_model
from accelnav.plots.run import plot_run, plot_smoothing

FOOT = MODELS / "foot_imu.toml"
UNIX_START = 1732530000.0  # a recording stamped in Unix seconds, as loggers write
OFFSET = 1.0  # m/s^2


@pytest.fixture(scope="module")
def figures(tmp_path_factory):
    tmp_path = tmp_path_factory.mktemp("png")
    run = simulate(load_model(FOOT), "walking", 20.0, 5)
    accel = run.accel + OFFSET  # an offset the rests reveal to the smoother; double integration runs away on it
    lines = ["t,ax,ay"] + [f"{UNIX_START + ti:.3f},{a:.6f},{b:.6f}" for ti, (a, b) in zip(run.t, accel, strict=True)]
    (tmp_path / "rec.csv").write_text("\n".join(lines) + "\n")
    # what ``accelnav smooth rec.csv --model FOOT --zupt auto --plots DIR`` draws, through the library
    smoothed, model = accelnav.read_input(tmp_path / "rec.csv", FOOT, axes=["ax", "ay"], time_column="t")
    smoothed = accelnav.smooth_run(smoothed, model, rest=accelnav.detect_rests(smoothed, model))
    (tmp_path / "p").mkdir()
    kept, close = [], plt.close
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(plt, "close", lambda fig=None: kept.append(fig))  # keep each figure to look at
        plot_run(smoothed, model, tmp_path / "p" / "smooth.png")
        plot_smoothing(smoothed, model, tmp_path / "p")
    yield {f._suptitle.get_text(): f for f in kept}
    for f in kept:
        close(f)


def _smooth_png(figures):
    (fig,) = [f for title, f in figures.items() if title.startswith("accelnav:")]
    return fig


def test_time_runs_from_the_recordings_start(figures):
    for fig in figures.values():
        fig.canvas.draw()  # the tick offset is set when drawn
        for ax in fig.axes:
            if not ax.get_xlabel():
                continue
            assert ax.get_xlabel() == "time from the recording's start [s]"
            assert ax.xaxis.get_major_formatter().get_offset() == ""  # no "+1.73253e9"
            lo, hi = ax.get_xlim()
            assert lo < 1.0 and 19.0 < hi < 30.0


def test_double_integration_does_not_flatten_the_track(figures):
    fig = _smooth_png(figures)
    for ax in fig.axes:
        lines = {ln.get_label().split(" (")[0]: ln for ln in ax.get_lines()}
        if "double integration" not in lines or not ax.get_ylabel().startswith("position"):
            continue
        lo, hi = ax.get_ylim()
        smooth = lines["smoother +-1 sigma"].get_ydata()
        # the smoother's track spans a good part of the panel, not a flat line at the bottom
        assert np.ptp(smooth) > 0.3 * (hi - lo)
        assert lo <= smooth.min() and smooth.max() <= hi
        dr = lines["double integration"]
        if np.max(np.abs(dr.get_ydata())) > max(abs(lo), abs(hi)):
            assert "leaves the plot" in dr.get_label()
