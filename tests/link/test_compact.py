"""The compact telemetry mode: block frames of raw inputs, checkpoints of the filter's state, the host's replay.

The firmware's own C (host board, cffi) streams the default model's samples;
the host decodes them with the vectorised decoder (whole and in pieces) and
with the frame-by-frame naive one, which replays the filter one sample at a
time. Asserted: repeated frames are dropped and counted, a gap of 100 000
block frames is counted exactly and the replay resynchronises at the next
checkpoint, a checkpoint that disagrees with the replay is reported (decoder
counts, the rows flagged, ``log info``/``export``, ``accelnav hil``), damaged
frames are never accepted, and the format meets its byte budget.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from support.frames import frame_kind, split_frames
from support.naive_decoder import decode_naive

from accelnav.cli import main as cli_main
from accelnav.data.logs import log_summary
from accelnav.hil_sim.targets.firmware import DUTY_MODEL, HostFirmware, build_firmware, manifest
from accelnav.link.codec import cobs_decode, encode_command, encode_stimulus, frame
from accelnav.link.decoder import Decoder, decode_all, replay_for
from accelnav.link.logfile import LogWriter
from accelnav.model.load import load_model

N = 1500


@pytest.fixture(scope="module")
def telemetry(man):
    fw = HostFirmware(build_firmware(None))
    code = 2048 + np.random.default_rng(21).integers(-300, 300, (N, 2))
    code[[100, 700], 0] = 0  # rails: refused inputs
    code[900, 1] = 4095
    fw.rx(encode_stimulus(man, code=code) + encode_command(man, "flush"))
    return fw.take()


def _payload(f: bytes) -> bytes:
    return cobs_decode(f[:-1])[:-4]


def _with_index(f: bytes, delta: int) -> bytes:
    """The frame with its u32 index (bytes 1..4 of every block and checkpoint payload) moved by delta."""
    p = bytearray(_payload(f))
    p[1:5] = ((int.from_bytes(p[1:5], "little") + delta) % 2**32).to_bytes(4, "little")
    return frame(bytes(p))


def _check(man, replay, stream: bytes, seed: int = 0) -> tuple[np.ndarray, dict]:
    """Whole, in pieces and naive agree; returns the rows and the counts."""
    frames, stats = decode_all(man, stream, replay)
    d = Decoder(man, replay=replay)
    cuts = np.sort(np.random.default_rng(seed).integers(0, len(stream) + 1, 9))
    got = [d.feed(stream[a:b])["sample"] for a, b in zip(np.r_[0, cuts], np.r_[cuts, len(stream)], strict=True)]
    np.testing.assert_array_equal(np.concatenate([*got, d.release()]), frames["sample"])
    keys = ("lost", "duplicates", "checkpoints", "mismatches", "checkpoint_repeats", "unreplayed")
    counts = {k: stats.as_dict()[k] for k in keys}
    assert {k: d.stats.as_dict()[k] for k in keys} == counts
    naive_counts: dict = {}
    naive, _ = decode_naive(man, stream, naive_counts, replay)
    assert [tuple(r) for r in frames["sample"].tolist()] == naive["sample"]
    assert {k: naive_counts[k] for k in keys} == counts
    return frames["sample"], counts


def test_a_clean_stream_delivers_every_sample_and_matches_every_checkpoint(man, replay, telemetry):
    rows, c = _check(man, replay, telemetry)
    np.testing.assert_array_equal(rows["index"], np.arange(N))
    C = man.data["checkpoint_samples"]
    assert c == {
        "lost": 0,
        "duplicates": 0,
        "checkpoints": 2 * (N // C + 1),  # the periodic ones and the flush's; the first pair starts the replay
        "mismatches": 0,
        "checkpoint_repeats": 0,
        "unreplayed": 0,
    }
    assert rows["x.flags"][100] & rows["x.flags"][700] & rows["y.flags"][900] & 2  # rails


def test_repeated_frames_are_dropped_and_counted(man, replay, telemetry):
    f = split_frames(telemetry)
    kinds = [frame_kind(man, x) for x in f]
    ck = [k for k, x in enumerate(kinds) if x == "checkpoint"]
    a, b = ck[4] - 3, ck[6] + 2  # a chunk with blocks and checkpoint pairs, repeated as an adapter might
    stale = next(k for k in range(20, len(f)) if kinds[k] == "block")
    stream = b"".join(f[:b] + f[a:b] + f[b:] + f[stale : stale + 1])  # and a single stale block much later
    rows, c = _check(man, replay, stream)
    np.testing.assert_array_equal(rows["index"], np.arange(N))  # every sample once
    B = man.data["block_samples"]
    n_blocks = sum(1 for x in kinds[a:b] if x == "block") + 1
    assert c["duplicates"] == n_blocks * B and c["lost"] == 0 and c["mismatches"] == 0
    assert c["checkpoint_repeats"] == sum(1 for x in kinds[a:b] if x == "checkpoint")


def test_a_gap_of_100000_block_frames_is_counted_exactly(man, replay, telemetry):
    """Frames lost for 100 000 block frames (3.2 million samples: the old 16-bit seq wrapped 48 times):
    the index says how many samples; the replay has no state until the next checkpoint, and the samples
    received before it are counted lost too, exactly."""
    f = split_frames(telemetry)
    kinds = [frame_kind(man, x) for x in f]
    B, C = man.data["block_samples"], man.data["checkpoint_samples"]
    blocks = [k for k, x in enumerate(kinds) if x == "block"]
    cut_from, cut_to = blocks[10], blocks[13]  # blocks 10..12 lost, then the link skips 100 000 blocks
    D = 100_000 * B
    stream = b"".join(f[:cut_from] + [_with_index(x, D) for x in f[cut_to:]])
    rows, c = _check(man, replay, stream)
    first_lost = 10 * B
    resync = C * (13 * B // C + 1)  # the first checkpoint after the gap
    np.testing.assert_array_equal(rows["index"], np.r_[0:first_lost, resync + D : N + D])
    assert c["lost"] == resync + D - first_lost and c["duplicates"] == 0 and c["mismatches"] == 0


def _tampered(man, telemetry, which: int = 3) -> tuple[bytes, int]:
    """The stream with one bit of checkpoint number ``which`` (a periodic one) flipped, its CRC made good."""
    f = split_frames(telemetry)
    ck = [k for k, x in enumerate(f) if frame_kind(man, x) == "checkpoint"]
    k = ck[which]
    p = bytearray(_payload(f[k]))
    p[man.field("checkpoint", "state")["offset"] + 20] ^= 0x04  # inside the state bytes
    f[k] = frame(bytes(p))
    return b"".join(f), int.from_bytes(p[1:5], "little")


def test_a_checkpoint_mismatch_is_reported(man, replay, telemetry):
    stream, at = _tampered(man, telemetry)
    rows, c = _check(man, replay, stream)
    # the replay disagrees with the bad checkpoint, then (resynchronised from it, as from any checkpoint:
    # the firmware's state is what it sends) with the next one: both reported
    assert c["mismatches"] == 2 and c["lost"] == 0
    flagged = rows["index"][(rows["flags"] & (1 << man.flags["mismatch"])) != 0]
    C = man.data["checkpoint_samples"]
    np.testing.assert_array_equal(flagged, np.arange(at - C, at + C))  # the stretches the two checkpoints close
    assert len(rows) == N  # reported, not hidden: the rows are still there, flagged


def _mismatch_log(path, man, telemetry, model_text: str | None = None):
    stream, _ = _tampered(man, telemetry)
    meta = {"manifest": man.data} | ({} if model_text is None else {"model_toml": model_text})
    with LogWriter(path, meta, fsync_s=None) as log:
        log.append(stream)
    return path


def test_log_info_shows_a_mismatch(tmp_path, man, telemetry):
    """log_summary, what ``accelnav log info`` prints, counts the mismatches, and replays with a model given later."""
    info = log_summary(_mismatch_log(tmp_path / "mismatch.acnlog", man, telemetry, load_model().text))
    assert info["mismatches"] == 2 and info["frames"]["sample"] == N and info["lost"] == 0
    assert info["checkpoints"] > 0
    # without the model text the samples cannot be replayed: said, counted, nothing made up
    path2 = _mismatch_log(tmp_path / "nomodel.acnlog", man, telemetry)
    info = log_summary(path2)
    assert info["unreplayed"] == N and info["frames"]["sample"] == 0 and info["warnings"]
    info = log_summary(path2, load_model().text)  # the model given afterwards replays them
    assert info["unreplayed"] == 0 and info["frames"]["sample"] == N and info["mismatches"] == 2


def test_log_info_and_export_commands_say_the_mismatch(tmp_path, man, telemetry, capsys):
    """The commands over it: ``log info --json`` prints log_summary, ``log export`` says the mismatches,
    ``--model`` is the model given afterwards."""
    path = _mismatch_log(tmp_path / "mismatch.acnlog", man, telemetry, load_model().text)
    assert cli_main(["log", "info", str(path), "--json"]) == 0
    assert json.loads(capsys.readouterr().out) == json.loads(json.dumps(log_summary(path)))
    assert cli_main(["log", "export", str(path), "--out", str(tmp_path / "m.csv")]) == 0
    assert "2 mismatches (MISMATCH" in capsys.readouterr().out
    path2 = _mismatch_log(tmp_path / "nomodel.acnlog", man, telemetry)
    model_file = tmp_path / "model.toml"
    model_file.write_text(load_model().text)
    assert cli_main(["log", "info", str(path2), "--json", "--model", str(model_file)]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["unreplayed"] == 0 and info["mismatches"] == 2


def test_hil_reports_a_mismatch(man, telemetry):
    from accelnav.hil_sim.sim.sensor import simulate
    from accelnav.hil_sim.targets import hil

    model = load_model()
    run = simulate(model, "stop_and_go", 6.0, 4)
    sil = hil.run_sil(model, hil.stimulus(man, run))
    good = hil.compare(model, run, sil)
    assert "no mismatch" in hil.format_comparison(good) and good.link["SIL"]["mismatches"] == 0
    bad, _ = _tampered(man, sil, which=2)
    c = hil.compare(model, run, sil, bad)
    text = hil.format_comparison(c)
    assert "PIL: " in text and "2 MISMATCHED" in text and c.pil_equal_sil is False


def _damage(data: bytes, rng, n_ops: int) -> bytes:
    b = bytearray(data)
    for _ in range(n_ops):
        p = int(rng.integers(0, len(b)))
        kind = int(rng.integers(0, 4))
        if kind == 0:
            b[p] ^= 1 << int(rng.integers(0, 8))
        elif kind == 1:
            del b[p : p + int(rng.integers(1, 5))]
        elif kind == 2:
            b[p:p] = bytes(rng.integers(0, 256, int(rng.integers(1, 30)), dtype=np.uint8))
        else:
            b[p:p] = b"\0"
    return bytes(b)


@pytest.mark.parametrize("seed", range(12))
def test_damaged_compact_frames_are_never_accepted(man, replay, telemetry, seed):
    """Random damage; the oracle: a frame is accepted iff its exact encoding survives as a whole segment.
    The rows are then exactly those of the surviving frames, and the replay never disagrees with a
    checkpoint (it would if a damaged input or state got through)."""
    rng = np.random.default_rng(seed)
    original = {x[:-1] for x in split_frames(telemetry)}
    stream = _damage(telemetry, rng, 60)
    survivors = b"".join(seg + b"\0" for seg in stream.split(b"\0")[:-1] if seg in original)
    got, stats = decode_all(man, stream, replay)
    want, _ = decode_all(man, survivors, replay)
    np.testing.assert_array_equal(got["sample"], want["sample"])
    for n in ("block", "checkpoint"):
        assert got[n].tobytes() == want[n].tobytes()
    assert stats.mismatches == 0


@pytest.mark.parametrize("model", [None, str(DUTY_MODEL)])
def test_bytes_per_sample_meet_the_budget(model):
    """At most 12 B per sample for the two axes at full rate, checkpoints included (the old sample frame:
    87 B analog, 99 B duty cycle)."""
    man = manifest(model)
    fr = man.frames
    per = fr["block"]["wire_size"] / man.data["block_samples"]
    per += len(man.axes) * fr["checkpoint"]["wire_size"] / man.data["checkpoint_samples"]
    assert per <= 12.0, per
    assert fr["sample"]["wire_size"] / per > 8


def test_a_block_lost_right_after_a_checkpoint(man, replay, telemetry):
    """The checkpoint before the gap closes the stretch before it (checked) but is no state for the samples
    after the gap: the replay waits for the next one."""
    f = split_frames(telemetry)
    kinds = [frame_kind(man, x) for x in f]
    k = next(k for k in range(len(f)) if kinds[k] == "checkpoint" and kinds[k + 1] == "checkpoint" and k > 10)
    at = int.from_bytes(_payload(f[k])[1:5], "little")
    rows, c = _check(man, replay, b"".join(f[: k + 2] + f[k + 3 :]))
    C, B = man.data["checkpoint_samples"], man.data["block_samples"]
    np.testing.assert_array_equal(rows["index"], np.r_[0:at, at + C : N])
    assert c["lost"] == C and c["mismatches"] == 0 and c["duplicates"] == 0
    assert c["checkpoints"] == 2 * (N // C + 1) - 2  # the one after the gap starts the replay again
    assert B <= C


def test_recorder_reconnects_and_counts_the_gap_in_samples(tmp_path, man, telemetry):
    """A pulled cable in the compact mode: the gap is counted from the sample index, the samples received
    after it before the next checkpoint too, and the log decodes to the same rows."""
    import io

    from support.link_server import server

    from accelnav.link.recorder import Recorder, Status, decode_log

    f = split_frames(telemetry)
    kinds = [frame_kind(man, x) for x in f]
    blocks = [k for k, x in enumerate(kinds) if x == "block"]
    a, b = blocks[12], blocks[20]  # blocks 12..19 never arrive; the second connection repeats 3 frames
    url, th, _ = server([b"".join(f[:a]), b"".join(f[a - 3 : a] + f[b:])], down_s=0.5)
    rec = Recorder(url, tmp_path / "c.acnlog", man, model_text=load_model().text, status=Status(io.StringIO()))
    C, B = man.data["checkpoint_samples"], man.data["block_samples"]
    resync = C * (20 * B // C + 1)
    res = rec.run(max_frames=12 * B + N - resync, duration=60)
    rec.close()
    th.join(30)
    assert res.reason == "frames", res
    g = res.gaps[0]
    assert (g["index_before"], g["index_after"], g["frames_lost"]) == (12 * B - 1, resync, resync - 12 * B)
    d = decode_log(tmp_path / "c.acnlog")
    np.testing.assert_array_equal(d.frames["sample"]["index"], np.r_[0 : 12 * B, resync:N])
    assert d.stats["lost"] == resync - 12 * B and d.stats["mismatches"] == 0


@pytest.mark.parametrize("seed", range(8))
def test_repeats_and_damage_agree_with_the_frame_by_frame_rule(man, replay, telemetry, seed):
    """Runs of repeated frames and damaged bytes together: the vectorised decoder (which takes runs of
    frames that follow on in bulk), fed whole and in pieces, and the naive one (the rule frame by frame)
    deliver the same rows and counts, and no checkpoint disagrees with the replay."""
    rng = np.random.default_rng(100 + seed)
    f = split_frames(telemetry)
    parts, at = [], 0
    for e in np.sort(rng.choice(np.arange(20, len(f)), 6, replace=False)).tolist():
        k = int(rng.integers(1, 15))
        parts += f[at:e] + f[e - k : e]
        at = e
    stream = bytearray(b"".join(parts + f[at:]))
    for p in rng.integers(0, len(stream), 5):
        stream[p] ^= 0x5A
    _, c = _check(man, replay, bytes(stream), seed=seed)
    assert c["mismatches"] == 0 and c["duplicates"] > 0


def test_replays_on_threads_agree_with_the_frame_by_frame_rule(man, replay, telemetry, monkeypatch):
    """The axes' replays run on threads for large batches; forced on for this small stream (repeats and
    damage too), the rows and counts are still the naive decoder's."""
    import accelnav.link.compact as compact

    monkeypatch.setattr(compact, "THREAD_MIN", 1)
    f = split_frames(telemetry)
    stream = bytearray(b"".join(f[:40] + f[30:40] + f[40:]))
    stream[len(stream) // 2] ^= 0x5A
    _, c = _check(man, replay, bytes(stream), seed=5)
    assert c["duplicates"] > 0 and c["lost"] > 0 and c["mismatches"] == 0


def test_duty_cycle_rows_agree_with_the_frame_by_frame_rule():
    """The duty-cycle model's block frames (16-bit T1/T2 counts, widened to the rows' 32-bit fields by the
    row fill; captures that timed out) decode to the naive decoder's rows."""
    dman = manifest(str(DUTY_MODEL))
    fw = HostFirmware(build_firmware(str(DUTY_MODEL)))
    rng = np.random.default_rng(4)
    t2 = np.full((900, 2), dman.data["t2_nominal"])
    t1 = t2 // 2 + rng.integers(-3000, 3000, (900, 2))
    t1[[50, 400], 1] = 0  # no capture: flagged timeout, predicted over
    fw.rx(encode_stimulus(dman, t1=t1, t2=t2) + encode_command(dman, "flush"))
    rows, c = _check(dman, replay_for(dman, load_model(str(DUTY_MODEL))), fw.take(), seed=2)
    assert len(rows) == 900 and c["mismatches"] == 0
    np.testing.assert_array_equal(rows["x.t1"], t1[:, 0])
    assert np.count_nonzero(rows["y.flags"]) == 2


# --------------------------------------------------------------------------
# gain-schedule builds: the state holds a pointer to its schedule row; the checkpoint carries the row's
# index instead (the generated accelnav_AXIS_save / _load), with the skip-following state


@pytest.fixture(scope="module")
def gs(tmp_path_factory):
    """The default model in the gain-schedule form: manifest, replay, and the firmware's compact telemetry of
    N samples with a rail burst on x right before the second checkpoint (the checkpoint is taken while the
    filter follows the skip), single rails later; and the firmware's own states of every sample."""
    from accelnav.hil_sim.targets.firmware import generated

    text = load_model().text
    assert 'form = "covariance" ' in text
    path = tmp_path_factory.mktemp("gs") / "gs.toml"
    path.write_text(text.replace('form = "covariance" ', 'form = "gain_schedule" ', 1))
    model = load_model(path)
    assert model.filter.form == "gain_schedule"
    gman = manifest(str(path))
    C = gman.data["checkpoint_samples"]
    code = 2048 + np.random.default_rng(22).integers(-300, 300, (N, 2))
    code[C - 3 : C, 0] = 0  # rails: skipped, the filter follows them past the checkpoint at C
    code[700, 0] = 4095
    code[3 * C - 1, 1] = 0
    mod = build_firmware(str(path))
    fw = HostFirmware(mod)
    fw.rx(encode_stimulus(gman, code=code) + encode_command(gman, "flush"))
    own = HostFirmware(mod)  # the state mode at decimation 1: the firmware's own states of every sample
    own.rx(encode_command(gman, "mode_states") + encode_stimulus(gman, code=code))
    states = decode_all(gman, own.take())[0]["sample"]
    assert len(states) == N
    return {
        "man": gman,
        "replay": replay_for(gman, model),
        "stream": fw.take(),
        "states": states,
        "files": generated(str(path)),
        "model": model,
    }


def _ck_image(man, f: bytes) -> tuple[int, int, bytes]:
    """(index, axis, image bytes) of a checkpoint frame."""
    p = _payload(f)
    return int.from_bytes(p[1:5], "little"), p[6], p[man.field("checkpoint", "state")["offset"] :]


def _gs_row_at(man, axis: int) -> tuple[int, int]:
    r = man.data["checkpoint_rows"][axis]
    return r["offset"], r["rows"]


def _assert_own_states(man, rows, states) -> None:
    """The replayed rows carry the firmware's own states of their samples, bit for bit."""
    want = states[np.searchsorted(states["index"], rows["index"])]
    np.testing.assert_array_equal(want["index"], rows["index"])
    for ax in man.axes:
        for st in "ruae":
            np.testing.assert_array_equal(rows[f"{ax}.{st}"], want[f"{ax}.{st}"], err_msg=f"{ax}.{st}")


def test_gain_schedule_compact_round_trip_follows_skips(gs):
    """A gain-schedule build streams block and checkpoint frames; the host's replay matches every checkpoint
    (a pointer-free image), and its rows are the firmware's own states. The checkpoint taken while the
    filter follows the rail burst carries the following flag (k's bit 31) and a non-zero deviation block;
    after a gap the replay starts from that very checkpoint and still matches the firmware bit for bit."""
    man, replay = gs["man"], gs["replay"]
    C, B = man.data["checkpoint_samples"], man.data["block_samples"]
    assert (
        man.frames["checkpoint"]["size"] == man.field("checkpoint", "state")["offset"] + 88
    )  # the image: 88 B per axis, the row a u32 index
    rows, c = _check(man, replay, gs["stream"], seed=3)
    np.testing.assert_array_equal(rows["index"], np.arange(N))
    assert c["mismatches"] == 0 and c["lost"] == 0 and c["checkpoints"] == 2 * (N // C + 1)
    _assert_own_states(man, rows, gs["states"])
    assert (rows["x.flags"][C - 3 : C] & 1).all() and rows["x.flags"][700] & 2  # skipped, rail
    # the image of x before sample C: following (k's bit 31) with a deviation; its row an index in the table
    f = split_frames(gs["stream"])
    ck = {(i, a): img for i, a, img in (_ck_image(man, x) for x in f if frame_kind(man, x) == "checkpoint")}
    off, nrows = _gs_row_at(man, 0)
    nb = man.data["state_bytes"][0]
    img = ck[(C, 0)]
    k = int.from_bytes(img[nb - 8 : nb - 4], "little")  # the image ends with k and overflow
    assert k == 0x80000000 | C, hex(k)
    assert any(img[off + 4 : nb - 8]), "no deviation carried"  # the seven deviation words follow the row
    assert 0 < int.from_bytes(img[off : off + 4], "little") < nrows
    assert int.from_bytes(ck[(C, 1)][nb - 8 : nb - 4], "little") == C  # y: not following
    # blocks before C lost: the replay starts from the following checkpoint, and still matches
    kinds = [frame_kind(man, x) for x in f]
    blocks = [k for k, x in enumerate(kinds) if x == "block"]
    cut = blocks[C // B - 3 : C // B]  # the three blocks before sample C
    rows, c = _check(man, replay, b"".join(x for k, x in enumerate(f) if k not in cut), seed=4)
    np.testing.assert_array_equal(rows["index"], np.r_[0 : C - 3 * B, C:N])
    assert c["mismatches"] == 0 and c["lost"] == 3 * B
    _assert_own_states(man, rows, gs["states"])


def _with_row(man, f: bytes, row: int) -> bytes:
    """The checkpoint frame with its image's row index set to ``row``, its CRC made good."""
    p = bytearray(_payload(f))
    off, _ = _gs_row_at(man, p[6])
    at = man.field("checkpoint", "state")["offset"] + off
    p[at : at + 4] = row.to_bytes(4, "little")
    return frame(bytes(p))


@pytest.mark.parametrize("bad", ["rows", "2**32-1"])
def test_gain_schedule_checkpoint_with_a_row_outside_the_table_is_refused(gs, bad):
    """A checkpoint whose row index lies outside the schedule's table (its CRC good) is refused as damaged
    by both decoders: the replay goes on from its own state and the next checkpoint matches; when that
    checkpoint was to restart the replay after a gap, the samples wait for the next good one (counted
    lost). The index just inside the table is taken (and then disagrees: a mismatch)."""
    man, replay = gs["man"], gs["replay"]
    C, B = man.data["checkpoint_samples"], man.data["block_samples"]
    f = split_frames(gs["stream"])
    kinds = [frame_kind(man, x) for x in f]
    at = next(k for k, x in enumerate(f) if kinds[k] == "checkpoint" and _ck_image(man, x)[:2] == (2 * C, 0))
    _, nrows = _gs_row_at(man, 0)
    value = nrows if bad == "rows" else 2**32 - 1
    tampered = f[:at] + [_with_row(man, f[at], value)] + f[at + 1 :]
    rows, c = _check(man, replay, b"".join(tampered), seed=5)
    np.testing.assert_array_equal(rows["index"], np.arange(N))
    assert c["mismatches"] == 0 and c["lost"] == 0 and c["checkpoints"] == 2 * (N // C + 1) - 1
    assert decode_all(man, b"".join(tampered), replay)[1].bad_frames == 1
    _assert_own_states(man, rows, gs["states"])
    # after a gap: the refused checkpoint cannot restart the replay; the next good one does
    blocks = [k for k, x in enumerate(kinds) if x == "block" and k < at]
    gap = tampered[: blocks[-2]] + tampered[blocks[-1] + 1 :]  # the last two blocks before it lost
    rows, c = _check(man, replay, b"".join(gap), seed=6)
    np.testing.assert_array_equal(rows["index"], np.r_[0 : 2 * C - 2 * B, 3 * C : N])
    assert c["lost"] == C + 2 * B and c["mismatches"] == 0
    _assert_own_states(man, rows, gs["states"])
    # the last row of the table is an index a firmware may send: taken, and the replay disagrees
    inside = f[:at] + [_with_row(man, f[at], nrows - 1)] + f[at + 1 :]
    _, c = _check(man, replay, b"".join(inside), seed=7)
    assert c["mismatches"] >= 1


def test_gain_schedule_load_refuses_a_row_outside_the_table(gs):
    """The generated accelnav_x_load (the host's replay and any reader of a checkpoint) refuses an image
    whose row index is outside the table and leaves the state untouched; an image inside it loads, and
    saving gives the same bytes back (the pointer became the index and back)."""
    from accelnav.hil_sim.targets.harness import build
    from accelnav.native.cbuild import cache_dir

    files = gs["files"]
    lib, ffi = (m := build(files, cache_dir() / "harness")).lib, m.ffi
    man = gs["man"]
    off, nrows = _gs_row_at(man, 0)
    nb = man.data["state_bytes"][0]
    assert json.loads(files["accelnav.json"])["axes"][0]["checkpoint"]["bytes"] == nb
    s = ffi.new("accelnav_x_t *")
    lib.accelnav_x_init(s)
    for _ in range(300):  # past the first rows of the schedule
        lib.accelnav_x_step(s, 2100)
    img = ffi.new(f"uint8_t[{nb}]")
    lib.accelnav_x_save(s, img)
    good = bytes(ffi.buffer(img))
    row = int.from_bytes(good[off : off + 4], "little")
    assert 0 < row < nrows
    t = ffi.new("accelnav_x_t *")
    for value in (nrows, nrows + 1, 2**31, 2**32 - 1):
        bad = ffi.new(f"uint8_t[{nb}]", good[:off] + value.to_bytes(4, "little") + good[off + 4 :])
        before = bytes(ffi.buffer(t))
        assert not lib.accelnav_x_load(t, bad), value
        assert bytes(ffi.buffer(t)) == before  # untouched
    # the deviation's zoom past codegen.follow.ZOOM_MAX: no shift in the follow C could take it
    from accelnav.codegen.emit_c import _fields_checkpoint, _fields_fixed, _struct_offsets
    from accelnav.codegen.follow import ZOOM_MAX
    from accelnav.codegen.ranges import plan_axis

    T = "accelnav_x"
    zoff = _struct_offsets(_fields_checkpoint(_fields_fixed(plan_axis(gs["model"], 0, "gain_schedule"), T), T))["z"]
    for value in (ZOOM_MAX + 1, 2**32 - 1):
        bad = ffi.new(f"uint8_t[{nb}]", good[:zoff] + value.to_bytes(4, "little") + good[zoff + 4 :])
        assert not lib.accelnav_x_load(t, bad), value
    img2 = good[:zoff] + ZOOM_MAX.to_bytes(4, "little") + good[zoff + 4 :]
    assert lib.accelnav_x_load(t, ffi.new(f"uint8_t[{nb}]", img2))
    for value in (row, nrows - 1, 0):
        img2 = good[:off] + value.to_bytes(4, "little") + good[off + 4 :]
        assert lib.accelnav_x_load(t, ffi.new(f"uint8_t[{nb}]", img2))
        back = ffi.new(f"uint8_t[{nb}]")
        lib.accelnav_x_save(t, back)
        assert bytes(ffi.buffer(back)) == img2
    # the host's replay kernel given such an image: the stretch runs from init, reported (never past the table)
    bad = np.frombuffer(good[:off] + nrows.to_bytes(4, "little") + good[off + 4 :], np.uint8)
    replay = gs["replay"]
    rows = np.zeros(4, man.dtypes["sample"])
    code = np.zeros(4, np.uint8)
    one = (np.zeros(1, np.int64), np.full(1, 4, np.int64))  # one stretch: samples 0..3
    fin, nbad = replay.run(0, *one, bad[None], code, np.full(4, 2100), None, rows)
    assert nbad.tolist() == [1] and int.from_bytes(fin[0, off : off + 4].tobytes(), "little") < nrows
    fin, nbad = replay.run(0, *one, np.frombuffer(good, np.uint8)[None], code, np.full(4, 2100), None, rows)
    assert nbad.tolist() == [0]
    # the loaded state steps exactly as the one it was saved from
    lib.accelnav_x_load(t, ffi.new(f"uint8_t[{nb}]", good))
    for code in (2100, 0, 0, 2100, 1990):  # a skip included
        assert lib.accelnav_x_step(s, code) == lib.accelnav_x_step(t, code)
        lib.accelnav_x_save(s, img)
        lib.accelnav_x_save(t, back)
        assert bytes(ffi.buffer(img)) == bytes(ffi.buffer(back))


def test_covariance_checkpoint_image_is_the_state_struct(man):
    """The covariance form's checkpoint image (accelnav_x_save) is its state struct's bytes, as the firmware
    sent them before images existed: older compact logs replay as before."""
    from accelnav.hil_sim.targets.firmware import generated
    from accelnav.hil_sim.targets.harness import build
    from accelnav.native.cbuild import cache_dir

    m = build(generated(None), cache_dir() / "harness")
    lib, ffi = m.lib, m.ffi
    s = ffi.new("accelnav_x_t *")
    lib.accelnav_x_init(s)
    img = ffi.new(f"uint8_t[{man.data['state_bytes'][0]}]")
    for code in (2100, 0, 2000, 2300):
        lib.accelnav_x_step(s, code)
        lib.accelnav_x_save(s, img)
        assert bytes(ffi.buffer(img)) == bytes(ffi.buffer(s))
    assert "checkpoint_rows" not in man.data
