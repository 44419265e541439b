"""A log's header is someone else's data: every malformed one is refused in one line (LogError).

Found by the structure-aware log fuzz (tests/link/test_decoder_fuzz.py): a header with a valid CRC
but a missing or malformed manifest, or JSON that is not an object, ended in tracebacks (KeyError,
TypeError, AttributeError, IndexError ... from the decoder's constructor or later, where a manifest
that constructs still does not fit the decoder: block slots against block_samples, a field past
its frame, an object dtype). No C is built for a refused header.
"""

from __future__ import annotations

import copy
import json
import struct
import zlib

import pytest
from conftest import MODELS

from accelnav.hil_sim.targets.firmware import manifest
from accelnav.link.logfile import MAGIC, LogError, LogWriter
from accelnav.link.manifest import Manifest, check_manifest
from accelnav.link.recorder import decode_log
from accelnav.link.replay import Replay, ReplayError
from accelnav.model.load import DEFAULT_MODEL, load_model


@pytest.fixture(scope="module")
def meta():
    return {"manifest": manifest(None).data, "model_toml": DEFAULT_MODEL.read_text(), "source": "test"}


def _log(tmp_path, meta) -> str:
    path = tmp_path / "x.acnlog"
    with LogWriter(path, meta) as log:
        log.append(b"\0\0")
    return path


def _raw_header_log(tmp_path, head: bytes) -> str:
    path = tmp_path / "raw.acnlog"
    path.write_bytes(MAGIC + struct.pack("<I", len(head)) + head + struct.pack("<I", zlib.crc32(head)))
    return path


def _edited(meta, edit) -> dict:
    m = copy.deepcopy(meta)
    edit(m)
    return m


HOSTILE = "x(void){} __attribute__((constructor)) static void own(void){} void acnr_x"


def _set_frame_field(name, field, key, value):
    def edit(m):
        for f in m["manifest"]["frames"][name]["fields"]:
            if f["name"] == field:
                f[key] = value

    return edit


BAD_META = {
    "no manifest": lambda m: m.pop("manifest"),
    "manifest not a table": lambda m: m.update(manifest=[1, 2]),
    "axes not names": lambda m: m["manifest"].update(axes=[1, 2]),
    "the same axis twice": lambda m: m["manifest"].update(axes=["x", "x"]),
    "an axis name with a newline": lambda m: m["manifest"].update(axes=["x\ny", "y"]),
    "object dtype": _set_frame_field("sample", "seq", "dtype", "O"),
    "field past its frame": _set_frame_field("block", "index", "offset", 250),
    "no block_samples": lambda m: m["manifest"].pop("block_samples"),
    "block_samples not the block's slots": lambda m: m["manifest"].update(block_samples=139),
    "frame type not a byte": lambda m: m["manifest"]["frames"]["sample"].update(type=None),
    "no cmd_stop frame": lambda m: m["manifest"]["frames"].pop("cmd_stop"),
    "flags without reset": lambda m: m["manifest"]["flags"].pop("reset"),
    "state_bytes not per axis": lambda m: m["manifest"].update(state_bytes=[64]),
}


@pytest.mark.parametrize("case", sorted(BAD_META))
def test_a_malformed_manifest_is_refused_in_one_line(tmp_path, meta, case, monkeypatch):
    import accelnav.native.cbuild as cbuild

    def no_build(*a, **k):
        raise AssertionError("C was built from a refused header")

    monkeypatch.setattr(cbuild, "build_module", no_build)
    with pytest.raises(LogError) as e:
        decode_log(_log(tmp_path, _edited(meta, BAD_META[case])))
    assert "\n" not in str(e.value) and len(str(e.value)) < 400


@pytest.mark.parametrize(
    "head",
    [b"\xff\xfe{", b"[1, 2]", b'"accelnav-log/1"', b"{", json.dumps({"format": "x" * 100_000}).encode()],
    ids=["not utf-8", "a list", "a string", "cut JSON", "a huge format"],
)
def test_a_header_that_is_not_a_json_object_is_refused_in_one_line(tmp_path, head):
    with pytest.raises(LogError) as e:
        decode_log(_raw_header_log(tmp_path, head))
    assert "\n" not in str(e.value) and len(str(e.value)) < 400


def test_a_model_text_that_is_not_a_string_is_refused_in_one_line(tmp_path, meta):
    with pytest.raises(LogError) as e:
        decode_log(_log(tmp_path, _edited(meta, lambda m: m.update(model_toml=["x"]))))
    assert "\n" not in str(e.value)


def test_the_replay_refuses_a_manifest_whose_axes_are_not_the_models():
    model = load_model()
    data = copy.deepcopy(manifest(None).data)
    data["axes"] = ["y", "x"]  # valid names, not the model's order: the replay would mix the axes up
    with pytest.raises(ReplayError, match="manifest"):
        Replay(Manifest(data), model)


@pytest.mark.parametrize("model", ["adxl250_default.toml", "adxl202_duty.toml"])
@pytest.mark.parametrize("form", [None, "gain_schedule"])
def test_every_generated_manifest_passes(model, form):
    check_manifest(Manifest.for_model(load_model(MODELS / model), form=form).data)
