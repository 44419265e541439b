"""The one way accelnav runs code on an emulated MCU (qemu-system-arm, qemu-system-riscv32).

The machines (:data:`MACHINES`), one per firmware board that runs in QEMU:
``mps2_an385`` (Cortex-M3, CMSDK UARTs), ``microbit`` (nRF51822, Cortex-M0,
one UART), ``stm32vldiscovery`` (STM32F100, Cortex-M3: the stm32f103
port's code, see firmware/boards/stm32f103/board_stm32.c) and ``sifive_e``
(SiFive FE310, RV32IMAC without FPU, one UART; qemu-system-riscv32).
:data:`ADC_MACHINES`: the boards whose samples come from a peripheral QEMU
models, not from a stimulus: ``netduino2`` (STM32F205, Cortex-M3: TIM3 and
ADC1 sample, USART1 streams; firmware/boards/netduino2/board_netduino2.c).

Two uses, one command line (:func:`qemu_command`):

* :class:`QemuBoard`: the firmware as a board. Its UARTs (telemetry out and
  commands in; the stimulus feed that stands in for the ADC or timer capture,
  on a second UART or, on the one-UART microbit, on the same one) are TCP
  servers on loopback, opened from Python as pyserial ``socket://`` URLs. A
  context manager: leaving it kills QEMU and waits for it, so no process is
  left behind, whatever happens inside. :class:`Mps2Board` is the mps2-an385 one.
* :func:`run_feed`: the firmware in feed mode, the way PIL runs it: the
  stimulus read from a file and the telemetry written to one through
  semihosting (ARM's, or RISC-V's, which QEMU serves alike), a block per
  trap, so the emulated core runs flat out instead of waiting for QEMU to move one UART byte per poll of its socket
  (firmware/boards/emu_feed.h). The same image runs on its UARTs when the
  command line names no feed.
* :func:`run_adc`: an ADC board for a number of sample periods, its telemetry
  UART written to a file; ``-icount shift=0,sleep=off``: the virtual clock
  counts instructions and jumps over the idle time to the next timer event,
  so the run is the same on every host and takes no wall-clock sample period.
* :func:`run_to_exit`: a bare-metal program that prints over semihosting and
  exits through it (the instruction-count benchmark), with ``-icount
  shift=0`` so one instruction is one tick of virtual time and the counts are
  deterministic.

A missing emulator or toolchain is a :class:`QemuError` with one line that
says what to install.
"""

from __future__ import annotations

import shutil
import socket
import subprocess
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

QEMU = "qemu-system-arm"
# the Debian package of each emulator, for the one-line error when it is missing
QEMU_PACKAGES = {"qemu-system-arm": "qemu-system-arm", "qemu-system-riscv32": "qemu-system-misc"}
MACHINE = "mps2-an385"  # Cortex-M3; UART0 at 0x40004000, UART1 at 0x40005000


@dataclass(frozen=True)
class Machine:
    """A QEMU machine that runs a firmware board: which -serial carries what."""

    board: str  # the firmware's BOARD name
    machine: str  # qemu-system-arm -M
    core: str
    uarts: int  # -serial devices, in the machine's order
    telemetry: int  # telemetry out, commands in
    stimulus: int  # the stimulus feed (may be the telemetry UART)
    qemu: str = QEMU  # the emulator binary


MACHINES = {
    m.board: m
    for m in (
        Machine("mps2_an385", "mps2-an385", "Cortex-M3", 2, 0, 1),  # CMSDK UART0 / UART1
        Machine("microbit", "microbit", "Cortex-M0 (nRF51822)", 1, 0, 0),  # the nRF51's one UART
        Machine("stm32vldiscovery", "stm32vldiscovery", "Cortex-M3 (STM32F100)", 2, 0, 1),  # USART1 / USART2
        Machine("sifive_e", "sifive_e", "RV32IMAC (SiFive FE310)", 1, 0, 0, "qemu-system-riscv32"),  # UART0 only
    )
}


# the boards that sample through QEMU's models of their peripherals (run by run_adc, no stimulus)
ADC_MACHINES = {
    m.board: m
    for m in (Machine("netduino2", "netduino2", "Cortex-M3 (STM32F205)", 1, 0, 0),)  # USART1: telemetry only
}
ADC_MARKER = "accelnav-adc"  # the first word of the command line of an ADC board's run (board_netduino2.c)


def machine_for(board: str) -> Machine:
    """The QEMU machine of a firmware board, or QemuError naming the boards that run in QEMU."""
    try:
        return MACHINES[board]
    except KeyError:
        raise QemuError(f"board {board!r} does not run in QEMU; accepted: {', '.join(MACHINES)}") from None


class QemuError(RuntimeError):
    """The emulator could not be started or did not behave."""


