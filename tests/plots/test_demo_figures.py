"""The demo's figures draw exactly the rows of its table: one curve per row (and the truth), named as the row."""

from __future__ import annotations

import numpy as np

from accelnav.estimate.pipeline import error_rows
from accelnav.plots import run as plots


def test_each_figure_has_one_curve_per_table_row_and_nothing_else(tmp_path, monkeypatch):
    t = np.arange(500) / 100.0
    truth = np.column_stack([0.5 * t, -0.2 * t])
    estimates = {  # as the demo's: double integration runs away, the others stay near the truth
        "double integration": np.stack([truth[:, 0] + 40 * t**2, truth[:, 1] - 30 * t**2]),
        "firmware filter": np.stack([truth[:, 0] + 0.3, truth[:, 1] - 0.2]),
        "smoother + ZUPT": np.stack([truth[:, 0] + 0.01 * t, truth[:, 1]]),
    }
    legends = {}
    save = plots._save

    def keep(plt, fig, path):
        legends[path.name] = [[x.get_text() for x in ax.get_legend().get_texts()] for ax in fig.axes]
        return save(plt, fig, path)

    monkeypatch.setattr(plots, "_save", keep)
    paths = plots.plot_estimates(t, ["x", "y"], truth, estimates, tmp_path, "test")
    assert [p.name for p in paths] == ["position.png", "position_error.png"]
    rows = error_rows(["x", "y"], truth, estimates)
    for j, axis in enumerate("xy"):
        named = [f"{r.method} (rms {r.rms:.3g} m)" for r in rows if r.axis == axis]
        for name in ("position.png", "position_error.png"):
            got = legends[name][j]
            assert [g.split(", leaves the plot")[0] for g in got if g != "truth"] == named, got
        assert legends["position.png"][j][0] == "truth"
        assert "leaves the plot" in legends["position_error.png"][j][0]  # the runaway row says how far it goes
