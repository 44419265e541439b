"""The frame layout (codegen.frames) and the round trip C packer -> Python decoder.

The firmware's own C (firmware/src + the host board + the generated filter
and frame code) runs in-process through cffi: frames it packs decode in Python
(vectorised and naive) to the very values it was given; its application,
driven by stimulus and command frames, streams what the generated filter
computes, flags rails and timeouts, obeys the commands, and counts what it
could not send.
"""

from __future__ import annotations

import json
import zlib

import numpy as np
import pytest
from support.naive_decoder import decode_naive

from accelnav.codegen.frames import COMMANDS, MAX_ENCODED, PROTOCOL_VERSION, layout
from accelnav.hil_sim.targets.firmware import DUTY_MODEL, HostFirmware, build_firmware, generated, manifest
from accelnav.link.codec import cobs_decode, cobs_encode, encode_command, encode_stimulus, frame
from accelnav.link.decoder import Decoder, decode_all, replay_for
from accelnav.link.manifest import sample_columns
from accelnav.model.load import load_model
from accelnav.native.cbuild import cache_dir

MODELS = {"analog": None, "duty": str(DUTY_MODEL)}


@pytest.fixture(scope="module", params=sorted(MODELS))
def kind(request):
    return request.param


@pytest.fixture(scope="module")
def fw_mod(kind):
    return build_firmware(MODELS[kind])


@pytest.fixture(scope="module")
def man(kind):
    return manifest(MODELS[kind])


@pytest.fixture(scope="module")
def replay(kind, man):
    """The host's replay of the firmware's filter: the compact mode's block frames need it."""
    return replay_for(man, load_model(MODELS[kind]))


def _flush(man):
    return encode_command(man, "flush")


# --------------------------------------------------------------------------
# layout


def test_layout_is_packed_and_fits_one_cobs_block(kind):
    files = generated(MODELS[kind])
    man = json.loads(files["acnframe.json"])
    for name, fr in man["frames"].items():
        off = 1
        for f in fr["fields"]:
            assert f["offset"] == off, (name, f["name"])
            off += np.dtype(f["dtype"]).itemsize
        assert off == fr["size"]
        assert fr["size"] + 4 < MAX_ENCODED
        assert fr["wire_size"] == fr["size"] + 6
    filt = json.loads(files["accelnav.json"])
    for i, ax in enumerate(man["axes"]):
        assert filt["axes"][i]["axis"] == ax
        for s, v in (("r", "r"), ("u", "u_out"), ("a", "a"), ("e", "e")):
            field = next(f for f in man["frames"]["sample"]["fields"] if f["name"] == f"{ax}.{s}")
            assert field["frac"] == filt["axes"][i]["variables"][v]["frac"]
            assert field["kind"] == f"i{filt['axes'][i]['variables'][v]['word']}"
    raw = {"analog": ["code"], "duty": ["t1", "t2"]}[kind]
    names = [f["name"] for f in man["frames"]["sample"]["fields"]]
    for ax in man["axes"]:
        assert all(f"{ax}.{r}" in names for r in raw)


def test_layout_hash_follows_the_layout():
    files = generated(None)
    model = load_model()
    filt = json.loads(files["accelnav.json"])
    base = layout(model, filt)
    assert f"0x{base.layout_hash:08x}" in files["acnframe.h"]
    changed = json.loads(json.dumps(filt))
    changed["axes"][0]["variables"]["r"]["frac"] += 1
    assert layout(model, changed).layout_hash != base.layout_hash
    one_axis = json.loads(json.dumps(filt))
    one_axis["axes"] = one_axis["axes"][:1]
    with pytest.raises(ValueError, match="axes differ"):
        layout(model, one_axis)


def test_generated_frame_code_is_reproducible():
    from accelnav.codegen.frames import emit_frames

    files = generated(None)
    again = emit_frames(load_model(), json.loads(files["accelnav.json"]))
    assert again == {k: files[k] for k in again}


# --------------------------------------------------------------------------
# framing primitives: the C and the Python agree