def require_qemu(qemu: str = QEMU) -> str:
    """Path of the emulator ``qemu`` (qemu-system-arm by default), or QemuError saying how to get it."""
    path = shutil.which(qemu)
    if path is None:
        package = QEMU_PACKAGES.get(qemu, qemu)
        raise QemuError(f"{qemu} not found: install Debian's {package} (PIL needs the emulator)")
    return path


FEED_MARKER = "accelnav-feed"  # the first word of the command line that puts a board in feed mode (emu_feed.h)


def qemu_command(
    elf: str | Path,
    *,
    uart_ports: tuple[int, ...] = (),
    icount: bool = False,
    machine: str = MACHINE,
    feed: tuple[str, str] | None = None,
    qemu: str = QEMU,
    args: tuple[str, ...] = (),
    warp: bool = False,
    serial_file: str | None = None,
) -> list[str]:
    """The emulator's command line: ``elf`` on ``machine``, UARTs as loopback TCP servers in port order.

    ``feed``: the names of the stimulus and telemetry files, relative to the emulator's working folder,
    for the board's file feed over semihosting (firmware/boards/emu_feed.h) instead of its UARTs.
    ``qemu``: the emulator binary (the machine's :attr:`Machine.qemu`). ``args``: more words of the
    semihosting command line (plain words). ``warp``: ``-icount shift=0,sleep=off`` (deterministic, idle
    time skipped). ``serial_file``: the first UART written to this file (a plain name) instead."""
    cmd = [qemu, "-M", machine, "-display", "none", "-monitor", "none"]
    semi = "enable=on,target=native"
    words = ((FEED_MARKER, *feed) if feed is not None else ()) + tuple(args)
    for name in (*words, *((serial_file,) if serial_file is not None else ())):
        if not name or any(c in name for c in " ,/:"):
            raise ValueError(f"feed file name {name!r}: a plain file name (no spaces, commas or folders)")
    semi += "".join(f",arg={w}" for w in words)
    cmd += ["-semihosting-config", semi, "-kernel", str(elf)]
    if icount or warp:
        # one instruction per ns of virtual time: deterministic counts; sleep=off: idle time is skipped
        cmd += ["-icount", "shift=0,sleep=off" if warp else "shift=0"]
    if serial_file is not None:
        cmd += ["-serial", f"file:{serial_file}"]
    elif not uart_ports:
        cmd += ["-serial", "none"]
    for i, port in enumerate(uart_ports):
        cmd += ["-chardev", f"socket,id=uart{i},host=127.0.0.1,port={port},server=on,wait=off"]
        cmd += ["-serial", f"chardev:uart{i}"]
    return cmd


