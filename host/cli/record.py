"""``accelnav record`` and ``accelnav log info|export``: record a telemetry link, inspect and export the log."""

from __future__ import annotations

import json
import signal
import sys
from pathlib import Path

import numpy as np

from accelnav.cli.args import NO_STDOUT
from accelnav.data.logs import _decoded, log_run_arrays, log_summary
from accelnav.errors import UserError
from accelnav.fileio import atomic_output, check_output, output_target


def register(sub) -> None:
    p = sub.add_parser("record", help="record a telemetry link (serial port, pty, socket://, loop://) to a log")
    p.add_argument("port", metavar="PORT_OR_URL", help="/dev/ttyUSB0, /dev/pts/N, socket://HOST:PORT, ...")
    p.add_argument("--out", type=Path, required=True, help="log file to create")
    p.add_argument("--baud", type=int, default=921600, help="baud rate; default: 921600 (ignored by socket://)")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--manifest", type=Path, help="frame manifest (acnframe.json) the firmware was built with")
    src.add_argument("--model", type=Path, help="model file; its manifest is generated (default: the embedded model)")
    p.add_argument("--duration", type=float, default=None, help="stop after this many seconds")
    p.add_argument("--frames", type=int, default=None, help="stop after this many sample frames")
    p.add_argument(
        "--give-up-after",
        type=float,
        default=None,
        metavar="S",
        help="end the recording after S seconds without the link (default: keep retrying until Ctrl-C)",
    )
    p.add_argument("--decimate", type=int, default=None, metavar="N", help="ask the device for one frame in N")
    p.add_argument("--no-commands", action="store_true", help="send nothing to the device (not even an info request)")
    p.add_argument("--force", action="store_true", help="overwrite an existing log")
    p.add_argument("--status", action="store_true", help="show the status line even when stderr is not a terminal")
    p.add_argument(
        "--live-plot",
        nargs="?",
        const=_LIVE_PORT,
        type=int,
        default=None,
        metavar="PORT",
        help=f"draw the raw acceleration and the firmware's position (last {RING_SECONDS:g} s) to OUT.live.png, "
        f"redrawn twice a second, and serve it as a self-reloading page on http://127.0.0.1:PORT/ "
        f"(default port {_LIVE_PORT}; 0: any free port)",
    )
    p.set_defaults(func=cmd_record)

    p = sub.add_parser("log", help="inspect or export a recorded log")
    lsub = p.add_subparsers(dest="log_command", metavar="ACTION")
    q = lsub.add_parser("info", help="summary of a log: source, model, frames, losses, errors")
    q.add_argument("log", type=Path)
    q.add_argument("--json", action="store_true", help="print the summary as JSON")
    q.add_argument("--model", type=Path, help=_MODEL_HELP)
    q.set_defaults(func=cmd_log_info)
    q = lsub.add_parser("export", help="export the sample frames as CSV or as an accelnav run file (NPZ)")
    q.add_argument("log", type=Path)
    q.add_argument("--out", type=Path, required=True, help="FILE.csv or FILE.npz")
    q.add_argument("--model", type=Path, help=_MODEL_HELP)
    q.set_defaults(func=cmd_log_export)
    q = lsub.add_parser("plot", help="the live plot as it stood at the end of a log (raw acceleration, firmware r)")
    q.add_argument("log", type=Path)
    q.add_argument("--out", type=Path, required=True, help="FILE.png")
    q.add_argument("--seconds", type=float, default=RING_SECONDS, help=f"seconds shown; default {RING_SECONDS:g}")
    q.add_argument("--model", type=Path, help=_MODEL_HELP)
    q.set_defaults(func=cmd_log_plot)
    p.set_defaults(func=lambda args: (p.print_help(), 2)[1])


_LIVE_PORT = 8765
RING_SECONDS = 10.0  # accelnav.plots.live.RING_SECONDS; not imported here: the parser stays light

_MODEL_HELP = (
    "model file of a log recorded with --manifest (no model text in it): the compact frames' samples need it "
    "to be replayed"
)


def _record_model_text(args) -> str:
    if getattr(args, "model", None) is None:
        return ""
    from accelnav.model.load import load_model

    return load_model(args.model).text


def _record_manifest(args):
    from accelnav.link.manifest import Manifest
    from accelnav.model.load import load_model

    if args.manifest is not None:
        try:
            man = Manifest.load(args.manifest)
        except (OSError, ValueError, KeyError) as exc:
            raise UserError(f"{args.manifest}: not a telemetry manifest: {exc}") from None
        return man, ""
    model = load_model(args.model)
    return Manifest.for_model(model), model.text


