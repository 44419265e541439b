"""The accelnav run file: one NPZ that each stage reads and extends.

Format ``accelnav-run/2`` (numpy ``.npz``, no pickled objects; stored, not compressed, unless the
user asks for compression):

========================  =====================  ===============================================
key                       shape, dtype           meaning
========================  =====================  ===============================================
``format``                (), str                ``"accelnav-run/3"`` (or ``/2``, ``/1``, see below)
``model_toml``            (), str                the model file's text (the run is self-contained)
``model_source``          (), str                where that text came from
``t``                     (N,), float64          sample time, s
``axis_names``            (n_axes,), str         axis names, in column order
``accel``                 (N, n_axes), float64   measured acceleration, m/s^2 (the filter's z)
``clipped``               (N, n_axes), bool      sample not used by the filter (rail, bad capture)
``code``                  (N, n_axes), int32     raw ADC codes (analog parts)
``t1``, ``t2``            (N, n_axes), int32     raw timer counts (duty-cycle parts)
``r u a eps``             (N, n_axes), float64   simulated truth (``accelnav sim`` only)
``scenario``, ``seed``    ()                     simulation settings (``accelnav sim`` only)
``stance``                (N,), bool             the foot is on the ground (``walking`` scenario only)
``rest``                  (N,), bool             the body is still (rest scenarios only)
``sim_fixes``             (M, 4), float64        a scenario's position fixes [t, axis column, r, sigma]
                                                 (``accelnav sim`` only; smooth takes fixes from ``--fixes``)
``filt_x``                (n_axes, N, 4)         filter posterior x[k|k] = [r, u, a, eps] (a streamed smooth:
                                                 with ``--filter-states``)
``filt_sd``               (n_axes, N, 4)         its standard deviations
``filt_P``                (n_axes, N, 4, 4)      its covariance (on request)
``filt_x_prior``          (n_axes, N, 4)         filter prior x[k|k-1] (on request)
``filt_P_prior``          (n_axes, N, 4, 4)      its covariance (on request)
``smooth_x``              (n_axes, N, 4)         RTS-smoothed x[k|N-1]
``smooth_sd``             (n_axes, N, 4)         its standard deviations
``smooth_P``              (n_axes, N, 4, 4)      its covariance (on request)
``zupt``                  (N, n_axes), bool      samples whose zero-velocity update was applied
``fixes``                 (M, 4), float64        position fixes used: [t, axis column, r, sigma]
``fix_nis``               (M,), float64          each fix's NIS y^2 / S as the filter met it
``zupt_nis``              (K, 4), float64        zero-velocity updates' NIS: [t, axis column, y^2 / S, 1 for
                                                 the first update of its rest]; ``/3`` keeps each rest's
                                                 first update alone (what the NIS checks read; /3 files
                                                 written before 2026-11-29 keep every
                                                 update), the others every update
``zupt_candidates``       (K, 3), float64        ``--zupt auto``'s candidate rests: [start_s, end_s, accepted]
========================  =====================  ===============================================

Versions: ``/3`` is what filter and smooth write by default, the need and no more: ``t``, ``axis_names``,
the model, and of each stage written ``*_x`` and ``*_sd`` as (n_axes, N, 2) float32, [r, u] and their
standard deviations (float32: 24-bit mantissa, 6e-8 relative, 0.6 mm at 10 km), with the aids' small
arrays (and the ``zupt`` mask); no echo of the input. That is 8 + 16 n_axes bytes per sample (plus
n_axes with rests): 20 B per sample per axis at 2 axes, 24 at one, against 77 for ``/2`` with its echo.
``--full`` writes ``/2``, ``--covariances`` ``/1``. ``/1`` always held the full covariances beside the
means. ``/2`` holds the standard deviations ``*_sd`` and the covariances only when asked
(``--covariances``: at 1e6 samples they were three quarters of the time and of the file). A file whose
every stage has its covariance is written as ``/1``, so that older readers still take it;
:func:`load_run` reads all three and adds the ``*_sd`` of a ``/1`` file.

:func:`export_csv` writes the per-sample columns (not the covariances, only
their standard deviations) as CSV for spreadsheets and other tools.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from accelnav.errors import UserError
from accelnav.fileio import atomic_output, excerpt, load_npz
from accelnav.model.load import Model, ModelError, loads_model

FORMAT = "accelnav-run/2"
FORMAT_V1 = "accelnav-run/1"
FORMAT_V3 = "accelnav-run/3"
FORMATS = (FORMAT, FORMAT_V1, FORMAT_V3)
COMPACT_KEYS = ("t", "axis_names", "zupt", "fixes", "fix_nis", "zupt_nis", "zupt_candidates")
STATE = ("r", "u", "a", "eps")
STAGES = ("filt", "smooth")


def save_run(path: str | Path, arrays: dict[str, np.ndarray], model: Model, *, compress: bool = False) -> None:
    """Write ``arrays`` and the model's text to ``path`` atomically (write, then rename).

    Stored uncompressed unless ``compress``: deflate ran at a few MB/s, most of a smooth's time, for a
    file of float64 noise that shrinks by a few per cent. The format is the oldest that holds the
    contents (see the module docstring).
    """
    data = dict(arrays)
    v1 = all(f"{st}_P" in data for st in STAGES if f"{st}_x" in data)
    v3 = "accel" not in data
    data["format"] = np.array(FORMAT_V3 if v3 else FORMAT_V1 if v1 else FORMAT)
    data["model_toml"] = np.array(model.text)
    data["model_source"] = np.array(str(model.source))
    with atomic_output(path) as fh:
        (np.savez_compressed if compress else np.savez)(fh, **data)


def compact(arrays: dict[str, np.ndarray], stages: tuple[str, ...] = STAGES) -> dict[str, np.ndarray]:
    """The ``/3`` contents of a run (see the module notes): r, u and their sds at float32 of ``stages``, no
    input echo, of ``zupt_nis`` each rest's first update."""
    out = {k: arrays[k] for k in COMPACT_KEYS if k in arrays}
    if "zupt_nis" in out:  # each rest's first update, the NIS checks' evidence: the later ones were 32 B an update
        out["zupt_nis"] = out["zupt_nis"][out["zupt_nis"][:, 3] == 1]
    for st in stages:
        if f"{st}_x" in arrays:
            out[f"{st}_x"] = np.asarray(arrays[f"{st}_x"][..., :2], dtype=np.float32)
            out[f"{st}_sd"] = np.asarray(state_sd(arrays, st)[..., :2], dtype=np.float32)
    return out