def free_port() -> int:
    """A TCP port on loopback that nothing listens on right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class QemuBoard:
    """``with QemuBoard(elf, "microbit") as board: tel = board.open(board.machine.telemetry)``.

    ``open(i)`` returns a pyserial port on UART i (retrying until QEMU listens);
    opening the same UART twice returns the same port.
    """

    def __init__(self, elf: str | Path, board: str = "mps2_an385", *, start_timeout: float = 20.0):
        self.machine = machine_for(board)
        self.elf = Path(elf)
        if not self.elf.is_file():
            raise QemuError(f"{self.elf}: no firmware image (build it with 'make firmware BOARD={board}')")
        require_qemu(self.machine.qemu)
        self.ports = tuple(free_port() for _ in range(self.machine.uarts))
        self.start_timeout = start_timeout
        self.proc: subprocess.Popen | None = None
        self._opened: list = []

    def url(self, uart: int) -> str:
        return f"socket://127.0.0.1:{self.ports[uart]}"

    def __enter__(self) -> QemuBoard:
        cmd = qemu_command(self.elf, uart_ports=self.ports, machine=self.machine.machine, qemu=self.machine.qemu)
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        return self

    def open(self, uart: int, timeout: float = 0.05):
        import serial

        for port in self._opened:
            if port.port == self.url(uart):
                return port
        deadline = time.monotonic() + self.start_timeout
        while True:
            if self.proc is not None and self.proc.poll() is not None:
                err = self.proc.stderr.read().decode(errors="replace").strip() if self.proc.stderr else ""
                raise QemuError(f"{self.machine.qemu} exited with status {self.proc.returncode}: {err[-500:]}")
            try:
                port = serial.serial_for_url(self.url(uart), timeout=timeout)
                self._opened.append(port)
                return port
            except serial.SerialException:
                if time.monotonic() > deadline:
                    raise QemuError(
                        f"{self.machine.qemu}: UART{uart} on {self.url(uart)} did not open in time"
                    ) from None
                time.sleep(0.05)

    def close(self) -> None:
        for port in self._opened:
            try:
                # pyserial's socket close() sleeps 0.3 s "in case of quick reconnects"; QEMU goes away next,
                # so close the socket itself (0.6 s less per PIL run on a two-UART board)
                sock = getattr(port, "_socket", None)
                if sock is not None:
                    sock.close()
                    port._socket = None
                    port.is_open = False
                port.close()
            except Exception:  # noqa: BLE001 - closing a dead socket must not hide the real error
                pass
        self._opened.clear()
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
        if self.proc is not None:
            self.proc.communicate(timeout=10)

    def __exit__(self, *exc) -> None:
        self.close()


class Mps2Board(QemuBoard):
    """``with Mps2Board(elf) as board: tel = board.open(0); feed = board.open(1)`` (mps2-an385)."""

    def __init__(self, elf: str | Path, *, start_timeout: float = 20.0):
        super().__init__(elf, "mps2_an385", start_timeout=start_timeout)


def _run_in_folder(
    m: Machine, board: str, elf: Path, files: dict[str, bytes], what: str, timeout: float, **cmd
) -> bytes:
    """Run ``elf`` on ``m`` in a temporary folder holding ``files``, with :func:`qemu_command`'s keywords
    ``cmd``, and return the telemetry file ``tel.bin`` it wrote; the folder is removed afterwards, the
    emulator killed past ``timeout`` (``what`` did not finish: the one-line error says so)."""
    with tempfile.TemporaryDirectory(prefix="accelnav-qemu-") as tmp:
        folder = Path(tmp)
        for name, data in files.items():
            (folder / name).write_bytes(data)
        argv = qemu_command(elf, machine=m.machine, qemu=m.qemu, **cmd)
        try:
            done = subprocess.run(argv, cwd=folder, capture_output=True, timeout=timeout)
        except subprocess.TimeoutExpired:
            raise QemuError(f"{m.qemu} ({board}): {what} did not finish within {timeout:g} s") from None
        err = (done.stdout + done.stderr).decode(errors="replace").strip()
        if done.returncode != 0:
            raise QemuError(f"{m.qemu} ({board}) exited with status {done.returncode}: {err[-500:]}")
        out = folder / "tel.bin"
        if not out.is_file():
            raise QemuError(
                f"{m.qemu} ({board}): the firmware wrote no telemetry file (an image without the file feed?)"
            )
        return out.read_bytes()


def _image(elf: str | Path, board: str, m: Machine) -> Path:
    elf = Path(elf).resolve()
    if not elf.is_file():
        raise QemuError(f"{elf}: no firmware image (build it with 'make firmware BOARD={board}')")
    require_qemu(m.qemu)
    return elf


def run_feed(elf: str | Path, board: str, stimulus: bytes, *, timeout: float = 600.0) -> bytes:
    """Run a firmware image on ``board``'s machine in feed mode and return its telemetry.

    The stimulus goes in and the telemetry comes out through files over semihosting, a block per
    trap (firmware/boards/emu_feed.h); the board exits at the end of the stimulus. Nothing is
    paced by a UART or by the host: the emulated core runs flat out. The files live in a
    temporary folder that is removed afterwards; the emulator is killed if it overruns ``timeout``."""
    m = machine_for(board)
    elf = _image(elf, board, m)
    files = {"stim.bin": stimulus}
    return _run_in_folder(m, board, elf, files, "the file feed", timeout, feed=("stim.bin", "tel.bin"))


def run_adc(elf: str | Path, board: str, periods: int, commands: bytes = b"", *, timeout: float = 120.0) -> bytes:
    """Run an ADC board's image (:data:`ADC_MACHINES`) for ``periods`` sample periods and return what it sent
    on its telemetry UART. ``commands`` (command frames) reach the board before its sample clock starts.
    The emulator runs in a temporary folder that is removed afterwards, and is killed past ``timeout``."""
    try:
        m = ADC_MACHINES[board]
    except KeyError:
        accepted = ", ".join(ADC_MACHINES)
        raise QemuError(f"board {board!r} does not sample on QEMU's peripherals; accepted: {accepted}") from None
    if not 1 <= periods <= 100_000_000:
        raise ValueError(f"periods {periods}: 1 .. 100000000")
    elf = _image(elf, board, m)
    words: tuple[str, ...] = (ADC_MARKER, str(periods))
    files = {"cmd.bin": commands} if commands else {}
    words += tuple(files)
    what = f"{periods} sample periods"
    return _run_in_folder(m, board, elf, files, what, timeout, args=words, warp=True, serial_file="tel.bin")


def run_to_exit(
    elf: str | Path, *, icount: bool = True, timeout: float = 300.0, machine: str = MACHINE, qemu: str = QEMU
) -> str:
    """Run a semihosting program to its exit; returns what it printed. Non-zero exit is a QemuError."""
    require_qemu(qemu)
    try:
        done = subprocess.run(
            qemu_command(elf, icount=icount, machine=machine, qemu=qemu),
            capture_output=True,
            text=True,
            timeout=timeout,
        )
    except subprocess.TimeoutExpired:
        raise QemuError(f"{qemu}: {elf} did not exit within {timeout:g} s") from None
    if done.returncode != 0:
        raise QemuError(f"{qemu}: {elf} exited with status {done.returncode}: {done.stderr.strip()[-500:]}")
    return done.stdout + done.stderr
