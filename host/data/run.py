"""The run as the library hands it out: the run file's arrays, with ways out to pandas, NPZ and CSV.

A ``Run`` is a ``dict`` of numpy arrays (keys as in :mod:`accelnav.data.runfile`), so every stage that
takes the arrays takes it unchanged; the methods only add ways out. pandas is imported only by
:meth:`Run.to_dataframe`, and only if it is installed.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from accelnav.data.runfile import csv_columns, export_csv, save_run
from accelnav.errors import UserError

if TYPE_CHECKING:
    import pandas

    from accelnav.model.load import Model


def pandas_or_error():
    """pandas, or one line saying how to get it."""
    try:
        import pandas
    except ImportError:
        raise UserError("to_dataframe needs pandas, which is not installed: pip install pandas") from None
    return pandas


class Run(dict):
    """One run: ``t`` (N,), ``axis_names``, ``accel`` (N, n_axes) m/s^2, ``clipped``, and what each stage adds
    (``filt_x``, ``smooth_x`` (n_axes, N, 4) = [r, u, a, eps], their covariances, ``zupt``, ``fixes``, ...)."""

    @property
    def t(self) -> np.ndarray:
        return self["t"]

    @property
    def axis_names(self) -> list[str]:
        return [str(a) for a in self["axis_names"]]

    @property
    def accel(self) -> np.ndarray:
        return self["accel"]

    def position(self, stage: str = "smooth") -> np.ndarray:
        """(N, n_axes) position [m] estimated by ``stage`` ("smooth" or "filt")."""
        key = f"{stage}_x"
        if key not in self:
            raise UserError(f"the run has no {key}: run {'smooth_run' if stage == 'smooth' else 'filter_run'} first")
        return np.asarray(self[key][:, :, 0]).T

    def to_dataframe(self) -> pandas.DataFrame:
        """One row per sample, indexed by t [s]; the columns of :meth:`to_csv` (standard deviations as ``*_sd``)."""
        pd = pandas_or_error()
        cols = csv_columns(self)
        frame = pd.DataFrame({name: col for name, col in cols[1:]}, index=pd.Index(cols[0][1], name="t_s"))
        return frame

    def to_npz(self, path: str | Path, model: Model) -> None:
        """An accelnav run file (with the model's text), which ``load_run`` and every command read."""
        save_run(path, self, model)

    def to_csv(self, path: str | Path) -> None:
        """One row per sample: time, then per axis the input, truth, filter and smoother columns."""
        export_csv(path, self)


def as_run(arrays: dict[str, Any]) -> Run:
    return arrays if isinstance(arrays, Run) else Run(arrays)