def test_cobs_and_crc_match_between_c_and_python(fw_mod):
    ffi, lib = fw_mod.ffi, fw_mod.lib
    rng = np.random.default_rng(3)
    out = ffi.new("uint8_t[]", 1024)
    back = ffi.new("uint8_t[]", 1024)
    for n in [0, 1, 2, 253, 254, 255, 300, 508, 600, *rng.integers(0, 600, 60)]:
        data = rng.integers(0, 256, n, dtype=np.uint8)
        data[rng.random(n) < rng.random()] = 0
        data = data.tobytes()
        m = lib.cobs_encode(data, n, out)
        enc = ffi.buffer(out, m)[:]
        assert enc == cobs_encode(data)
        assert 0 not in enc
        assert cobs_decode(enc) == data
        k = lib.cobs_decode(enc, m, back)
        assert ffi.buffer(back, k)[:] == data
        assert lib.crc32_update(0, data, n) == zlib.crc32(data)
    assert lib.crc32_update(lib.crc32_update(0, b"12345", 5), b"6789", 4) == 0xCBF43926  # the check value


def test_link_frame_equals_python_frame(fw_mod, man):
    ffi, lib = fw_mod.ffi, fw_mod.lib
    rng = np.random.default_rng(4)
    out = ffi.new("uint8_t[]", 512)
    biggest = max(f["size"] for f in man.frames.values() if f["direction"] == "up")
    for n in [1, biggest, *rng.integers(1, biggest, 50)]:
        payload = rng.integers(0, 256, n, dtype=np.uint8).tobytes()
        m = lib.link_frame(payload, n, out)
        assert ffi.buffer(out, m)[:] == frame(payload)
    assert lib.link_frame(b"x" * (biggest + 1), biggest + 1, out) == 0  # refused, nothing written


# --------------------------------------------------------------------------
# round trip: packed by the C, decoded by Python


def _random_samples(man, n, rng):
    """Field values over each field's whole range, extremes included."""
    fields = man.frames["sample"]["fields"]
    vals = {}
    for f in fields:
        info = np.iinfo(np.dtype(f["dtype"]))
        v = rng.integers(info.min, info.max, n, dtype=np.dtype(f["dtype"]), endpoint=True)
        v[: min(n, 4)] = np.array([info.min, info.max, 0, -1 if info.min < 0 else 1], dtype=v.dtype)[: min(n, 4)]
        vals[f["name"]] = v
    return vals


def test_round_trip_sample_frames(fw_mod, man):
    ffi, lib = fw_mod.ffi, fw_mod.lib
    rng = np.random.default_rng(5)
    n = 3000
    vals = _random_samples(man, n, rng)
    # a stream in order: the index advances with seq; random gaps (seq wraps), the index near its top
    step = rng.integers(1, 4, n)
    vals["seq"] = (np.cumsum(step) + 65000).astype(np.uint16)
    vals["index"] = (np.cumsum(step) + 2**32 - 4 * n).astype(np.uint32)
    vals["flags"] &= ~np.uint16(1 << man.flags["reset"])
    s = ffi.new("acnf_sample_t *")
    payload = ffi.new("uint8_t[]", 256)
    wire = ffi.new("uint8_t[]", 512)
    stream = bytearray()
    raw = man.raw_fields()
    for k in range(n):
        for top in ("seq", "index", "flags", "tx_drop", "skipped", "overflow", "missed", "rx_lost"):
            setattr(s, top, int(vals[top][k]))
        for j, ax in enumerate(man.axes):
            a = s.axis[j]
            a.flags = int(vals[f"{ax}.flags"][k])
            for r in raw:
                setattr(a, r, int(vals[f"{ax}.{r}"][k]))
            for st in "ruae":
                setattr(a, st, int(vals[f"{ax}.{st}"][k]))
        size = lib.acnf_pack_sample(s, payload)
        assert size == man.frames["sample"]["size"]
        m = lib.link_frame(payload, size, wire)
        stream += ffi.buffer(wire, m)[:]
    frames, stats = decode_all(man, bytes(stream))
    got = frames["sample"]
    assert len(got) == n
    assert stats.bad_frames == 0 and stats.crc_errors == 0
    for name, v in vals.items():
        np.testing.assert_array_equal(got[name], v, err_msg=name)
    # lost frames: the random steps leave gaps
    expected_lost = int((step[1:] - 1).sum())
    assert stats.lost == expected_lost
    naive, lost = decode_naive(man, bytes(stream))
    assert lost == expected_lost
    assert [tuple(r) for r in got.tolist()] == naive["sample"]


