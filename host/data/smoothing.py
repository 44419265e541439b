"""filter and smooth of a file: the input opened (streamed or whole), the engine run, the outputs written.

The engine (:mod:`accelnav.estimate.engine`) decides how the passes are cut; here only how the input
is read: a CSV, gzip CSV or uncompressed NPZ whose numbers exceed what one input may hold in memory
(:data:`STREAM_ABOVE` without a budget, or any uncompressed NPZ; with a budget, when the whole-array run would
exceed it) is streamed
(:func:`accelnav.data.stream.open_stream`); anything else is read whole by
:func:`accelnav.data.inputs.read_input`. Fixes and given rests (intervals, an NPZ mask) are placed on the
run's clock a piece at a time and stream with it; what needs the input in memory (the rest decision of
``--zupt auto``, a per-sample CSV mask, what the engine runs as one chunk) is refused over the input limit in
one line before anything is parsed (the rest decision also over the memory budget: engine.rest_bytes). A chunked
run's rest decision reads a streamed input whole once where it fits the budget, else a chunk at a time
(zupt.decide_rests_read); the chunked passes read the stream again.
"""

from __future__ import annotations

import logging
import os
import shutil
from collections.abc import Sequence
from contextlib import ExitStack
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from accelnav.data.inputs import read_input
from accelnav.data.runfile import FORMAT, FORMAT_V1, FORMAT_V3, compact, export_csv, save_run
from accelnav.errors import UserError
from accelnav.estimate import engine
from accelnav.estimate.chunked import disk_needed, whole_bytes
from accelnav.fileio import atomic_output, check_output, free_bytes, input_limit, output_target, write_text
from accelnav.model.load import Model, load_model
from accelnav.progress import note


def smooth_file(
    path: str | Path,
    out: str | Path,
    model: Model | str | Path | None = None,
    *,
    job: engine.Job | None = None,
    fixes: str | Path | None = None,
    zupt: str | Path | None = None,
    zupt_params=None,
    zupt_report: str | Path | None = None,
    csv: str | Path | None = None,
    compress: bool = False,
    rests_decided=None,
    **read,
) -> engine.Outcome:
    """Filter or smooth the recording or run file ``path`` as ``job`` says; write the run file ``out``
    (and ``csv``, ``zupt_report``). ``fixes``: a fixes CSV (accelnav.estimate.fixes.read_fixes); ``zupt``:
    "auto" (the rest decision, with ``zupt_params``) or a rest file (accelnav.estimate.zupt.read_zupt_file);
    ``rests_decided(rest)``: called with the rest stage's engine.RestOutcome as soon as it is decided (before
    ``--tune``); ``read``: read_input's keywords (axes, time_column, rate_hz, time_unit, unit, allow_gaps).
    Returns the engine's :class:`~accelnav.estimate.engine.Outcome`; ``Outcome.written`` lists the files."""
    from accelnav.estimate import zupt as zu

    job = engine.Job() if job is None else job
    # the output rule against every file this run reads (a fleet's output named like its input, say)
    given = [path, fixes, None if zupt == "auto" else zupt, model if isinstance(model, str | Path) else None]
    for p, flag in ((out, "--out"), (csv, "--csv"), (zupt_report, "--zupt-report")):
        if p is not None:
            check_output(p, flag, inputs=given)
    if zupt_report is not None and zupt != "auto":
        raise UserError("--zupt-report: only with --zupt auto (it lists the detector's candidates)")
    in_memory = job.in_memory
    smooth = "smooth" in job.stages
    rests = None
    if smooth and zupt is not None:
        rests = engine.Rests(zupt_params, detect=zupt == "auto", decided=rests_decided)
    # the plan before any reading: what cannot be done within the budget is refused now
    job = replace(job, in_memory=in_memory, rests=rests, fixes=[] if smooth and fixes is not None else None,
                  full=job.full or job.covariances)  # fmt: skip
    whole = _whole_reasons(job, zupt)
    workdir = output_target(out).workdir  # the output rule (accelnav.fileio): where its temporaries go
    out = Path(out)
    with ExitStack() as stack:
        source, model = _open(path, model, job, whole, read, workdir, stack)
        if job.aided:  # placed on the run's clock, read a piece at a time (the input is not held whole for them)
            names = [str(a) for a in source.axis_names]
            if fixes is not None:
                from accelnav.estimate.fixes import read_fixes

                job = replace(job, fixes=read_fixes(fixes, source.clock(), names))
            if zupt is not None and zupt != "auto":
                spans = zu.read_rest_spans(zupt, source.clock(), names)
                job = replace(job, rests=replace(rests, spans=spans))
        fmt = FORMAT_V1 if job.covariances else FORMAT if job.full else FORMAT_V3  # as save_run names them
        outcome = engine.run(model, source, job, out, workdir=workdir, run_format=fmt)
        if outcome.arrays is not None and job.aided and job.checks and "smooth" in job.stages:
            outcome.checks = _checks(outcome, source.whole(), job.fixes)
        elif job.aided and job.checks and "smooth" in job.stages:
            outcome.checks = _file_checks(out, tuned=outcome.tune is not None)
        written = [out]
        if outcome.arrays is not None:
            kept = outcome.arrays if job.full else compact(outcome.arrays, job.stages)
            save_run(out, kept, outcome.model, compress=compress)
            if csv is not None:
                export_csv(csv, outcome.arrays)
        else:  # written in place by the chunked passes: the CSV and the deflated copy read it back in pieces
            if csv is not None:
                csv_in_pieces(out, csv)
            if compress:
                deflate_in_pieces(out)
        if csv is not None:
            written.append(Path(csv))
        if zupt_report is not None and outcome.rests is not None:
            write_text(zupt_report, zu.report_csv(outcome.rests.decisions, source.times_at), flag="--zupt-report")
            written.append(Path(zupt_report))
        outcome.written = written
        return outcome


