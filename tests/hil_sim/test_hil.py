"""SIL and PIL: the same firmware in-process and on the emulated boards, bit for bit.

PIL runs on every board hil_sim.qemu knows: mps2-an385 (Cortex-M3), microbit
(Cortex-M0), stm32vldiscovery (the STM32 port's code on QEMU's STM32F100) and
sifive_e (SiFive FE310, RV32IMAC without FPU, in qemu-system-riscv32),
for both shipped models, each built in both filter forms, on two short
scenarios each (one with rail-clipped samples for the analog model), and a
1 kHz model. PIL runs through the boards' file feed over semihosting (the
path `accelnav hil --target pil` takes); test_qemu_left_behind_by_no_pil_run
also runs it over the UARTs with the recorder (the real link's path).

The PIL tests need qemu-system-arm and arm-none-eabi-gcc (sifive_e:
qemu-system-riscv32, riscv64-unknown-elf-gcc and picolibc). Where they are
missing the tests skip and say why; with ACCELNAV_REQUIRE_PIL=1 (set by
.ci/run) a missing tool is a failure instead, so CI cannot pass by skipping.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest
from conftest import MODELS

from accelnav.cli import main
from accelnav.hil_sim.sim.sensor import simulate
from accelnav.hil_sim.targets import hil, qemu, simavr
from accelnav.hil_sim.targets.firmware import make_firmware, manifest
from accelnav.link.decoder import decode_all, replay_for
from accelnav.model.load import load_model

SIGMA_FRACTION = 1e-3  # firmware vs float64 reference, in units of the reference's sigma, after 1 s


# what PIL needs on each board, and its Debian packages; the boards not named are ARM
ARM_TOOLS = (("qemu-system-arm", "arm-none-eabi-gcc"), "qemu-system-arm gcc-arm-none-eabi libnewlib-arm-none-eabi")
PIL_TOOLS = {
    "sifive_e": (
        ("qemu-system-riscv32", "riscv64-unknown-elf-gcc"),
        "qemu-system-misc gcc-riscv64-unknown-elf picolibc-riscv64-unknown-elf",
    ),
}


def _require_pil(board: str = "mps2_an385"):
    tools, packages = PIL_TOOLS.get(board, ARM_TOOLS)
    missing = [tool for tool in tools if shutil.which(tool) is None]
    if missing:
        reason = f"PIL on {board} needs {', '.join(missing)} (Debian: {packages})"
        if os.environ.get("ACCELNAV_REQUIRE_PIL") == "1":
            pytest.fail(f"ACCELNAV_REQUIRE_PIL=1 but {reason}")
        pytest.skip(reason)


BOARDS = tuple(qemu.MACHINES)
AVR_BOARDS = simavr.BOARDS  # in simavr: the covariance form (the gain schedule does not fit the part)


def _require_avr():
    """avr-gcc and simavr's library for the atmega328p board; skipped with the reason, or a failure under
    ACCELNAV_REQUIRE_AVR=1 (set by .ci/run)."""
    try:
        simavr.require_avr()
        simavr.harness()
    except simavr.AvrError as e:
        if os.environ.get("ACCELNAV_REQUIRE_AVR") == "1":
            pytest.fail(f"ACCELNAV_REQUIRE_AVR=1 but {e}")
        pytest.skip(str(e))


def _require_board(board: str):
    _require_avr() if board in AVR_BOARDS else _require_pil(board)


FORMS = ("covariance", "gain_schedule")
SCENARIOS = {  # model -> two short scenarios (seconds of samples)
    "adxl250_default.toml": (("shock", 2.0), ("stop_and_go", 3.0)),  # shock: rail-clipped samples
    "adxl202_duty.toml": (("vehicle", 3.0), ("sinusoid+bad_captures", 2.0)),  # bad captures: skipped samples
}
BAD_CAPTURES = (37, 38, 39, 120, 151)  # samples whose T2 capture is lost (T2 = 0), on every axis


def _simulate(model, scenario: str, seconds: float, seed: int):
    """A simulated run; ``NAME+bad_captures`` loses the duty-cycle captures of BAD_CAPTURES, as a timer
    that missed an edge does: the firmware must skip (predict over) exactly those samples."""
    name, _, extra = scenario.partition("+")
    run = simulate(model, name, seconds, seed=seed)
    if extra != "bad_captures":
        return run
    import dataclasses

    import numpy as np

    from accelnav.model.design import input_conversion

    t2 = np.array(run.t2)
    t2[list(BAD_CAPTURES), :] = 0
    conv = [input_conversion(model, j) for j in range(len(model.axes))]
    clipped = np.column_stack([c.clipped(run.t1[:, j], t2[:, j]) for j, c in enumerate(conv)])
    accel = np.column_stack([c.accel(run.t1[:, j], t2[:, j]) for j, c in enumerate(conv)])
    assert clipped[list(BAD_CAPTURES)].all()
    return dataclasses.replace(run, t2=t2, clipped=clipped, accel=accel)


PIL_CASES = [
    (board, model_file, form, scenario, seconds)
    for board in BOARDS
    for model_file, scenarios in SCENARIOS.items()
    for form in FORMS
    for scenario, seconds in scenarios
] + [
    (board, model_file, "covariance", scenario, seconds)
    for board in AVR_BOARDS
    for model_file, scenarios in SCENARIOS.items()
    for scenario, seconds in scenarios
]


@pytest.fixture(scope="module")
def model_in_form(tmp_path_factory):
    """A shipped model file built in the given filter form (the shipped file itself where it already is)."""
    folder = tmp_path_factory.mktemp("models")

    def get(model_file: str, form: str) -> Path:
        path = MODELS / model_file
        text = path.read_text()
        shipped = re.search(r'^form = "(\w+)"', text, re.M)
        assert shipped, f"{model_file}: no [filter] form"
        if shipped.group(1) == form:
            return path
        out = folder / f"{path.stem}_{form}.toml"
        out.write_text(text[: shipped.start()] + f'form = "{form}"' + text[shipped.end() :])
        return out

    return get


@pytest.mark.parametrize("board,model_file,form,scenario,seconds", PIL_CASES)
def test_pil_frames_equal_sil_bit_for_bit(tmp_path, model_in_form, board, model_file, form, scenario, seconds):
    _require_board(board)
    model = load_model(model_in_form(model_file, form))
    assert model.filter.form == form
    run = _simulate(model, scenario, seconds, seed=9)
    man = manifest(model.source)
    stim = hil.stimulus(man, run)
    sil = hil.run_sil(model, stim)
    pil = hil.run_pil(model, stim, len(run.t), tmp_path / "pil.acnlog", board=board, timeout_s=120)
    c = hil.compare(model, run, sil, pil.telemetry)
    assert c.n == len(run.t)
    assert c.pil_equal_sil, f"{board}: PIL differs from SIL from frame {c.first_difference}"
    if scenario in ("shock", "sinusoid+bad_captures"):
        assert run.clipped.any()
        flag = 2 if scenario == "shock" else 1  # the rail flag (analog), the skipped flag (a lost capture)
        assert (c.fw["axis_flags"] & flag).any(), "the skip reached no frame"
    # both forms follow skipped samples: the firmware's filter is the Kalman filter with the same skips
    for key, err in c.max_err_sigma.items():
        assert err < SIGMA_FRACTION, f"{key}: firmware off the float64 reference by {err:.2e} sigma"
    assert c.max_of_bound <= 1.0, f"firmware at {c.max_of_bound:.3g} of the generator's stated bound"
    assert pil.stats["lost"] == 0 and pil.stats["crc_errors"] == 0
    # both forms stream compact frames: every checkpoint the board sent matched the host's replay
    assert c.link["PIL"]["mismatches"] == 0 and c.link["PIL"]["checkpoints"] >= len(model.axes)
    fr = decode_all(man, pil.telemetry, replay_for(man, model))[0]
    assert len(fr["sample"]) == len(run.t)
    assert not fr["sample"]["missed"].any() and not fr["sample"]["rx_lost"].any()
    print(f"\n{board} {model.name} {form} {scenario}: {c.n} samples, {c.n / pil.seconds:.0f} samples/s")


def test_sil_agrees_with_reference_and_compare_catches_a_flipped_bit(default_model):
    run = simulate(default_model, "stop_and_go", 8.0, seed=2)
    man = manifest(default_model.source)
    sil = hil.run_sil(default_model, hil.stimulus(man, run))
    c = hil.compare(default_model, run, sil, sil)
    assert c.pil_equal_sil and c.first_difference is None
    assert max(c.max_err_sigma.values()) < SIGMA_FRACTION and c.max_of_bound <= 1.0
    # one bit of sample 500's input in its block frame, re-framed with a valid CRC: must be seen
    from accelnav.link.codec import cobs_decode, frame

    frames = [p + b"\0" for p in sil.split(b"\0")[:-1]]
    for k, f in enumerate(frames):
        p = bytearray(cobs_decode(f[:-1])[:-4])
        first = int.from_bytes(p[1:5], "little")
        if p[0] == man.frames["block"]["type"] and first <= 500 < first + p[6]:
            off = man.field("block", "x.code")["offset"] + 2 * (500 - first)
            p[off] ^= 1
            frames[k] = frame(bytes(p))
    tampered = b"".join(frames)
    c = hil.compare(default_model, run, sil, tampered)
    # the replay then misses the next checkpoint: the rows of the stretch holding sample 500 are flagged
    C = man.data["checkpoint_samples"]
    assert c.pil_equal_sil is False and c.first_difference == C * (500 // C)
    assert c.link["PIL"]["mismatches"] >= 1 and c.link["SIL"]["mismatches"] == 0


def test_smoother_with_zupt_beats_filter_in_the_summary(default_model):
    run = simulate(default_model, "stop_and_go", 30.0, seed=4)
    man = manifest(default_model.source)
    c = hil.compare(default_model, run, hil.run_sil(default_model, hil.stimulus(man, run)))
    final = {(row.axis, row.method): abs(row.final) for row in c.position_rows}
    for axis in run.axis_names:
        assert final[(axis, "smoother + ZUPT")] < 0.1 * final[(axis, "firmware filter")]


@pytest.mark.parametrize("board_name", BOARDS)
def test_qemu_is_never_left_behind(tmp_path, board_name):
    _require_pil(board_name)
    elf = make_firmware(board_name) / "accelnav_fw.elf"
    with pytest.raises(RuntimeError, match="inside"):
        with qemu.QemuBoard(elf, board_name) as board:
            board.open(board.machine.telemetry)
            pid = board.proc.pid
            raise RuntimeError("an error inside the run")
    assert board.proc.poll() is not None
    ps = subprocess.run(["ps", "-p", str(pid), "-o", "stat="], capture_output=True, text=True).stdout.strip()
    assert ps in ("", "Z"), f"qemu process {pid} still there: {ps!r}"


@pytest.mark.parametrize("link", ["feed", "uart"])
def test_qemu_left_behind_by_no_pil_run(tmp_path, link):
    """After a whole PIL run (and one that fails: too few frames for what it waits for), no qemu of ours runs.
    Over the UART too: the real link's path (stimulus UART in, the recorder on the telemetry UART), the
    one PIL took before the file feed, still equals SIL."""
    _require_pil()
    model = load_model(MODELS / "adxl250_default.toml")
    man = manifest(model.source)
    run = simulate(model, "stationary", 0.5, seed=1)
    stim = hil.stimulus(man, run)
    before = _our_qemus()
    ok = hil.run_pil(model, stim, len(run.t), tmp_path / "ok.acnlog", board="microbit", link=link)
    assert ok.telemetry == hil.run_sil(model, stim)
    with pytest.raises(qemu.QemuError, match="ended early"):
        hil.run_pil(model, stim, len(run.t) + 5, tmp_path / "short.acnlog", board="microbit", timeout_s=2.0, link=link)
    assert _our_qemus() - before == set()


@pytest.mark.parametrize("board_name", BOARDS)
def test_file_feed_takes_commands_as_the_host_board_does(tmp_path, board_name):
    """The feed's input is the host board's stdin: command frames in it act as in SIL (decimate 7: a
    frame every 7th sample; stop, then start: no frames in between), byte for byte; the log holds it."""
    _require_pil(board_name)
    from accelnav.link.codec import encode_command
    from accelnav.link.logfile import read_log

    model = load_model(MODELS / "adxl250_default.toml")
    man = manifest(model.source)
    run = simulate(model, "shock", 1.0, seed=2)
    n = len(run.t)
    half = hil.stimulus(man, run)
    stop, start = encode_command(man, "stop"), encode_command(man, "start")
    stim = encode_command(man, "decimate", factor=7) + half + stop + half + start + half
    sil = hil.run_sil(model, stim)
    frames = decode_all(man, sil)[0]
    expected = len(range(0, n, 7)) * 2
    # acks: decimate, then stop and start, and the flush that ends each third of the stimulus
    assert len(frames["sample"]) == expected and len(frames["ack"]) == 6
    assert frames["sample"]["index"][expected // 2] == 2 * n  # the first sample after start
    pil = hil.run_pil(model, stim, expected, tmp_path / "cmd.acnlog", board=board_name)
    assert pil.telemetry == sil
    assert b"".join(read_log(pil.log).data) == sil
    assert pil.stats["lost"] == 0 and pil.stats["crc_errors"] == 0


def test_file_feed_errors_are_one_line(tmp_path):
    """A feed whose input file is missing ends the emulator with status 1 and a one-line reason; a feed
    file name the semihosting command line cannot carry is refused before QEMU starts."""
    _require_pil()
    elf = make_firmware("mps2_an385") / "accelnav_fw.elf"
    cmd = qemu.qemu_command(elf.resolve(), machine="mps2-an385", feed=("missing.bin", "tel.bin"))
    done = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=60)
    assert done.returncode == 1
    assert "accelnav-feed: cannot open the stimulus or the telemetry file" in done.stdout + done.stderr
    for bad in ("two words.bin", "a,b.bin", "sub/stim.bin", ""):
        with pytest.raises(ValueError, match="plain file name"):
            qemu.qemu_command(elf, feed=(bad, "tel.bin"))


def _our_qemus() -> set[int]:
    """Live qemu-system-arm processes that are children of this test process."""
    out = subprocess.run(["ps", "-o", "pid=,ppid=,stat=,comm=", "-e"], capture_output=True, text=True).stdout
    me = os.getpid()
    return {
        int(pid)
        for pid, ppid, stat, comm in (line.split(None, 3) for line in out.splitlines() if line.strip())
        if comm.startswith("qemu-system") and int(ppid) == me and not stat.startswith("Z")
    }


def test_unknown_board_is_a_one_line_error(capsys):
    with pytest.raises(qemu.QemuError, match="accepted: mps2_an385, microbit, stm32vldiscovery"):
        qemu.machine_for("nrf52")
    with pytest.raises(SystemExit):
        main(["hil", "--target", "pil", "--board", "nrf52"])
    err = capsys.readouterr().err
    assert "invalid choice: 'nrf52'" in err and "microbit" in err and "stm32vldiscovery" in err
    assert main(["hil", "--target", "sil", "--board", "microbit"]) == 2
    assert "--board microbit: a board is emulated only with --target pil" in capsys.readouterr().err


def test_missing_emulator_is_a_clear_error(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(qemu.shutil, "which", lambda name: None)
    with pytest.raises(qemu.QemuError, match="qemu-system-arm not found: install"):
        qemu.require_qemu()
    (tmp_path / "fw.elf").write_bytes(b"\x7fELF")
    with pytest.raises(qemu.QemuError, match="not found"):
        qemu.Mps2Board(tmp_path / "fw.elf")
    with pytest.raises(qemu.QemuError, match="no firmware image"):
        qemu.Mps2Board(tmp_path / "missing.elf")


def test_hil_cli_pil_on_the_m0(tmp_path, capsys):
    _require_pil()
    status = main(
        [
            "hil",
            "--target",
            "pil",
            "--board",
            "microbit",
            "--scenario",
            "shock",
            "--duration",
            "2",
            "--out",
            str(tmp_path),
        ]
    )
    out = capsys.readouterr().out
    assert status == 0, out
    assert "PIL (microbit): 200 samples" in out and "PIL vs SIL: 200 sample rows, bit-identical" in out
    assert "PIL: 7 block frames, replay matched 2 checkpoints bit for bit, no mismatch" in out
    # the link budget: PIL's telemetry is SIL's, byte for byte
    sil_bytes = int(re.search(r"SIL: 200 samples in, (\d+) bytes of telemetry out", out).group(1))
    assert f"PIL (microbit): 200 samples in, {sil_bytes} bytes of telemetry out" in out


def test_hil_cli_sil(tmp_path, capsys):
    status = main(["hil", "--target", "sil", "--duration", "6", "--plots", str(tmp_path)])
    out = capsys.readouterr().out
    assert status == 0
    assert "firmware vs float64 reference" in out and "smoother + ZUPT" in out
    man = manifest(None)
    fr, B, C = man.frames, man.data["block_samples"], man.data["checkpoint_samples"]
    # compact: 19 blocks (18 full, the flush's), checkpoints at 0, 256, 512 and the flush's, one ack
    size = 18 * fr["block"]["wire_size"] + fr["block"]["wire_size"] + 4 * 2 * fr["checkpoint"]["wire_size"]
    size += fr["ack"]["wire_size"]
    assert 600 // B == 18 and 600 // C == 2
    assert f"SIL: 600 samples in, {size} bytes of telemetry out ({size / 600:.1f} B per sample)" in out
    assert (tmp_path / "hil.png").stat().st_size > 10_000
    status = main(["hil", "--scenario", "nowhere"])
    assert status == 2 and "unknown scenario" in capsys.readouterr().err


def _schedule_model(tmp_path):
    from accelnav.model.load import load_model as load

    text = (MODELS / "adxl250_default.toml").read_text().replace('form = "covariance" ', 'form = "gain_schedule" ')
    path = tmp_path / "gs.toml"
    path.write_text(text)
    model = load(path)
    assert model.filter.form == "gain_schedule"
    return model


def test_stated_bound_is_against_the_kalman_filter_and_catches_a_blind_schedule(tmp_path, capsys):
    """A gain schedule that ignored skipped samples (its skip-following cut out of the generated C) on a
    shock run (rail-clipped samples) departs from the float64 Kalman filter by more than the stated
    bound, which hil.compare uses; the generated one stays within it, and `accelnav hil` runs it."""
    import numpy as np
    from support.codegen_lockstep import blind_schedule

    from accelnav.codegen.emit_c import emit
    from accelnav.estimate.kf import run_filter
    from accelnav.hil_sim.targets.harness import AxisRunner, build
    from accelnav.model.design import axis_design

    model = _schedule_model(tmp_path)
    run = simulate(model, "shock", 4.0, seed=9)
    valid = ~run.clipped[:, 0]
    assert not valid.all()
    files = emit(model)
    kf = run_filter(axis_design(model, 0), run.accel[:, 0], valid=valid, progress=False)
    bound = hil.stated_bound(model, 0, run, kf.x_post)
    for c_files, within in ((files, True), (blind_schedule(files), False)):
        res = AxisRunner(build(c_files, tmp_path / str(within)), files["accelnav.json"], 0).run(code=run.code[:, 0])
        assert bool((np.abs(res["x"] - kf.x_post) / bound).max() <= 1.0) == within
    status = main(["hil", "--model", str(tmp_path / "gs.toml"), "--target", "sil", "--duration", "2"])
    out = capsys.readouterr().out
    assert status == 0 and "within the generator's stated bound" in out


@pytest.mark.parametrize("form", FORMS)
@pytest.mark.parametrize("rate", [1000.0])  # 100 Hz: test_pil_frames_equal_sil_bit_for_bit[shock]
def test_sil_shock_against_the_float64_filter(tmp_path, rate, form):
    """The firmware in-process on rail-clipped shock data at 1 kHz, both forms: within the stated bound
    of the float64 Kalman filter (same skips) at every sample, and < 1e-3 of its sigma after 1 s."""
    from accelnav.model.load import load_model as load

    text = (MODELS / "adxl250_default.toml").read_text().replace("rate_hz = 100.0", f"rate_hz = {rate!r}")
    text = text.replace('form = "covariance" ', f'form = "{form}" ')
    path = tmp_path / "fast.toml"
    path.write_text(text)
    model = load(path)
    run = simulate(model, "shock", 3.0, seed=9)
    assert run.clipped.any()
    man = manifest(model.source)
    c = hil.compare(model, run, hil.run_sil(model, hil.stimulus(man, run)))
    assert c.max_of_bound <= 1.0, f"firmware at {c.max_of_bound:.3g} of the generator's stated bound"
    for key, err in c.max_err_sigma.items():
        assert err < SIGMA_FRACTION, f"{key}: firmware off the float64 reference by {err:.2e} sigma"


@pytest.mark.parametrize("board_name", BOARDS)
def test_pil_at_1khz_equals_sil(tmp_path, board_name):
    """A 1 kHz model (rail-clipped shock, 3 s: 3 000 samples) on every emulated board: the telemetry is
    SIL's byte for byte, nothing lost or missed."""
    _require_pil(board_name)
    text = (MODELS / "adxl250_default.toml").read_text().replace("rate_hz = 100.0", "rate_hz = 1000.0")
    path = tmp_path / "fast.toml"
    path.write_text(text)
    model = load_model(path)
    assert model.rate_hz == 1000.0
    run = simulate(model, "shock", 3.0, seed=9)
    assert run.clipped.any()
    man = manifest(model.source)
    stim = hil.stimulus(man, run)
    pil = hil.run_pil(model, stim, len(run.t), tmp_path / "pil.acnlog", board=board_name, timeout_s=120)
    assert pil.telemetry == hil.run_sil(model, stim)
    assert pil.stats["frames"]["sample"] == len(run.t) == 3000
    assert pil.stats["lost"] == 0 and pil.stats["crc_errors"] == 0
    fr = decode_all(man, pil.telemetry, replay_for(man, model))[0]
    assert len(fr["sample"]) == len(run.t)
    assert not fr["sample"]["missed"].any() and not fr["sample"]["rx_lost"].any()
    print(f"\n{board_name} at 1 kHz: {len(run.t)} samples, {len(run.t) / pil.seconds:.0f} samples/s")


