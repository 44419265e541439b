"""Logs from elsewhere and outputs that must appear whole (issue 21, items 9-12): malformed headers, a log
with no samples, a streamed ``log info``, outputs renamed into place, ``--out`` naming a directory."""

from __future__ import annotations

import json
import struct
import tracemalloc
import zlib

import numpy as np
import pytest

from accelnav.cli import main
from accelnav.hil_sim.targets.firmware import HostFirmware, build_firmware
from accelnav.link.codec import encode_command, encode_stimulus
from accelnav.link.logfile import MAGIC, LogWriter
from accelnav.link.manifest import Manifest
from accelnav.model.load import load_model


def _one_line(argv, capsys) -> str:
    status = main([str(a) for a in argv])
    err = capsys.readouterr().err
    assert status == 2 and err.startswith("accelnav: error: ") and err.count("\n") == 1, err[:800]
    assert len(err) < 400, err[:400]
    return err


@pytest.fixture(scope="module")
def meta():
    model = load_model()
    return {"manifest": Manifest.for_model(model).data, "model_toml": model.text, "source": "test"}


def _log(path, meta, parts=()):
    with LogWriter(path, meta, fsync_s=None) as log:
        for p in parts:
            log.append(p)
            log.flush()
    return path


def _raw_header(path, head: bytes):
    path.write_bytes(MAGIC + struct.pack("<I", len(head)) + head + struct.pack("<I", zlib.crc32(head)))
    return path


@pytest.mark.parametrize(
    "head, said",
    [
        (b'{"format": "accelnav-log/1", ', "not UTF-8 JSON"),  # cut JSON, CRC valid
        (b'{"format": "accelnav-log/1", "x": "\xff\xfe"}', "not UTF-8 JSON"),
        (b'["accelnav-log/1"]', "JSON list, not an object"),
        (b'{"format": "accelnav-log/1"}', "no frame manifest"),
        (b'{"format": "accelnav-log/1", "manifest": "frames"}', "no frame manifest"),
        (b'{"format": "accelnav-log/1", "manifest": {"frames": 3}}', "manifest is not valid"),
        (b'{"format": "accelnav-log/1", "manifest": {}, "model_toml": 5}', "model_toml is not text"),
    ],
)
def test_malformed_log_headers_are_one_line(tmp_path, capsys, head, said):
    path = _raw_header(tmp_path / "bad.acnlog", head)
    for argv in (["log", "info", path], ["log", "export", path, "--out", tmp_path / "x.csv"]):
        assert said in _one_line(argv, capsys)


def test_a_header_declaring_gigabytes_is_not_read(tmp_path, capsys):
    path = tmp_path / "big.acnlog"
    path.write_bytes(MAGIC + struct.pack("<I", 0xFFFF_FFF0) + b"{}")
    assert "declares 4294967280 bytes" in _one_line(["log", "info", path], capsys)


@pytest.mark.parametrize("command", ["smooth", "filter", "fit-bias", "tune", "log export"])
def test_a_log_with_no_samples_is_refused_by_every_command(tmp_path, capsys, meta, command):
    path = _log(tmp_path / "silent.acnlog", meta)  # a silent device: the header and nothing else
    out = tmp_path / ("o.csv" if command == "log export" else "o.toml" if command in ("fit-bias", "tune") else "o.npz")
    argv = [*command.split(), path, "--out", out] + (["--max-evaluations", "10"] if command == "tune" else [])
    assert "0 sample frames" in _one_line(argv, capsys)
    assert not out.exists()


def test_log_info_on_a_log_with_no_samples_still_answers(tmp_path, capsys, meta):
    path = _log(tmp_path / "silent.acnlog", meta)
    assert main(["log", "info", str(path), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["frames"].get("sample", 0) == 0 and info["index_first"] is None


def test_log_info_streams_the_log(tmp_path, capsys, meta):
    junk = np.random.default_rng(2).integers(0, 256, 1 << 16, dtype=np.uint8).tobytes()
    path = _log(tmp_path / "big.acnlog", meta, [junk] * 96)  # 6 MiB of link bytes
    size = path.stat().st_size
    tracemalloc.start()
    try:
        status = main(["log", "info", str(path), "--json"])
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    info = json.loads(capsys.readouterr().out)
    assert status == 0 and info["chunks"] == 96 and info["bytes"] == 96 << 16
    assert peak < size / 4, f"peak {peak / 1e6:.1f} MB for a {size / 1e6:.1f} MB log"


@pytest.fixture(scope="module")
def telemetry(meta):
    man = Manifest(meta["manifest"])
    fw = HostFirmware(build_firmware(None))
    fw.rx(encode_command(man, "mode_states"))
    fw.take()
    fw.rx(encode_stimulus(man, code=2048 + np.random.default_rng(8).integers(-60, 60, (600, 2))))
    return fw.take()


def test_log_export_never_leaves_a_partial_csv(tmp_path, capsys, meta, telemetry, monkeypatch):
    path = _log(tmp_path / "x.acnlog", meta, [telemetry])
    out = tmp_path / "out" / "x.csv"
    real = np.savetxt

    def dies_half_way(fname, X, *a, **k):  # as a kill -9 or a full disk would, after the first rows
        real(fname, X[:10], *a, **k)
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(np, "savetxt", dies_half_way)
    err = _one_line(["log", "export", path, "--out", out], capsys)
    assert "No space left on device" in err
    assert not out.exists() and list(out.parent.iterdir()) == []  # no partial file, no temporary left
    monkeypatch.setattr(np, "savetxt", real)
    assert main(["log", "export", str(path), "--out", str(out)]) == 0
    assert np.loadtxt(out, delimiter=",", skiprows=1).shape[0] == 600 and list(out.parent.iterdir()) == [out]


@pytest.mark.parametrize("command", ["smooth", "filter", "log export"])
def test_out_naming_a_directory_is_refused_before_the_work(tmp_path, capsys, meta, telemetry, command):
    path = _log(tmp_path / "x.acnlog", meta, [telemetry])
    target = tmp_path / ("d.csv" if command == "log export" else "d.npz")
    target.mkdir()
    assert "is a directory" in _one_line([*command.split(), path, "--out", target], capsys)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([target.name, path.name])  # no d.npz.tmp
    assert list(target.iterdir()) == []
