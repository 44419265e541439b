"""The checks every estimator makes on the arrays it is given, so that a library call cannot run a model
on data it was not made for (a 100 Hz model on 200 Hz data integrates twice the time: position off by
hundreds of metres, silently)."""

from __future__ import annotations

import numpy as np

from accelnav.errors import UserError
from accelnav.model.load import Model

REQUIRED = ("t", "axis_names", "accel", "clipped")
RATE_TOL = 0.01  # the median step may differ from the model's period by 1 % (the readers' tolerance)


def check_run(arrays, model: Model, where: str = "the run") -> None:
    """Refuse, in one line, arrays that lack a run's keys or shapes, or whose rate or axes are not the model's."""
    missing = [k for k in REQUIRED if k not in arrays]
    if missing and str(arrays.get("format", "")).endswith("/3"):  # the compact run file holds no input
        raise UserError(
            f"{where}: a run file as filter and smooth write it by default (accelnav-run/3) holds their output, "
            "not the recording; give the recording, or write this file with --full to filter or smooth it again"
        )
    if missing:
        keys = ", ".join(sorted(map(str, arrays))) or "none"
        raise UserError(
            f"{where}: no {', '.join(repr(k) for k in missing)} in the arrays (keys: {keys}); "
            "accepted: a run as read_input, load_run or simulate return it"
        )
    accel = np.asarray(arrays["accel"])
    names = [str(a) for a in np.asarray(arrays["axis_names"]).reshape(-1)]
    n = len(arrays["t"])
    if accel.ndim != 2 or accel.shape != (n, len(names)) or np.shape(arrays["clipped"]) != accel.shape:
        raise UserError(
            f"{where}: shapes t {np.shape(arrays['t'])}, accel {accel.shape}, clipped {np.shape(arrays['clipped'])} "
            f"for {len(names)} axes; accepted: t (N,), accel and clipped (N, n_axes)"
        )
    model_names = [a.name for a in model.axes]
    if names != model_names:
        raise UserError(f"{where}: axes {names} are not the model {model.source}'s {model_names}")
    if n > 2:
        step = float(np.median(np.diff(np.asarray(arrays["t"], dtype=np.float64))))
        if not abs(step * model.rate_hz - 1) <= RATE_TOL:
            raise UserError(
                f"{where}: the run is sampled at {1 / step:.6g} Hz but the model {model.source} has "
                f"sampling.rate_hz = {model.rate_hz:g} Hz"
            )
