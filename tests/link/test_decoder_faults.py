"""The compact decoder's order and counts under the faults of issue 21 (items 3, 4, 5, 7 and garbage_bytes).

The firmware's own C (host board, cffi) makes the telemetry; each test damages it
the way a link or an adapter would and decodes it whole and in pieces of random
size. Asserted: rows come out in strictly increasing index order whatever the
cut, a lone CRC-valid frame far in the future is damage and not the new truth,
power-on frames sent again are repeats and not a reboot (another boot id is),
the samples lost just before a pause or a mode change are counted, and
``garbage_bytes`` does not depend on how the input was cut.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from support.frames import frame_kind, split_frames
from support.naive_decoder import decode_naive

from accelnav.cli import main as cli_main
from accelnav.hil_sim.targets.firmware import HostFirmware, build_firmware, manifest
from accelnav.link.codec import cobs_decode, encode_command, encode_stimulus, frame
from accelnav.link.decoder import Decoder, decode_all
from accelnav.link.logfile import LogWriter
from accelnav.link.manifest import Manifest


@pytest.fixture(scope="module")
def mod():
    return build_firmware(None)


def _stim(man, n: int, seed: int) -> bytes:
    return encode_stimulus(man, code=2048 + np.random.default_rng(seed).integers(-300, 300, (n, 2)))


def _in_pieces(man, replay, stream: bytes, seed: int, pieces: int):
    d = Decoder(man, replay=replay)
    cuts = np.sort(np.random.default_rng(seed).integers(0, len(stream) + 1, pieces - 1))
    got = [d.feed(stream[a:b])["sample"] for a, b in zip(np.r_[0, cuts], np.r_[cuts, len(stream)], strict=True)]
    d.finish()
    return np.concatenate([*got, d.release()]), d.stats


def _all_ways(man, replay, stream: bytes, seeds=range(12), runs: int = 1):
    """Whole, in pieces (seeded), and frame by frame: the same rows and counts, the index strictly increasing
    within each of ``runs`` runs; returns (rows, stats)."""
    whole, stats = decode_all(man, stream, replay)
    rows = whole["sample"]
    for seed in seeds:
        got, st = _in_pieces(man, replay, stream, seed, int(np.random.default_rng(seed).integers(2, 80)))
        idx = got["index"].astype(np.int64)
        assert np.count_nonzero(np.diff(idx) <= 0) == runs - 1, f"seed {seed}: {idx[np.argmin(np.diff(idx))]} then less"
        assert got.tobytes() == rows.tobytes(), seed
        assert (st.lost, st.duplicates, st.bad_frames) == (stats.lost, stats.duplicates, stats.bad_frames), seed
    counts: dict = {}
    naive, _ = decode_naive(man, stream, counts, replay)
    assert [tuple(r) for r in rows.tolist()] == naive["sample"]
    assert (counts["lost"], counts["duplicates"]) == (stats.lost, stats.duplicates)
    return rows, stats


def test_rows_held_over_a_pause_whose_checkpoints_were_lost_stay_in_order(man, replay, mod):
    """Item 3: compact rows, a stop whose checkpoints are lost, the state mode, compact again. The rows held
    since the last checkpoint before the stop came out after the state mode's rows when the bytes arrived
    in pieces (index 1975 -> 768); now they go out first, every sample once."""
    fw = HostFirmware(mod)
    fw.rx(_stim(man, 1000, 1))
    a = fw.take()
    fw.rx(encode_command(man, "stop"))
    stop = [f for f in split_frames(fw.take()) if frame_kind(man, f) != "checkpoint"]  # the flush's checkpoints lost
    fw.rx(encode_command(man, "mode_states") + encode_command(man, "start") + _stim(man, 1000, 2))
    fw.rx(encode_command(man, "mode_compact") + _stim(man, 1000, 3) + encode_command(man, "flush"))
    stream = a + b"".join(stop) + fw.take()
    rows, stats = _all_ways(man, replay, stream)
    np.testing.assert_array_equal(rows["index"], np.arange(3000))
    assert stats.lost == 0 and stats.duplicates == 0


@pytest.mark.parametrize("where", ["block", "checkpoint", "last"])
def test_one_crc_valid_frame_far_in_the_future_is_damage(man, replay, mod, where):
    """Item 4: one frame whose index (CRC made good) jumps 10 million samples ahead. It was taken as the new
    truth and everything after it discarded as repeats (640 of 6000 rows delivered, 9 999 392 lost); now the
    next frame does not agree with it, so it is refused as damaged, and only the samples it carried and
    those up to the next checkpoint (no state to replay them from) are lost. As the stream's very last
    frame (nothing after it to agree) it is refused too."""
    fw = HostFirmware(mod)
    fw.rx(_stim(man, 6000, 4) + encode_command(man, "flush"))
    f = split_frames(fw.take())
    kinds = [frame_kind(man, x) for x in f]
    k = {"block": [i for i, x in enumerate(kinds) if x == "block"][40], "checkpoint": kinds.index("checkpoint", 30)}
    k["last"] = max(i for i, x in enumerate(kinds) if x in ("block", "checkpoint"))
    at = k[where]
    p = bytearray(cobs_decode(f[at][:-1])[:-4])
    p[1:5] = (10_000_000).to_bytes(4, "little")
    stream = b"".join(f[:at] + [frame(bytes(p))] + f[at + 1 :])
    rows, stats = _all_ways(man, replay, stream)
    C = man.data["checkpoint_samples"]
    assert stats.bad_frames == 1 and stats.duplicates == 0
    assert len(rows) + stats.lost == 6000 and stats.lost <= C
    assert (rows["index"] < 6000).all()
    if where == "checkpoint":  # the other axis' checkpoint and the replay carry on: nothing lost
        assert stats.lost == 0


def test_power_on_frames_sent_again_are_repeats_not_a_reboot(man, replay, mod):
    """Item 5: the first frames after power-on (the reset checkpoints, the first blocks) arrive again 4000
    samples later, as a misbehaving adapter or a replayed capture would send them. They were taken as a
    reboot (rows delivered twice, others dropped, thousands counted lost); the run id the frames carry now
    says they belong to the run under way: repeats, dropped and counted."""
    fw = HostFirmware(mod)
    fw.rx(_stim(man, 4000, 5))
    f = split_frames(fw.take())
    fw.rx(_stim(man, 3000, 6) + encode_command(man, "flush"))
    again = f[:12]
    stream = b"".join(f + again) + fw.take()
    rows, stats = _all_ways(man, replay, stream)
    np.testing.assert_array_equal(rows["index"], np.arange(7000))
    B = man.data["block_samples"]
    assert stats.lost == 0 and stats.duplicates == B * sum(frame_kind(man, x) == "block" for x in again)


def test_a_reboot_and_a_reset_start_new_runs(man, replay, mod):
    """The other side of item 5: a power-on with another boot id, and a reset command (run id + 1), each start
    a new run whose index begins at 0 again; frames of the runs before, sent again later, are repeats."""
    fw = HostFirmware(mod, boot_id=7)
    fw.rx(_stim(man, 2000, 7) + encode_command(man, "flush"))
    first = fw.take()
    fw2 = HostFirmware(mod, boot_id=8)
    fw2.rx(_stim(man, 1000, 8) + encode_command(man, "reset") + _stim(man, 500, 9) + encode_command(man, "flush"))
    second = split_frames(fw2.take())
    stream = first + b"".join(second) + b"".join(split_frames(first)[:6])  # and the first boot's frames again
    rows, stats = _all_ways(man, replay, stream, runs=3)
    np.testing.assert_array_equal(rows["index"], np.r_[0:2000, 0:1000, 0:500])
    assert stats.lost == 0 and stats.duplicates > 0


def test_samples_lost_before_a_pause_are_counted(man, replay, mod):
    """Item 7, a pause: the last block before a stop lost together with the stop's checkpoints. Its samples
    were missing and counted nowhere (lost 0); the next run's checkpoints say where the stream paused."""
    fw = HostFirmware(mod)
    fw.rx(_stim(man, 1000, 10))
    a = fw.take()
    fw.rx(encode_command(man, "stop"))
    stop = split_frames(fw.take())
    assert [frame_kind(man, x) for x in stop] == ["block", "checkpoint", "checkpoint", "ack"]
    fw.rx(_stim(man, 300, 11) + encode_command(man, "start") + _stim(man, 1000, 12) + encode_command(man, "flush"))
    stream = a + stop[-1] + fw.take()
    rows, stats = _all_ways(man, replay, stream)
    B = man.data["block_samples"]
    gone = 1000 - 1000 // B * B  # the partial block the stop sent
    np.testing.assert_array_equal(rows["index"], np.r_[0 : 1000 - gone, 1300:2300])
    assert stats.lost == gone and stats.duplicates == 0