def test_stream_split_anywhere_decodes_the_same(fw_mod, man, replay):
    fw = HostFirmware(fw_mod)
    rng = np.random.default_rng(6)
    n = 400
    if man.input == "duty_cycle":
        t2 = np.full((n, len(man.axes)), man.data["t2_nominal"])
        wire_in = encode_stimulus(man, t1=rng.integers(t2 // 4, 3 * t2 // 4), t2=t2)
    else:
        wire_in = encode_stimulus(man, code=rng.integers(1, 4095, (n, len(man.axes))))
    fw.rx(wire_in + _flush(man))
    data = fw.take()
    whole, _ = decode_all(man, data, replay)
    assert len(whole["sample"]) == n
    d = Decoder(man, replay=replay)
    cuts = np.sort(rng.integers(0, len(data), 80))
    parts = [d.feed(data[a:b])["sample"] for a, b in zip(np.r_[0, cuts], np.r_[cuts, len(data)], strict=True)]
    np.testing.assert_array_equal(np.concatenate(parts), whole["sample"])
    assert d.stats.lost == 0 and d.stats.bad_frames == 0
    assert d.stats.mismatches == 0 and d.stats.checkpoints == 2 * (1 + n // man.data["checkpoint_samples"])


# --------------------------------------------------------------------------
# the application, driven by frames


def _run_filter_directly(kind, raw):
    """The generated filter alone (codegen.harness), for comparison with what the firmware streams."""
    from accelnav.hil_sim.targets.harness import AxisRunner, build

    files = {k: v for k, v in generated(MODELS[kind]).items() if k.startswith("accelnav.")}
    mod = build(files, cache_dir() / "harness")
    return [
        AxisRunner(mod, files["accelnav.json"], axis=j).run(**{k: v[:, j] for k, v in raw.items()}) for j in range(2)
    ]


def test_streamed_states_are_the_generated_filters(kind, fw_mod, man, replay):
    """The compact mode's round trip through the firmware's C: raw inputs in block frames, the states
    from the host's replay, every checkpoint (the firmware's own state bytes) matched bit for bit, the
    rows equal to the generated filter run alone and to the states the firmware itself sends in the
    state mode (decimation 2)."""
    fw = HostFirmware(fw_mod)
    rng = np.random.default_rng(7)
    n = 600
    if kind == "duty":
        t2 = np.full((n, 2), man.data["t2_nominal"], dtype=np.int64)
        t1 = t2 // 2 + rng.integers(-300, 300, (n, 2))
        t1[50, 0] = 0  # output stuck low: skipped
        t2[60, 1] = t2[60, 1] * 2  # period far off: skipped
        raw = {"t1": t1, "t2": t2}
    else:
        code = 2048 + rng.integers(-40, 40, (n, 2))
        code[50, 0] = 0  # rails
        code[60, 1] = 4095
        raw = {"code": code}
    fw.rx(encode_stimulus(man, **raw) + _flush(man))
    frames, stats = decode_all(man, fw.take(), replay)
    assert stats.mismatches == 0 and stats.lost == 0
    assert stats.checkpoints == 2 * (1 + n // man.data["checkpoint_samples"])  # all but the first pair
    assert (frames["sample"]["flags"] & (1 << man.flags["replayed"])).all()
    cols = sample_columns(man, frames["sample"])
    np.testing.assert_array_equal(cols["index"], np.arange(n))
    # the same input in the state mode: the firmware's own states of every second sample
    fw2 = HostFirmware(fw_mod)
    fw2.rx(encode_command(man, "decimate", factor=2) + encode_stimulus(man, **raw))
    own = decode_all(man, fw2.take())[0]["sample"]
    np.testing.assert_array_equal(own["index"], np.arange(0, n, 2))
    for ax in man.axes:
        for st in "ruae":
            np.testing.assert_array_equal(frames["sample"][f"{ax}.{st}"][::2], own[f"{ax}.{st}"], err_msg=st)
    ref = _run_filter_directly(kind, raw)
    for j in range(2):
        x = ref[j]["x"]
        for i, key in enumerate(("r", "u", "a", "eps")):
            np.testing.assert_allclose(cols[key][:, j], x[:, i], rtol=1e-12, atol=1e-12, err_msg=key)
        skipped = (cols["axis_flags"][:, j] & 1).astype(bool)
        np.testing.assert_array_equal(skipped, ~ref[j]["valid"])
    assert (cols["axis_flags"][50, 0] & 1) and (cols["axis_flags"][60, 1] & 1)
    if kind == "analog":
        assert cols["axis_flags"][50, 0] & 2  # rail
    assert frames["sample"]["skipped"][-1] == 2
    assert frames["sample"]["flags"][0] & 4  # reset: the first frame after init
    assert not (frames["sample"]["flags"][1:] & 4).any()


def test_missed_samples_are_predicted_over_and_counted(kind, fw_mod, man, replay):
    """A board that misses samples (its main loop too slow: the STM32 port's sample overrun) calls
    app_missed: every axis filter predicts over each missed sample, exactly as over a refused input,
    the sample index keeps time, and the `missed` counter says how many. Here the host board misses
    samples 100, 101 and 200 of 300; the reference is the generated filter with those refused."""
    fw = HostFirmware(fw_mod)
    rng = np.random.default_rng(11)
    n = 300
    missed = [100, 101, 200]
    if kind == "duty":
        t2 = np.full((n, 2), man.data["t2_nominal"], dtype=np.int64)
        raw = {"t1": t2 // 2 + rng.integers(-300, 300, (n, 2)), "t2": t2}
        refused = {"t1": raw["t1"].copy(), "t2": t2}
        refused["t1"][missed] = 0  # output stuck low: the generated filter predicts only
    else:
        raw = {"code": 2048 + rng.integers(-40, 40, (n, 2))}
        refused = {"code": raw["code"].copy()}
        refused["code"][missed] = 0  # a rail: the generated filter predicts only
    stim = encode_stimulus(man, **raw)
    per = len(stim) // n  # every stimulus frame has the same size on the wire
    for a, b, gap in ((0, 100, 2), (102, 200, 1), (201, n, 0)):
        fw.rx(stim[a * per : b * per])
        fw.lib.app_missed(gap)
    fw.rx(_flush(man))
    frames, stats = decode_all(man, fw.take(), replay)
    s = frames["sample"]
    # compact mode: a row for every sample, the missed ones flagged (no input, predicted over)
    np.testing.assert_array_equal(s["index"], np.arange(n))
    assert stats.lost == 0 and stats.mismatches == 0
    for ax in man.axes:
        miss = (s[f"{ax}.flags"] & (1 << man.axis_flags["missed"])) != 0
        np.testing.assert_array_equal(np.flatnonzero(miss), missed)
    assert s["missed"][-1] == 3
    assert not s["skipped"].any() and not s["rx_lost"].any()
    cols = sample_columns(man, s)
    ref = _run_filter_directly(kind, refused)
    for j in range(2):
        for i, key in enumerate(("r", "u", "a", "eps")):
            np.testing.assert_allclose(cols[key][:, j], ref[j]["x"][:, i], rtol=1e-12, atol=1e-12, err_msg=key)


def test_duty_cycle_timeout_is_flagged_and_the_filter_keeps_running():
    mod = build_firmware(MODELS["duty"])
    man = manifest(MODELS["duty"])
    fw = HostFirmware(mod)
    n = 50
    t2 = np.full((n, 2), man.data["t2_nominal"])
    flags = np.zeros(n, np.uint8)
    flags[20:30] = 1  # axis x unplugged for 10 samples
    fw.rx(encode_stimulus(man, flags=flags, t1=t2 // 2, t2=t2) + _flush(man))
    s = decode_all(man, fw.take(), replay_for(man, load_model(MODELS["duty"])))[0]["sample"]
    assert len(s) == n
    timeout = (s["x.flags"] & 4) != 0
    np.testing.assert_array_equal(timeout, flags == 1)
    assert not (s["y.flags"] & 4).any()
    assert s["skipped"][-1] == 10


def test_commands(fw_mod, man, replay):
    fw = HostFirmware(fw_mod)
    n_ax = len(man.axes)

    def stim(n):
        if man.input == "duty_cycle":
            t2 = np.full((n, n_ax), man.data["t2_nominal"])
            return encode_stimulus(man, t1=t2 // 2, t2=t2)
        return encode_stimulus(man, code=np.full((n, n_ax), 2048))

    cmd = lambda name, **a: encode_command(man, name, **a)  # noqa: E731
    fw.rx(cmd("info") + stim(10) + cmd("decimate", factor=4) + stim(20) + cmd("zupt_begin") + stim(4))
    fw.rx(cmd("zupt_end") + stim(4) + cmd("stop") + stim(8) + cmd("start") + cmd("decimate", factor=1) + stim(3))
    fw.rx(cmd("decimate", factor=0) + cmd("decimate", factor=1001) + cmd("reset") + stim(2) + cmd("flush"))
    frames, stats = decode_all(man, fw.take(), replay)
    info, ack, s = frames["info"], frames["ack"], frames["sample"]
    assert len(info) == 1
    assert info["layout_hash"][0] == man.layout_hash
    assert bytes(info["model_sha256"][0]).hex() == man.model_sha256
    assert info["protocol"][0] == PROTOCOL_VERSION and info["board"][0] == man.data["boards"]["host"]
    assert info["rate_mhz"][0] == round(man.rate_hz * 1000)
    sent = "info decimate zupt_begin zupt_end stop start decimate decimate decimate reset flush".split()
    assert list(ack["command"]) == [COMMANDS[c][0] for c in sent]
    assert list(ack["status"]) == [0] * 7 + [1, 1, 0, 0]  # factors 0 and 1001 refused
    # 10 at 1:1 (compact), 20 at 1:4 (5), 4 + 4 at 1:4 (2), 8 stopped, 3 at 1:1, then 2 after the reset
    assert list(s["index"]) == [*range(10), 10, 14, 18, 22, 26, 30, 34, 46, 47, 48, 0, 1]
    assert stats.lost == 0 and stats.mismatches == 0  # seq runs on across stop and start; resumes are no loss
    zupt = (s["flags"] & 2) != 0
    assert list(zupt) == [False] * 15 + [True] + [False] * 6
    assert (s["flags"][-2:] & 4).tolist() == [4, 0]  # reset flagged once


def test_blocks_the_link_cannot_take_are_counted_and_the_replay_resynchronises(fw_mod, man, replay):
    """Compact mode: a block the link cannot take is dropped (tx_drop); the host counts its samples lost
    from the index, has no state for the samples after it until the next checkpoint (counted lost too,
    exactly) and resynchronises there."""
    fw = HostFirmware(fw_mod)
    B, C = man.data["block_samples"], man.data["checkpoint_samples"]
    n = C + 2 * B
    n_ax = len(man.axes)
    if man.input == "duty_cycle":
        t2 = np.full((n, n_ax), man.data["t2_nominal"])
        data = encode_stimulus(man, t1=t2 // 2, t2=t2)
    else:
        data = encode_stimulus(man, code=np.full((n, n_ax), 2048))
    per = len(data) // n
    fw.rx(data[: 2 * B * per])
    sent = fw.take()
    fw.lib.board_host_set_tx_limit(0)  # the link takes nothing while the third block fills and goes
    fw.rx(data[2 * B * per : 3 * B * per])
    assert fw.take() == b""
    fw.lib.board_host_set_tx_limit(1 << 16)
    fw.rx(data[3 * B * per :] + _flush(man))
    frames, stats = decode_all(man, sent + fw.take(), replay)
    s = frames["sample"]
    # delivered: the first two blocks, then from the checkpoint after sample C on
    np.testing.assert_array_equal(s["index"], np.r_[0 : 2 * B, C:n])
    assert stats.lost == C - 2 * B  # the dropped block and the samples up to the checkpoint
    assert stats.mismatches == 0
    assert s["tx_drop"][-1] == 1


def test_frames_the_link_cannot_take_are_counted(fw_mod, man):
    fw = HostFirmware(fw_mod)
    fw.rx(encode_command(man, "decimate", factor=2))  # the state mode: one sample frame per two samples
    wire = man.frames["sample"]["wire_size"]
    fw.lib.board_host_set_tx_limit(wire * 3 + 10)  # room for three frames between drains
    n_ax = len(man.axes)
    if man.input == "duty_cycle":
        t2 = np.full((80, n_ax), man.data["t2_nominal"])
        data = encode_stimulus(man, t1=t2 // 2, t2=t2)
    else:
        data = encode_stimulus(man, code=np.full((80, n_ax), 2048))
    step = len(data) // 80 * 10  # five frames per piece: two of them find the link full
    fw.rx(data, step=step)
    frames, stats = decode_all(man, fw.take())
    s = frames["sample"]
    assert len(s) == 24
    # 16 dropped; the last piece's two come after the last frame sent, so the host sees 14 gaps,
    # and the MCU's own count in that frame explains every one of them
    assert stats.lost == 14
    assert s["tx_drop"][-1] == 14
