"""``accelnav hil``: the firmware on simulated data or a user's recording, in-process (SIL) or on an emulated
board (PIL)."""

from __future__ import annotations

from pathlib import Path

from accelnav.cli.args import clock_args, reader_options
from accelnav.errors import UserError
from accelnav.hil_sim.targets.qemu import ADC_MACHINES, MACHINES
from accelnav.hil_sim.targets.simavr import BOARDS as AVR_BOARDS
from accelnav.model.load import DEFAULT_MODEL, load_model


def register(sub) -> None:
    p = sub.add_parser("hil", help="run the firmware on simulated data or your recording: SIL (cffi) or PIL (QEMU)")
    p.add_argument("--model", type=Path, default=None, help=f"model file; default: the embedded {DEFAULT_MODEL.name}")
    p.add_argument("--scenario", default=None, help="trajectory (accelnav sim --list-scenarios); default: stop_and_go")
    p.add_argument("--duration", type=float, default=None, help="seconds; default: 20")
    p.add_argument("--seed", type=int, default=None, help="random seed; default: 1")
    p.add_argument(
        "--input",
        type=Path,
        default=None,
        metavar="REC",
        help="your own recording instead of a simulation (CSV, gzip CSV, NPZ, run file or recorder log): "
        "raw counts are fed as they are, an acceleration is read out as the sensor would; no truth, so no "
        "position errors",
    )
    p.add_argument("--axis", action="append", metavar="NAME", help="--input: a column to use as an axis; repeat")
    p.add_argument("--time-column", default=None, metavar="NAME", help="--input CSV: the time column")
    clock_args(p)
    p.add_argument("--unit", default=None, help="--input: unit of the acceleration columns, g, mg, m/s^2 or counts")
    p.add_argument(
        "--target", choices=("sil", "pil"), default="sil", help="sil: in-process; pil: QEMU, compared with SIL"
    )
    p.add_argument(
        "--board",
        choices=(*MACHINES, *AVR_BOARDS, *ADC_MACHINES),
        default=None,
        help="emulated board for --target pil: mps2_an385 (Cortex-M3, default), microbit (Cortex-M0), "
        "stm32vldiscovery (the STM32 port's code on an STM32F100), sifive_e (RV32IMAC, SiFive FE310), "
        "atmega328p (AVR in simavr), netduino2 (STM32F205: samples QEMU's timer and ADC models for "
        "--duration seconds; no scenario)",
    )
    p.add_argument("--out", type=Path, default=Path("build/hil"), help="folder for the PIL log; default build/hil")
    p.add_argument("--plots", type=Path, default=None, metavar="DIR", help="write hil.png into DIR")
    p.set_defaults(func=cmd_hil)


def cmd_hil(args) -> int:
    from accelnav.fileio import output_target
    from accelnav.hil_sim.sim.sensor import simulate
    from accelnav.hil_sim.sim.trajectories import require_scenario
    from accelnav.hil_sim.targets import hil
    from accelnav.hil_sim.targets.firmware import FirmwareError, manifest
    from accelnav.hil_sim.targets.qemu import QemuError
    from accelnav.hil_sim.targets.simavr import AvrError
    from accelnav.progress import Progress

    if args.board is not None and args.target != "pil":
        raise UserError(f"--board {args.board}: a board is emulated only with --target pil")
    board = args.board or "mps2_an385"
    if board in ADC_MACHINES:
        return _hil_adc(args, board)
    if args.input is not None:
        run, model = _hil_recorded(args)
        scenario = args.input.name
        n = len(run.t)
        print(f"model {model.name}, {model.sensor.kind} input, recording {args.input}, {n} samples")
    else:
        from accelnav.data.inputs import FLAGS

        for key, value in reader_options(args).items():  # the reader's flags: nothing to read without --input
            if value is not None:
                raise UserError(f"--{FLAGS[key].replace('_', '-')}: only with --input (a recording)")
        scenario = args.scenario or "stop_and_go"
        seed = 1 if args.seed is None else args.seed
        model = load_model(args.model)
        require_scenario(scenario, "--scenario", UserError)
        try:
            run = simulate(model, scenario, 20.0 if args.duration is None else args.duration, seed)
        except ValueError as exc:
            raise UserError(str(exc)) from None
        n = len(run.t)
        print(f"model {model.name}, {model.sensor.kind} input, scenario {scenario}, {n} samples, seed {seed}")
    log = None
    if args.target == "pil":  # the log by the output rule, before any work: never one of the inputs
        name = args.out / f"pil_{board}_{model.name}_{_hil_stem(scenario)}.acnlog"
        log = output_target(name, "--out", inputs=(args.input, args.model), stdout=False)
    try:
        man = manifest(model.source)
        stim = hil.stimulus(man, run)
        sil = hil.run_sil(model, stim)
        print(f"SIL: {n} samples in, {len(sil)} bytes of telemetry out ({len(sil) / max(n, 1):.1f} B per sample)")
        pil = None
        if log is not None:
            with Progress("pil", n, unit="samples", enabled=None) as bar:
                res = hil.run_pil(model, stim, n, log, board=board)
                bar.update(n)
            pil = res.telemetry
            print(f"PIL ({board}): {n} samples in {res.seconds:.1f} s ({n / res.seconds:,.0f} samples/s), log {log}")
            print(f"PIL ({board}): {n} samples in, {len(pil)} bytes of telemetry out")
    except (QemuError, FirmwareError, AvrError) as exc:
        raise UserError(str(exc).splitlines()[0]) from None
    c = hil.compare(model, run, sil, pil)
    print(hil.format_comparison(c))
    if args.plots is not None:
        from accelnav.plots.hil import plot_hil

        path = plot_hil(run, c, args.plots / "hil.png", f"accelnav hil ({args.target}): {model.name}, {scenario}")
        print(f"wrote {path}")
    return 0 if c.pil_equal_sil in (None, True) and c.max_of_bound <= 1.0 else 1