def state_sd(arrays: dict[str, np.ndarray], stage: str) -> np.ndarray:
    """(n_axes, N, 4) standard deviations of ``stage`` ("filt" or "smooth"), from whichever key holds them."""
    if f"{stage}_sd" in arrays:
        return arrays[f"{stage}_sd"]
    return np.sqrt(np.einsum("akii->aki", arrays[f"{stage}_P"]))


def load_run(path: str | Path) -> tuple[dict[str, np.ndarray], Model]:
    """Read a run file; returns (arrays, model). Refuses anything else with one line."""
    path = Path(path)
    arrays = load_npz(path, then=", so not an accelnav run file")  # sizes checked before inflating
    fmt = str(arrays.get("format", ""))
    if fmt not in FORMATS:
        raise UserError(
            f"{path}: format is {excerpt(fmt or 'missing')}; accepted: {' or '.join(map(repr, FORMATS))} "
            "(written by accelnav sim)"
        )
    v3 = fmt == FORMAT_V3  # no input echo: accel and clipped only if they were asked for
    for key in ("model_toml", "t", "axis_names") + (() if v3 else ("accel", "clipped")):
        if key not in arrays:
            raise UserError(f"{path}: key {key!r} is missing; the file is damaged or not from accelnav")
    try:
        model = loads_model(str(arrays["model_toml"]), source=f"{path}:model_toml")
    except ModelError as exc:
        raise UserError(str(exc)) from None
    if "accel" in arrays and arrays["accel"].ndim != 2:
        raise UserError(f"{path}: 'accel' has shape {arrays['accel'].shape}; accepted: (N, n_axes)")
    n, n_axes = len(arrays["t"]), len(arrays["axis_names"])
    if n == 0:
        raise UserError(f"{path}: 0 samples; nothing to process (was the device silent?)")
    shapes = {"t": (n,), "accel": (n, n_axes), "clipped": (n, n_axes)}
    if any(k in arrays and arrays[k].shape != v for k, v in shapes.items()):
        raise UserError(f"{path}: array shapes disagree (t, accel, clipped, axis_names); the file is damaged")
    for st in STAGES:
        if f"{st}_x" not in arrays:
            continue
        if f"{st}_sd" not in arrays and f"{st}_P" not in arrays:
            raise UserError(f"{path}: {st}_x without {st}_sd or {st}_P; the file is damaged")
        if f"{st}_sd" not in arrays:  # a /1 file: its sds from the covariances
            arrays[f"{st}_sd"] = state_sd(arrays, st)
        k = 2 if v3 else 4
        if arrays[f"{st}_x"].shape != (n_axes, n, k) or arrays[f"{st}_sd"].shape != (n_axes, n, k):
            raise UserError(f"{path}: {st}_x or {st}_sd is not (n_axes, N, {k}); the file is damaged")
    return arrays, model


def export_csv(path: str | Path, arrays: dict[str, np.ndarray]) -> None:
    """Write one row per sample: time, then per axis the raw input, truth, filter and smoother columns."""
    cols = csv_columns(arrays)
    table = np.column_stack([c for _, c in cols])
    with atomic_output(path, flag="--csv") as fh:
        np.savetxt(fh, table, delimiter=",", header=",".join(n for n, _ in cols), comments="", fmt="%.10g")


def csv_columns(arrays: dict[str, np.ndarray]) -> list[tuple[str, np.ndarray]]:
    """(name, column) of every per-sample quantity, t_s first: what export_csv writes and to_dataframe shows."""
    cols: list[tuple[str, np.ndarray]] = [("t_s", arrays["t"])]
    for j, name in enumerate(str(a) for a in arrays["axis_names"]):
        for raw in ("code", "t1", "t2"):
            if raw in arrays:
                cols.append((f"{name}_{raw}", arrays[raw][:, j]))
        if "accel" in arrays:  # a /3 file does not echo its input
            cols.append((f"{name}_accel", arrays["accel"][:, j]))
            cols.append((f"{name}_clipped", arrays["clipped"][:, j].astype(int)))
        for s in STATE:
            if s in arrays:
                cols.append((f"{name}_true_{s}", arrays[s][:, j]))
        for stage in ("filt", "smooth"):
            if f"{stage}_x" in arrays:
                x = arrays[f"{stage}_x"][j]
                sd = state_sd(arrays, stage)[j]
                for i, s in enumerate(STATE[: x.shape[-1]]):
                    cols.append((f"{name}_{stage}_{s}", x[:, i]))
                    cols.append((f"{name}_{stage}_{s}_sd", sd[:, i]))
    return cols