STREAM_ABOVE = 1 << 30  # bytes of input in memory above which an input is streamed, without a budget given
PIECE = 1 << 16  # samples per piece of csv_in_pieces (and 64 MiB of bytes per piece of deflate_in_pieces)


def deflate_in_pieces(path: Path) -> None:
    """Rewrite the stored NPZ ``path`` deflated, member by member, a piece at a time (bounded memory)."""
    import zipfile

    with zipfile.ZipFile(path) as src, atomic_output(path) as fh, zipfile.ZipFile(fh, "w", zipfile.ZIP_DEFLATED) as dst:
        for info in src.infolist():
            with src.open(info) as r, dst.open(info.filename, "w", force_zip64=True) as w:
                shutil.copyfileobj(r, w, PIECE << 10)


def csv_in_pieces(npz: Path, csv: str | Path) -> None:
    """export_csv of a run file written by the chunked passes, reading ``PIECE`` samples of it at a time."""
    import zipfile

    from accelnav.data.runfile import csv_columns
    from accelnav.estimate.chunked import _stored_member
    from accelnav.fileio import pread_exact

    with zipfile.ZipFile(npz) as zf:
        names = [i.filename.removesuffix(".npy") for i in zf.infolist()]
        members = {k: _stored_member(npz, zf, k) for k in names}
    n = members["t"][1][0]
    small = {k: np.load(npz)[k] for k in ("axis_names",)}
    n_axes = len(small["axis_names"])
    per_sample = {k: m for k, m in members.items() if m[1][:1] == (n,) or m[1][:2] == (n_axes, n)}
    fd = os.open(npz, os.O_RDONLY)
    try:
        with atomic_output(csv, "w", "--csv") as fh:
            for s in range(0, n, PIECE):
                e = min(s + PIECE, n)
                piece = dict(small)
                for k, (off, shape, dtype) in per_sample.items():
                    if shape[:1] == (n,) and k != "axis_names":
                        row = int(np.prod(shape[1:], dtype=np.int64)) * dtype.itemsize
                        buf = np.empty((e - s, *shape[1:]), dtype=dtype)
                        pread_exact(fd, buf, off + s * row)
                    else:  # (n_axes, N, k): a slice per axis
                        row = int(np.prod(shape[2:], dtype=np.int64)) * dtype.itemsize
                        buf = np.empty((shape[0], e - s, *shape[2:]), dtype=dtype)
                        for j in range(shape[0]):
                            pread_exact(fd, buf[j], off + (j * n + s) * row)
                    piece[k] = buf
                cols = csv_columns(piece)
                header = ",".join(c for c, _ in cols) if s == 0 else ""
                np.savetxt(fh, np.column_stack([c for _, c in cols]), delimiter=",", header=header, comments="",
                           fmt="%.10g")  # fmt: skip
    finally:
        os.close(fd)


def _checks(outcome: engine.Outcome, inputs: dict, fixes):
    """The aids' consistency checks of a run smoothed in memory (accelnav.estimate.pipeline.smooth_checks); a
    model just tuned is not advised to be tuned again."""
    from accelnav.estimate.pipeline import smooth_checks

    r = outcome.rests
    kw = dict(rest=None, zupt_params=None, rest_sigma=None)
    if r is not None:
        kw = dict(rest=r.mask, zupt_params=r.params, rest_sigma=r.sigma)
    # the rests' review (Outcome.rests.review) is said where the rests are decided, not among these lines
    return smooth_checks(outcome.arrays, outcome.model, inputs, fixes, tuned=outcome.tune is not None, **kw)