@pytest.mark.parametrize("model_file", ["adxl250_default.toml", "adxl202_duty.toml"])
def test_avr_board_fits_its_ram_with_the_stack_it_measured(tmp_path, model_file):
    """The atmega328p image's static RAM plus the deepest stack simavr saw (a run through blocks,
    checkpoints and every command that sends) stays inside the part's 2 KiB, and inside the stack
    reserve firmware.mk checks every build against."""
    _require_avr()
    from accelnav.codegen import targets
    from accelnav.hil_sim.targets.firmware import FW
    from accelnav.link.codec import cobs_decode, encode_command

    model = load_model(MODELS / model_file)
    man = manifest(model.source)
    run = simulate(model, "shock", 3.0, seed=3)
    cmds = b"".join(encode_command(man, c) for c in ("info", "mode_states", "zupt_begin", "zupt_end", "reset"))
    stim = hil.stimulus(man, run) + cmds + hil.stimulus(man, run) + encode_command(man, "decimate", factor=3)
    out = make_firmware("atmega328p", model.source)
    res = simavr.run_feed(out / "accelnav_fw.elf", stim, timeout=120)
    info = man.frames["info"]["type"]
    frames = {}
    for name, tel in (("pil", res.telemetry), ("sil", hil.run_sil(model, stim))):
        frames[name] = [cobs_decode(f)[:-4] for f in tel.split(b"\0")[:-1]]
    # the info frame names the board (and its uptime): the only frame the AVR and the host board send apart
    assert [f for f in frames["pil"] if f[0] != info] == [f for f in frames["sil"] if f[0] != info]
    board = [f for f in frames["pil"] if f[0] == info]
    assert len(board) == 1 and man.data["boards"]["atmega328p"] in board[0]
    size = subprocess.run(["avr-size", "-A", str(out / "accelnav_fw.elf")], capture_output=True, text=True).stdout
    sec = {m[0]: int(m[1]) for m in re.findall(r"^(\.\w+)\s+(\d+)", size, re.M)}
    # the reserve firmware.mk's check and the codegen fit check keep (parts.mk: PART_STACK_atmega328p)
    assert re.search(r"^AVR_STACK\s*\?=\s*\$\(PART_STACK_atmega328p\)", (FW / "firmware.mk").read_text(), re.M)
    reserve = targets.part("atmega328p").stack
    assert 0 < res.stack <= reserve, f"the deepest stack, {res.stack} B, is beyond firmware.mk's reserve {reserve} B"
    assert sec[".data"] + sec[".bss"] + res.stack <= simavr.RAM_BYTES
    print(f"\natmega328p {model.name}: {sec['.data'] + sec['.bss']} B static RAM + {res.stack} B stack")


def test_avr_gain_schedule_refused_in_one_line_naming_flash_and_ram(tmp_path, model_in_form, capsys):
    _require_avr()
    path = model_in_form("adxl250_default.toml", "gain_schedule")
    status = main(["hil", "--model", str(path), "--target", "pil", "--board", "atmega328p", "--duration", "1",
                   "--out", str(tmp_path)])  # fmt: skip
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1, err
    m = re.search(r"BOARD=atmega328p: this model needs (\d+) B flash and (\d+) B RAM \+ (\d+) B stack", err)
    assert m and int(m[1]) > simavr.FLASH_BYTES, err
    assert "the ATmega328P has 32768 B flash and 2048 B RAM" in err


def test_avr_hil_cli_pil(tmp_path, capsys):
    _require_avr()
    status = main(["hil", "--target", "pil", "--board", "atmega328p", "--scenario", "shock", "--duration", "2",
                   "--out", str(tmp_path)])  # fmt: skip
    out = capsys.readouterr().out
    assert status == 0, out
    assert "PIL (atmega328p): 200 samples" in out and "PIL vs SIL: 200 sample rows, bit-identical" in out
