"""One accounting for a link: the recorder's summary and ``accelnav log info`` give the same counts for the
same bytes (they disagreed: the recorder left out the compact rows waiting for a checkpoint when the
recording ended, and the unfinished frame at its end)."""

from __future__ import annotations

import numpy as np
from support.loop_record import record_loop

from accelnav.data.logs import log_summary
from accelnav.hil_sim.targets.firmware import HostFirmware, build_firmware, manifest
from accelnav.link.codec import encode_stimulus
from accelnav.model.load import load_model


def test_recorder_summary_and_log_info_agree(tmp_path):
    man = manifest(None)
    fw = HostFirmware(build_firmware(None))
    fw.rx(encode_stimulus(man, code=2048 + np.random.default_rng(3).integers(-300, 300, (1700, 2))))
    data = fw.take()  # no flush: the rows since the last checkpoint wait for one that never comes
    cut = data.index(b"\0", 200) + 1  # between two frames
    data = data[:cut] + b"\x05" * 40 + b"\0" + data[cut:] + data[-150:-1]  # junk, and a torn frame at the end
    out = tmp_path / "counts.acnlog"
    res = record_loop(man, out, data, model_text=load_model().text, duration=1.0)
    info = log_summary(out)  # what ``accelnav log info --json`` prints
    for k in ("lost", "duplicates", "bad_frames", "garbage_bytes"):
        assert res.stats[k] == info[k], k
    assert res.stats["frames"] == info["frames"]
    from accelnav.link.accounting import link_counts

    counts = link_counts(res.stats)
    assert counts == {k: info[k] for k in counts}
    B, C = man.data["block_samples"], man.data["checkpoint_samples"]
    sent = 1700 // B * B  # whole blocks: the last partial one waits for a flush
    assert sent % C, "some rows must wait for a checkpoint at the end"
    assert counts["samples"] == sent and counts["damaged_frames"] == 2 and counts["garbage_bytes"] == 40 + 149
    assert info["counts"].startswith(f"{sent} samples, lost 0, duplicates 0, damaged 2 frames")