def test_the_first_state_frame_after_a_mode_change_is_counted_lost(man, replay, mod):
    """Item 7, a mode change: the first sample frame after mode_states lost (no sample frame before it to
    count from). The compact checkpoints carry the seq the next sample frame will have."""
    fw = HostFirmware(mod)
    fw.rx(_stim(man, 1000, 13))
    a = fw.take()
    fw.rx(encode_command(man, "mode_states") + _stim(man, 500, 14))
    f = split_frames(fw.take())
    first = next(i for i, x in enumerate(f) if frame_kind(man, x) == "sample")
    stream = a + b"".join(f[:first] + f[first + 1 :])
    rows, stats = _all_ways(man, replay, stream)
    np.testing.assert_array_equal(rows["index"], np.r_[0:1000, 1001:1500])
    assert stats.lost == 1 and stats.duplicates == 0


def test_garbage_bytes_do_not_depend_on_the_cut(man, replay, mod):
    """Garbage longer than any frame, split across reads, was counted short (the tail kept past a frame's
    length was counted once, the segment at its delimiter as one byte more than a frame)."""
    fw = HostFirmware(mod)
    fw.rx(_stim(man, 2000, 15))
    s = bytearray(fw.take())
    rng = np.random.default_rng(16)
    for at, n in ((1000, 700), (9000, 257), (20000, 3000)):
        s[at:at] = bytes(rng.integers(1, 256, n, dtype=np.uint8))  # no zero: one long segment
    s += bytes(rng.integers(1, 256, 500, dtype=np.uint8))  # and an unfinished one at the end
    stream = bytes(s)
    d = Decoder(man, replay=replay)
    d.feed(stream)
    d.finish()
    want = d.stats.garbage_bytes
    for seed in range(8):
        _, st = _in_pieces(man, replay, stream, seed, int(np.random.default_rng(seed).integers(10, 400)))
        assert st.garbage_bytes == want, seed
    assert want >= 700 + 257 + 3000 + 500


def test_a_manifest_of_another_protocol_is_refused_in_one_line(man, tmp_path, capsys):
    old = dict(man.data, protocol_version=2)
    with pytest.raises(ValueError, match=r"telemetry protocol 2: this accelnav reads protocol 3") as e:
        Manifest(old)
    assert "\n" not in str(e.value)
    path = tmp_path / "old.acnlog"
    with LogWriter(path, {"manifest": old}, fsync_s=None) as log:
        log.append(b"\0")
    assert cli_main(["log", "info", str(path), "--json"]) == 2
    err = capsys.readouterr().err.strip()
    assert "telemetry protocol 2" in err and "\n" not in err and "Traceback" not in err


def test_the_decoder_reads_the_generator_s_protocol():
    from accelnav.codegen.frames import PROTOCOL_VERSION
    from accelnav.link.manifest import PROTOCOL

    assert PROTOCOL == PROTOCOL_VERSION
    assert json.loads(json.dumps(manifest(None).data))["protocol_version"] == PROTOCOL