def _hil_adc(args, board: str) -> int:
    """PIL on a board that samples QEMU's ADC model: its input is what the model makes, not a scenario."""
    from accelnav.data.inputs import FLAGS
    from accelnav.fileio import output_target
    from accelnav.hil_sim.targets import hil
    from accelnav.hil_sim.targets.firmware import FirmwareError
    from accelnav.hil_sim.targets.qemu import QemuError

    for flag in ("input", "scenario", "seed", "plots"):
        if getattr(args, flag) is not None:
            raise UserError(f"--{flag}: not with --board {board} (its samples come from QEMU's ADC model)")
    for key, value in reader_options(args).items():
        if value is not None:
            raise UserError(f"--{FLAGS[key].replace('_', '-')}: only with --input (a recording)")
    model = load_model(args.model)
    if model.sensor.kind != "analog":
        raise UserError(f"{model.source}: --board {board} samples an ADC; the model's sensor is {model.sensor.kind}")
    seconds = 20.0 if args.duration is None else args.duration
    n = round(seconds * model.rate_hz)
    if not 1 <= n <= 1_000_000:
        raise UserError(f"--duration {seconds:g}: 1 .. 1000000 samples at {model.rate_hz:g} Hz")
    name = args.out / f"pil_{board}_{model.name}_adc.acnlog"
    log = output_target(name, "--out", inputs=(args.model,), stdout=False)
    print(f"model {model.name}, {n} sample periods on {board}: TIM3 and ADC1 as QEMU models them")
    try:
        res = hil.run_adc_pil(model, n, board=board, log=log, timeout_s=60.0 + n / 100.0)
    except (QemuError, FirmwareError) as exc:
        raise UserError(str(exc).splitlines()[0]) from None
    rows = len(res.codes)
    print(f"PIL ({board}): {n} sample periods in {res.seconds:.1f} s, {len(res.telemetry)} bytes, log {log}")
    sent = "" if rows == n else f"; {rows} sent: the compact mode sends whole blocks"
    print(f"codes the firmware read from its ADC: {res.codes.min()} .. {res.codes.max()}{sent}")
    where = "" if res.equal else f" from byte {res.first_difference}"
    verdict = "bit-identical (the same bytes)" if res.equal else f"DIFFERENT{where}"
    print(f"PIL vs SIL on those codes: {rows} samples, {verdict}")
    return 0 if res.equal else 1


def _hil_recorded(args):
    """(RecordedRun, model) of --input; the simulation's options make no sense beside it."""
    from accelnav.hil_sim.targets.hil import recorded_input

    for flag in ("scenario", "duration", "seed"):
        if getattr(args, flag) is not None:
            raise UserError(f"--{flag}: not with --input (the recording is the input)")
    return recorded_input(args.input, args.model, **reader_options(args))


def _hil_stem(name: str) -> str:
    """A recording's name as a safe part of the log's file name."""
    import re

    return re.sub(r"[^A-Za-z0-9_-]+", "_", name.split(".")[0])[:40] or "input"
