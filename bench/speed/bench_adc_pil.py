"""Benchmark: PIL on the ADC board (netduino2: TIM3 and ADC1 modelled by QEMU), beside the stimulus-fed PIL.

For the ADXL250 model at 100 Hz and at 1 kHz: the netduino2 board samples N periods on QEMU's timer and
ADC (``-icount shift=0,sleep=off``), in compact mode and with ``mode_states`` (a sample frame with the
states every sample, every byte through the emulated USART); SIL then runs on the codes it read, and the
telemetry must be the same bytes. Baseline from the same run: the same codes fed as a stimulus file to the
stm32vldiscovery board (the file feed over semihosting, how the other boards' PIL runs). Times are wall
clock of the emulator alone (the image is built beforehand), the best of 3.
Usage: python bench/run_all.py bench/speed/bench_adc_pil.py [--samples 2000]
"""

from __future__ import annotations

import argparse
import re
import tempfile
from pathlib import Path

from baselines import best_of

from accelnav.hil_sim.targets import hil
from accelnav.hil_sim.targets.firmware import firmware_images, manifest, private_firmware
from accelnav.hil_sim.targets.qemu import run_feed
from accelnav.link.codec import encode_stimulus
from accelnav.model.load import load_model
from accelnav.resources import models_dir


def models(tmp: Path) -> list[tuple[str, Path]]:
    """(label, model file): the ADXL250 model at its 100 Hz and at 1 kHz."""
    path = models_dir() / "adxl250_default.toml"
    fast, n = re.subn(r"^rate_hz = .*$", "rate_hz = 1000.0", path.read_text(), flags=re.M)
    assert n == 1, "adxl250_default.toml: no rate_hz line"
    (tmp / "adxl250_1khz.toml").write_text(fast)
    return [("adxl250_default", path), ("adxl250_default at 1 kHz", tmp / "adxl250_1khz.toml")]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=2000, help="sample periods per run (a multiple of 32)")
    args = ap.parse_args()
    n = args.samples
    print(
        "| model | rate | mode | samples | netduino2 ADC PIL s (samples/s) | stm32vldiscovery file feed s "
        "(samples/s) | telemetry bytes | PIL == SIL |"
    )
    print("|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp_name:
        for label, path in models(Path(tmp_name)):
            model = load_model(path)
            man = manifest(model.source)
            firmware_images("netduino2", model.source)
            firmware_images("stm32vldiscovery", model.source)  # built outside the timing
            for mode, commands in (("compact", ()), ("states", ("mode_states",))):
                runs = [hil.run_adc_pil(model, n, commands=commands) for _ in range(3)]
                res = runs[-1]
                t_adc = min(r.seconds for r in runs)  # the emulator alone, not SIL and decode
                cmd = b"".join(hil.encode_command(man, c) for c in commands)
                stim = cmd + encode_stimulus(man, code=res.codes)
                with private_firmware("stm32vldiscovery", model.source) as fw:
                    t_feed = best_of(lambda e=fw / "accelnav_fw.elf", s=stim: run_feed(e, "stm32vldiscovery", s), 3)
                print(
                    f"| {label} | {model.rate_hz:g} Hz | {mode} | {len(res.codes)} | {t_adc:.2f} ({n / t_adc:,.0f}) "
                    f"| {t_feed:.2f} ({n / t_feed:,.0f}) | {len(res.telemetry)} | {'yes' if res.equal else 'NO'} |",
                    flush=True,
                )


if __name__ == "__main__":
    main()