def _file_checks(out: Path, tuned: bool):
    """The aids' NIS checks of a run written chunk by chunk, from its members fix_nis and zupt_nis (one row per
    rest, or per rest update with --full: read a piece at a time); the held-out fixes and the anchor check
    re-smooth or read the run whole and are not made here."""
    import zipfile

    from accelnav.estimate.chunked import _stored_member
    from accelnav.estimate.consistency import SmoothChecks, first_rest_nis, nis_check
    from accelnav.fileio import pread_exact

    with zipfile.ZipFile(out) as zf:
        members = {k: _stored_member(out, zf, k) for k in ("t", "fix_nis", "zupt_nis")}
    fd = os.open(out, os.O_RDONLY)
    try:
        t0 = np.empty(1)
        pread_exact(fd, t0, members["t"][0])
        fix = np.empty(members["fix_nis"][1])
        pread_exact(fd, fix, members["fix_nis"][0])
        offset, (rows, _), _ = members["zupt_nis"]
        rest = []
        for s in range(0, rows, PIECE):
            piece = np.empty((min(PIECE, rows - s), 4))
            pread_exact(fd, piece, offset + 32 * s)
            rest.append(first_rest_nis(piece, float(t0[0])))
    finally:
        os.close(fd)
    kinds = (("fixes", fix), ("rests", np.concatenate(rest) if rest else np.zeros(0)))
    return SmoothChecks(tuple(nis_check(kind, v) for kind, v in kinds if len(v)), None, None, tuned)


def _whole_reasons(job: engine.Job, zupt) -> str:
    """The flags for which the input is read whole, in words: the rest decision reads every sample, and a rest
    mask given as CSV is read whole (fixes, rest intervals and an NPZ mask are placed a piece at a time)."""
    from accelnav.estimate.zupt import rest_file_kind

    given = zupt is not None and zupt != "auto"
    held = zupt == "auto" or (given and "smooth" in job.stages and rest_file_kind(zupt) == "mask")
    flags = [f for f, v in (("--zupt", zupt if held else None),) if v is not None]
    flags += [f for f in job.in_memory if f not in flags]
    return ", ".join(flags)


def input_size(path, model: Model | str | Path | None, axes) -> tuple[int, int] | None:
    """(estimated rows, axes) of a CSV, gzip CSV or NPZ input from its size and first bytes, before it is
    parsed; None for another input (a recorder log, an unreadable file: read whole, which says why)."""
    from accelnav.data.stream import estimate_rows, npz_rows

    rows = estimate_rows(path)
    if rows is None:
        rows = npz_rows(path)
    if rows is None:
        return None
    if axes:
        return rows, len(axes)
    m = model if isinstance(model, Model) else load_model(model)
    return rows, len(m.axes)


def _open(path, model, job: engine.Job, whole: str, read: dict, workdir: Path, stack: ExitStack):
    """(engine.Source, model): the input streamed when it is large and nothing needs it whole, else read whole."""
    if not isinstance(path, (str, Path)):
        run, m = read_input(path, model, **read)
        return engine.Source.of(run, "<arrays>"), m
    size = input_size(path, model, read.get("axes"))
    if size is not None:
        rows, n_axes = size
        p = engine.plan(rows, n_axes, job, label=str(path))  # refuses before reading what the budget cannot do
        if p.whole and not whole and (job.covariances or job.tune or job.envelope):  # within the budget: one chunk
            whole = "--covariances" if job.covariances else "--tune" if job.tune else "--plots"  # in memory, read whole
        held, limit = rows * 8 * (2 + n_axes), input_limit()
        # with a budget given, an input whose whole-array run exceeds it streams; without one, an input over
        # STREAM_ABOVE in memory (a store read again three times costs more than reading it whole once)
        # without a budget an uncompressed NPZ, its own store read in place by rows, streams at any length:
        # checked block by block and never held whole (1e7 samples, 2 axes: 6.6 s of CPU against 7.7 read
        # whole, and 1.09 GB peak against 1.30, measured; the same output file)
        big = whole_bytes(rows, n_axes) > job.budget if job.budget is not None else held > STREAM_ABOVE or _is_npz(path)
        # the rest decision alone of a chunked run reads every sample (the stream read whole once and dropped, or
        # a chunk at a time over the budget)
        decided = whole == "--zupt" and not p.whole and job.rests is not None and job.rests.detect and not job.full
        if (big or held > limit) and whole:
            if held > limit:
                raise UserError(
                    f"{path}: about {rows} rows x {n_axes} axes need about {held / 1e9:.3g} GB in memory; {whole} "
                    f"need(s) every sample in memory, which may take {limit / 1e9:.3g} GB here "
                    "(ACCELNAV_MAX_INPUT_BYTES); plain smooth streams any length"
                )
            if decided:
                source = _stream(path, model, job, read, rows, n_axes, workdir, stack)
                if source is not None:
                    return source
        elif big or held > limit:
            source = _stream(path, model, job, read, rows, n_axes, workdir, stack)
            if source is not None:
                return source
    run, m = read_input(path, model, **read)
    return engine.Source.of(run, str(path)), m