def cmd_record(args) -> int:
    import serial

    from accelnav.link.accounting import format_counts, link_counts
    from accelnav.link.recorder import Recorder, Status

    out = output_target(args.out, stdout=NO_STDOUT["record"])
    if out.kind == "file" and out.path.exists() and not args.force:  # a FIFO or a device is written through
        raise UserError(f"--out: {args.out} exists; give --force to overwrite it")
    if args.give_up_after is not None and args.give_up_after < 0:
        raise UserError(f"--give-up-after: got {args.give_up_after}; accepted: 0 or more seconds")
    if args.decimate is not None and not 1 <= args.decimate <= 1000:
        raise UserError(f"--decimate: got {args.decimate}; accepted: 1 to 1000")
    man, model_text = _record_manifest(args)
    commands: tuple = ()
    if not args.no_commands:
        commands = (("info", {}),)
        if args.decimate is not None:
            commands = (("decimate", {"factor": args.decimate}), ("start", {}), ("info", {}))
    live = None
    if args.live_plot is not None:
        live = _record_live_view(args, man, model_text)
    try:
        rec = Recorder(
            args.port,
            args.out,
            man,
            baud=args.baud,
            model_text=model_text,
            commands=commands,
            overwrite=args.force,
            status=Status(enabled=True if args.status else None),
            on_rows=live.plot.push if live is not None else None,
        )
    except (serial.SerialException, OSError, ValueError) as exc:
        if live is not None:
            live.close()
        raise UserError(f"{args.port}: cannot open: {exc}") from None
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: rec.stop())
    try:
        res = rec.run(duration=args.duration, max_frames=args.frames, give_up_after=args.give_up_after)
    finally:
        rec.close()
        if live is not None:
            live.close()
    if live is not None:
        print(f"accelnav record: live plot: {live.png} ({live.frames_drawn} redraws)")
        if live.error:
            print(f"accelnav record: warning: the live plot stopped: {live.error}; the recording went on")
    for w in res.warnings[:5]:
        print(f"accelnav record: warning: {w}")
    for g in res.gaps:
        back = f"back at {g['back_s']:.1f} s" if "back_s" in g else "not back"
        lost = f", {g['frames_lost']} frames lost" if "frames_lost" in g else ""
        print(f"accelnav record: link lost at {g['lost_s']:.1f} s, {back} ({g['attempts']} attempts){lost}")
    print(f"accelnav record: {args.out}: {res.seconds:.1f} s: {format_counts(link_counts(res.stats))} ({res.reason})")
    if res.reason.startswith("log write failed"):
        print(f"accelnav record: error: {args.out}: {res.reason}; the recording ended there", file=sys.stderr)
    return 1 if res.reason.startswith(("link lost", "log write failed")) else 0


def _record_live_line(line: str) -> None:
    """The live page's line (a refused request) as the recorder's own, on stderr beside its progress."""
    print(f"accelnav record: live plot: {line}", file=sys.stderr)


def _record_live_view(args, man, model_text: str):
    """The live plot beside the log, drawn from its own thread (the recorder never waits for it)."""
    from accelnav.model.load import loads_model
    from accelnav.plots.live import LivePlot, LiveView

    if not 0 <= args.live_plot <= 65535:
        raise UserError(f"--live-plot: port {args.live_plot}; accepted: 0 to 65535")
    model = loads_model(model_text, source=str(args.model)) if model_text else None
    png = args.out.with_name(args.out.name + ".live.png")
    try:
        view = LiveView(LivePlot(man, model), png, port=args.live_plot, log=_record_live_line)
    except OSError as exc:
        raise UserError(f"--live-plot: 127.0.0.1:{args.live_plot}: cannot serve: {exc.strerror or exc}") from None
    print(f"accelnav record: live plot: {view.url} (also {png})", file=sys.stderr)
    return view.start()


def cmd_log_plot(args) -> int:
    from accelnav.plots.live import plot_log

    if args.out.suffix.lower() != ".png":
        raise UserError(f"--out: {args.out}: accepted: a .png file name")
    if not args.seconds > 0:
        raise UserError(f"--seconds: got {args.seconds}; accepted: more than 0")
    check_output(args.out)
    from accelnav.link.logfile import LogError

    try:
        plot = plot_log(args.log, args.out, _record_model_text(args), args.seconds)
    except LogError as exc:
        raise UserError(str(exc)) from None
    except OSError as exc:
        raise UserError(f"--out: {args.out}: cannot write: {exc.strerror or exc}") from None
    print(f"accelnav log plot: {args.out}: the last {min(plot.pushed, plot.capacity)} of {plot.pushed} samples")
    return 0


def cmd_log_info(args) -> int:
    summary = log_summary(args.log, _record_model_text(args))
    if args.json:
        print(json.dumps(summary, indent=1))
        return 0
    print(log_info_table(summary))
    return 0


