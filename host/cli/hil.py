"""``accelnav hil``: the firmware on simulated data, in-process (SIL) or on an emulated board (PIL)."""

from __future__ import annotations

from pathlib import Path

from accelnav.errors import UserError
from accelnav.hil_sim.targets.qemu import MACHINES
from accelnav.hil_sim.targets.simavr import BOARDS as AVR_BOARDS
from accelnav.model.load import DEFAULT_MODEL, load_model


def register(sub) -> None:
    p = sub.add_parser("hil", help="run the firmware on simulated sensor data: SIL (cffi) or PIL (QEMU)")
    p.add_argument("--model", type=Path, default=None, help=f"model file; default: the embedded {DEFAULT_MODEL.name}")
    p.add_argument("--scenario", default="stop_and_go", help="trajectory (accelnav sim --list-scenarios)")
    p.add_argument("--duration", type=float, default=20.0, help="seconds; default: 20")
    p.add_argument("--seed", type=int, default=1, help="random seed; default: 1")
    p.add_argument(
        "--target", choices=("sil", "pil"), default="sil", help="sil: in-process; pil: QEMU, compared with SIL"
    )
    p.add_argument(
        "--board",
        choices=(*MACHINES, *AVR_BOARDS),
        default=None,
        help="emulated board for --target pil: mps2_an385 (Cortex-M3, default), microbit (Cortex-M0), "
        "stm32vldiscovery (the STM32 port's code on an STM32F100), sifive_e (RV32IMAC, SiFive FE310), "
        "atmega328p (AVR in simavr)",
    )
    p.add_argument("--out", type=Path, default=Path("build/hil"), help="folder for the PIL log; default build/hil")
    p.add_argument("--plots", type=Path, default=None, metavar="DIR", help="write hil.png into DIR")
    p.set_defaults(func=cmd_hil)


def cmd_hil(args) -> int:
    from accelnav.cli.core import require_scenario
    from accelnav.hil_sim.sim.sensor import simulate
    from accelnav.hil_sim.targets import hil
    from accelnav.hil_sim.targets.firmware import FirmwareError, manifest
    from accelnav.hil_sim.targets.qemu import QemuError
    from accelnav.hil_sim.targets.simavr import AvrError
    from accelnav.progress import Progress

    if args.board is not None and args.target != "pil":
        raise UserError(f"--board {args.board}: a board is emulated only with --target pil")
    board = args.board or "mps2_an385"
    model = load_model(args.model)
    require_scenario(args.scenario)
    try:
        run = simulate(model, args.scenario, args.duration, args.seed)
    except ValueError as exc:
        raise UserError(str(exc)) from None
    n = len(run.t)
    print(f"model {model.name}, {model.sensor.kind} input, scenario {args.scenario}, {n} samples, seed {args.seed}")
    try:
        man = manifest(model.source)
        stim = hil.stimulus(man, run)
        sil = hil.run_sil(model, stim)
        print(f"SIL: {n} samples in, {len(sil)} bytes of telemetry out ({len(sil) / max(n, 1):.1f} B per sample)")
        pil = None
        if args.target == "pil":
            log = args.out / f"pil_{board}_{model.name}_{args.scenario}.acnlog"
            log.parent.mkdir(parents=True, exist_ok=True)
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

        path = plot_hil(run, c, args.plots / "hil.png", f"accelnav hil ({args.target}): {model.name}, {args.scenario}")
        print(f"wrote {path}")
    return 0 if c.pil_equal_sil in (None, True) and c.max_of_bound <= 1.0 else 1