def _is_npz(path) -> bool:
    try:
        with open(path, "rb") as fh:
            return fh.read(2) == b"PK"
    except OSError:
        return False  # the whole reader says why


def _stream(path, model, job: engine.Job, read: dict, rows: int, n_axes: int, workdir: Path, stack: ExitStack):
    """The input opened as a stream (its store in ``workdir``), or None when only the whole reader takes it."""
    from accelnav.data.stream import NotStreamed, open_stream

    smooth = "smooth" in job.stages
    # the output as it will be laid out (compact or full, covariances, the aids' marks); aided axes take the
    # general path's wider store
    stages = 2 if smooth and job.covariances else len(job.stages)
    need = rows * 8 * (2 + n_axes) + disk_needed(
        rows, n_axes, n_axes if smooth and job.aided else 0, n_stages=stages, store=smooth, full=job.full,
        covariances=job.covariances, marks=smooth and (job.aided or job.covariances),
    )  # fmt: skip
    free = free_bytes(workdir)
    if need > free:
        raise UserError(
            f"{path}: about {rows} rows x {n_axes} axes need about {need / 1e9:.3g} GB of disk in {workdir} "
            f"to be smoothed in bounded memory; {free / 1e9:.3g} GB are free"
        )
    try:
        st = stack.enter_context(open_stream(path, model, workdir=workdir, **read))
    except NotStreamed as exc:
        note(f"{exc}; reading it whole")
        return None
    t_ends = (st.t0, st.t0 + (st.n - 1) * st.Ts)
    return engine.Source(st.n, st.axis_names, st, None, str(path), t_ends, streamed=st.kind), st.model


def summary_arrays(outcome: engine.Outcome) -> tuple[dict[str, np.ndarray], int]:
    """(arrays, samples) for a summary of the run: the whole run, or its outputs' ends when it was chunked."""
    if outcome.arrays is not None:
        return outcome.arrays, outcome.n
    t = np.array(outcome.t_ends)
    return {"t": t, "axis_names": outcome.axis_names, "clipped": outcome.clipped[None, :], **outcome.ends}, outcome.n


@dataclass(frozen=True)
class FileResult:
    """One input of :func:`smooth_files`: where it went, and on failure the one-line reason."""

    path: str
    out: str
    ok: bool
    message: str  # "N samples, S s" or the error's line
    seconds: float
    pid: int = field(default_factory=os.getpid)  # the process that smoothed it (how a fleet's work was shared)


def fleet_outputs(paths: Sequence[str | Path], out_dir: str | Path) -> list[Path]:
    """``out_dir/<input name without its extensions>.npz`` for each input; two inputs that would share an
    output are refused in one line before any work."""
    out_dir = Path(out_dir)
    outs, seen = [], {}
    for p in map(Path, paths):
        stem = p.name.split(".")[0] or p.name
        out = out_dir / f"{stem}.npz"
        if out in seen:
            raise UserError(f"--out-dir: {seen[out]} and {p} would both write {out}; rename one of them")
        seen[out] = p
        outs.append(out)
    return outs


def smooth_one(path: str | Path, out: str | Path, kw: dict) -> FileResult:
    """:func:`smooth_file` of one input of a fleet, its failure caught and said in one line (a worker's task:
    top level, so that a process pool or Dask can send it)."""
    import time

    t0 = time.monotonic()
    try:
        outcome = smooth_file(path, out, **kw)
    except UserError as exc:
        return FileResult(str(path), str(out), False, str(exc), time.monotonic() - t0)
    except Exception as exc:  # a file that breaks something else must not stop the others
        return FileResult(str(path), str(out), False, f"{type(exc).__name__}: {exc}", time.monotonic() - t0)
    sec = time.monotonic() - t0
    return FileResult(str(path), str(out), True, f"{outcome.n} samples, {sec:.2f} s", sec)