def log_info_table(s: dict) -> str:
    """``log info`` for a person: one row per subject, values in words and numbers (the JSON keeps every field)."""
    frames = s["frames"]
    kinds = sorted(frames, key=lambda k: (k != "sample", k))
    rows = [
        ("log", f"{s['log']} (source {s['source'] or 'not recorded'}, started {s['started_utc'] or 'not recorded'})"),
        ("model", f"{s['model'] or 'not named'}, sha256 {s['model_sha256']}, frame layout {s['layout_hash']}"),
        ("axes", f"{', '.join(s['axes'])}; {s['input']} input at {s['rate_hz']:g} Hz"),
    ]
    if s["index_first"] is None:
        rows.append(("samples", "none"))
    else:
        rows += [
            ("samples", f"{s['samples']}, sample index {s['index_first']} .. {s['index_last']}"),
            (
                "device time",
                f"{s['device_seconds']:.2f} s: the recording's length, the index span at {s['rate_hz']:g} Hz",
            ),
            (
                "host time",
                f"{s['host_seconds']:.2f} s: first to last chunk read by the host (not the recording's length: "
                "shorter when the device had buffered or ran faster than real time, longer when the link stalled)",
            ),
            ("tx drops", f"{s['tx_drop_last']} (the device's count of frames it could not send, at the last sample)"),
        ]
    rows += [
        ("link", s["counts"]),
        ("frames", ", ".join(f"{k} {frames[k]}" for k in kinds)),
        ("bytes", f"{s['bytes']} in {s['chunks']} chunks; damaged {s['damaged_bytes']}, torn {s['torn_bytes']}"),
    ]
    if "device_layout_ok" in s:
        ok = "matches the manifest" if s["device_layout_ok"] else "DIFFERS from the manifest"
        rows.append(("device", f"frame layout {ok}; decimation {s['device_decimation']}"))
    rows += [("warning", w) for w in s["warnings"]] or [("warnings", "none")]
    width = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:<{width}}  {v}" for k, v in rows)


def cmd_log_export(args) -> int:
    from accelnav.link.manifest import sample_columns

    suffix = args.out.suffix.lower()
    if suffix not in (".csv", ".npz"):
        raise UserError(f"--out: {args.out}: accepted: a .csv or .npz file name")
    check_output(args.out)  # before the work: a directory named as the output is refused at once
    d = _decoded(args.log, _record_model_text(args))
    for w in d.warnings:
        print(f"accelnav log export: warning: {w}")
    cols = sample_columns(d.manifest, d.frames["sample"])
    names = d.manifest.axes
    raw = d.manifest.raw_fields()
    if suffix == ".csv":
        header = ["t_s", "index", "seq", "flags", "host_time_s"]
        table = [cols["t"], cols["index"], cols["seq"], cols["flags"], d.host_t_ns / 1e9]
        for j, ax in enumerate(names):
            for r in raw:
                header.append(f"{ax}_{r}")
                table.append(cols[r][:, j])
            header.append(f"{ax}_flags")
            table.append(cols["axis_flags"][:, j])
            for s in ("r", "u", "a", "eps"):
                header.append(f"{ax}_fw_{s}")
                table.append(cols[s][:, j])
        with atomic_output(args.out) as fh:  # a kill leaves no partial CSV under the name asked for
            np.savetxt(fh, np.column_stack(table), delimiter=",", header=",".join(header), comments="", fmt="%.17g")
        print(f"accelnav log export: {args.out}: {len(cols['t'])} rows; {format_link_counts(d.stats)}")
        return 0
    # NPZ: an accelnav run file (host/data/runfile.py) plus the firmware's own states
    arrays, _ = log_run_arrays(args.log, d, _record_model_text(args))
    with atomic_output(args.out) as fh:
        np.savez_compressed(fh, **arrays)
    gaps = int(np.count_nonzero(np.diff(cols["index"]) != 1)) if len(cols["index"]) > 1 else 0
    print(
        f"accelnav log export: {args.out}: {len(cols['t'])} samples; {format_link_counts(d.stats)}"
        + (f" ({gaps} gaps in the sample index: decimation or lost frames; t is from the index)" if gaps else "")
    )
    return 0


def format_link_counts(stats: dict) -> str:
    return (
        f"lost {stats['lost']}, duplicates {stats['duplicates']}, damaged {stats['bad_frames']} frames"
        + format_compact_counts(stats)
    )


def format_compact_counts(stats: dict) -> str:
    """The compact mode's checks, when the stream had block frames."""
    if not stats["frames"].get("block"):
        return ""
    text = f"; replay: {stats['checkpoints']} checkpoints matched, {stats['mismatches']} mismatches"
    if stats["mismatches"]:
        text += " (MISMATCH: the host's replay differs from the firmware's filter; rows flagged 'mismatch')"
    if stats["unreplayed"]:
        text += f", {stats['unreplayed']} samples unreplayed (no model text)"
    return text
