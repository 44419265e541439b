"""The sanitized command-parser fuzzer, run as a script with libasan preloaded.

tests/link/test_telemetry_fuzz.py starts it in a child process (the sanitizer
runtime must be loaded before Python); it drives the firmware's receiver and
command parser, built by hil_sim.firmware with ASan and UBSan, with
hypothesis-built and plain random inputs, and prints the counts as JSON.
"""

from __future__ import annotations

import json
import sys

from accelnav.hil_sim.targets.firmware import HostFirmware, build_firmware, manifest


def fuzz(examples: int, random_inputs: int, seed: int = 5) -> dict:
    """Drive the command/stimulus parser with hypothesis-built and plain random inputs; returns counts."""
    import numpy as np
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st

    from accelnav.link.codec import encode_command, encode_stimulus, frame

    mod = build_firmware(sanitize=True)
    fw = HostFirmware(mod)
    man = manifest()
    ffi, lib = mod.ffi, mod.lib
    counts = {"hypothesis_inputs": 0, "random_inputs": 0}
    cmd_out = ffi.new("acnf_command_t *")
    n_axes = len(man.axes)

    valid = st.one_of(
        st.sampled_from(["start", "stop", "reset", "info", "zupt_begin", "zupt_end"]).map(
            lambda c: encode_command(man, c)
        ),
        st.integers(0, 65535).map(lambda f: encode_command(man, "decimate", factor=f)),
        st.lists(st.integers(0, 4095), min_size=n_axes, max_size=n_axes).map(
            lambda c: encode_stimulus(man, code=np.array([c]))
        ),
        st.binary(min_size=0, max_size=40).map(frame),  # well framed, arbitrary payload
    )
    chunk = st.one_of(valid, st.binary(max_size=64), st.just(b"\0"), st.binary(min_size=200, max_size=600))

    @settings(
        max_examples=examples, derandomize=True, deadline=None, database=None, suppress_health_check=list(HealthCheck)
    )
    @given(st.lists(chunk, max_size=24), st.integers(0, 1), st.binary(max_size=48))
    def one(chunks, ch, payload):
        data = b"".join(chunks)
        fw.rx(data, ch)
        lib.acnf_parse_command(payload, len(payload), cmd_out)
        fw.take()
        counts["hypothesis_inputs"] += 1

    one()
    rng = np.random.default_rng(seed)
    for _ in range(random_inputs):
        n = int(rng.integers(0, 256))
        data = rng.integers(0, 256, n, dtype=np.uint8)
        data[rng.random(n) < 0.05] = 0  # delimiters now and then
        b = data.tobytes()
        fw.rx(b, int(rng.integers(0, 2)))
        lib.acnf_parse_command(b, len(b), cmd_out)
        counts["random_inputs"] += 1
        if counts["random_inputs"] % 64 == 0:
            fw.take()
    return counts


if __name__ == "__main__":
    result = fuzz(int(sys.argv[1]), int(sys.argv[2]))
    print(json.dumps(result))