def smooth_batch(pairs: Sequence[tuple[str | Path, str | Path]], kw: dict | None = None) -> list[FileResult]:
    """:func:`smooth_one` over ``pairs`` of (input, output) in turn, in a process given to the fleet (a Dask
    partition's task, ``bag.map_partitions(smooth_batch, kw)``: one task per partition, not per file; the
    recipe, with the settings that share the partitions among the processes, is in docs/python.rst), the
    process set up as the command's workers are (:func:`accelnav.resources.reuse_freed_memory`)."""
    from accelnav.resources import MALLOC_ENV, reuse_freed_memory

    global _said_malloc
    if not reuse_freed_memory() and not _said_malloc:
        given = [k for k in MALLOC_ENV if k in os.environ]
        if given:  # said once per process: a fleet's worker runs many partitions
            _said_malloc = True
            logging.getLogger(__name__).warning(
                "%s set in this worker (dask.distributed's workers set MALLOC_TRIM_THRESHOLD_ by default): glibc "
                "keeps it, and each file's arrays are fresh pages, about twice the CPU of a 1e5-row file (measured); "
                "unset it for the workers as docs/python.rst says ('Files of any length, and many of them')",
                ", ".join(given),
            )
    kw = {} if kw is None else kw
    return [smooth_one(p, o, kw) for p, o in pairs]


_said_malloc = False  # smooth_batch's warning that the environment's malloc settings stand, given in this process


def _fleet_worker(threads: int = 1) -> None:
    """A worker process of :func:`smooth_files`: quiet (the parent reports each file; a worker's notes and
    bars would interleave), its share of the CPUs (accelnav.resources.threads), and set up for file after
    file as the command's process is (:func:`accelnav.resources.reuse_freed_memory`)."""
    from accelnav import progress, resources

    progress.set_verbosity(0)
    os.environ[resources.THREADS_ENV] = str(threads)
    logging.getLogger("accelnav").setLevel(logging.ERROR)
    resources.reuse_freed_memory()


def start_method() -> str:
    """How the workers start: forked where that is safe (Linux, and no other thread of this process's Python
    that could hold a lock across the fork): a copy of this process, its imports done, ready at once; else
    spawned, each importing numpy and accelnav afresh (0.45 s of CPU per worker before its first file, measured:
    with 1e5-row files at 40 ms each, a tenth of a 200-file fleet's time on 2 cores). The command's workers
    start so, and Dask's local processes in the recipe of docs/python.rst (``multiprocessing.context``)."""
    import sys
    import threading

    return "fork" if sys.platform == "linux" and threading.active_count() == 1 else "spawn"


def smooth_files(
    paths: Sequence[str | Path], out_dir: str | Path, *, jobs: int = 1, done=None, **kw
) -> list[FileResult]:
    """:func:`smooth_file` over many inputs, each to ``out_dir`` (:func:`fleet_outputs`), ``jobs`` at a time
    in worker processes (concurrent.futures, started as :func:`start_method` says; a budget given is shared
    among them). A failed input is reported in its :class:`FileResult` and the others go on. ``done(result)``
    is called as each finishes.
    For a cluster, map :func:`smooth_batch` over partitions of the inputs with Dask (see docs/python.rst).
    With ``jobs`` = 1 the files are smoothed in this process, as it is: the command sets it up first
    (:func:`accelnav.resources.reuse_freed_memory`); a worker process is set up the same way."""
    from concurrent.futures import ProcessPoolExecutor, as_completed
    from multiprocessing import get_context

    from accelnav import resources

    if jobs < 1:
        raise UserError(f"--jobs: got {jobs}; accepted: 1 or more")
    outs = fleet_outputs(paths, out_dir)
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    job = kw.get("job") or engine.Job()
    kw["job"] = replace(job, budget=engine.budget_bytes(job.budget) // jobs if job.budget else None)
    results: dict[int, FileResult] = {}
    if jobs == 1:
        for i, (p, o) in enumerate(zip(paths, outs, strict=True)):
            results[i] = smooth_one(p, o, kw)
            if done is not None:
                done(results[i])
    else:
        share = max(1, resources.threads() // jobs)  # the CPUs shared among the jobs (a bad setting refused here)
        with ProcessPoolExecutor(
            jobs, mp_context=get_context(start_method()), initializer=_fleet_worker, initargs=(share,)
        ) as pool:
            futures = {pool.submit(smooth_one, p, o, kw): i for i, (p, o) in enumerate(zip(paths, outs, strict=True))}
            for f in as_completed(futures):
                results[futures[f]] = f.result()
                if done is not None:
                    done(results[futures[f]])
    return [results[i] for i in range(len(outs))]
