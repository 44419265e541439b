"""Issue 21 item 1 at the log: opening someone else's log compiles only C generated from a model that
passed the loader. A log is made with the project's LogWriter, then its embedded model text or its
manifest is edited as an attacker would (keeping the sha256 they carry consistent)."""

from __future__ import annotations

import hashlib
import json

import pytest
from conftest import model_text

from accelnav.cli import main
from accelnav.codegen.generated import generated_files
from accelnav.link.logfile import LogWriter
from accelnav.model.load import load_model

HOSTILE = "x */ __attribute__((constructor)) static void own(void) { } /* y"


@pytest.fixture
def no_compiler(monkeypatch):
    import accelnav.native.cbuild as cbuild

    calls = []

    def refuse(*a, **k):
        calls.append(a[0] if a else "?")
        raise AssertionError("a C compiler was invoked while opening a log")

    monkeypatch.setattr(cbuild, "build_module", refuse)
    return calls


def _log(path, text: str, manifest: dict) -> None:
    with LogWriter(path, {"manifest": manifest, "model_toml": text, "source": "test"}, fsync_s=None) as log:
        log.append(b"\x00garbage\x00", t_ns=1)


def _compact_manifest() -> dict:
    man = json.loads(generated_files(load_model())["acnframe.json"])
    assert "block" in man["frames"]  # the compact mode: opening the log builds the replay
    return man


def test_log_with_hostile_model_name_refused_in_one_line(tmp_path, no_compiler, capsys):
    text = model_text().replace('name = "adxl250_default"', f'name = "{HOSTILE}"')
    man = _compact_manifest()
    man["model"], man["model_sha256"] = HOSTILE, hashlib.sha256(text.encode()).hexdigest()
    path = tmp_path / "theirs.acnlog"
    _log(path, text, man)
    for argv in (["log", "info", str(path)], ["log", "export", str(path), "--out", str(tmp_path / "x.csv")]):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and f"{path}:model_toml: model.name: got " in err, err
    assert no_compiler == []
    assert not (tmp_path / "x.csv").exists()


def test_log_manifest_not_its_models_builds_nothing(tmp_path, no_compiler, capsys):
    """The manifest is the log's too: axis names from it were pasted into the replay's C. A manifest that
    is not the one its (valid) model generates gets no replay: a warning, nothing compiled."""
    man = _compact_manifest()
    man["axes"] = ["x(void){} int own", "y"]
    path = tmp_path / "theirs.acnlog"
    _log(path, model_text(), man)
    assert main(["log", "info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "not the one its model generates" in out
    assert no_compiler == []
