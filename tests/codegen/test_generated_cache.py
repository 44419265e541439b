"""The generator's output kept in the cache (accelnav.codegen.generated) is compiled by the log replay and
SIL: a tampered or truncated entry is regenerated in one line, never compiled (issue 30). The case as
found: a constructor appended to the cached accelnav.c ran during ``accelnav log info``."""

from __future__ import annotations

import json
import shutil

import pytest
from support.cachekey import private_cache, seal_with_other_key

from accelnav.cli import main
from accelnav.codegen.generated import generated_files
from accelnav.link.logfile import LogWriter
from accelnav.model.load import load_model


@pytest.fixture
def cache(tmp_path, monkeypatch):
    if shutil.which("cc") is None:
        pytest.skip("no C compiler (Debian: gcc)")
    return private_cache(tmp_path, monkeypatch)


def _log(path) -> None:
    """A log of the default model in the compact mode: ``log info`` builds the replay from generated C."""
    model = load_model()
    man = json.loads(generated_files(model)["acnframe.json"])
    assert "block" in man["frames"]
    with LogWriter(path, {"manifest": man, "model_toml": model.text, "source": "test"}, fsync_s=None) as log:
        log.append(b"\x00garbage\x00", t_ns=1)


def _info(path, capsys) -> tuple[str, str]:
    assert main(["log", "info", str(path)]) == 0
    got = capsys.readouterr()
    return got.out, got.err


def test_a_constructor_appended_to_the_cached_c_never_runs(cache, tmp_path, monkeypatch, capsys):
    log = tmp_path / "a.acnlog"
    _log(log)
    clean, err = _info(log, capsys)
    assert err == "" and "\nwarnings  none\n" in clean
    (entry,) = (cache / "cffi").glob("gen-*.json")
    raw = entry.read_bytes()
    files = json.loads(raw[40:])
    marker = tmp_path / "MARKER"
    files["accelnav.c"] += (
        "\n#include <stdio.h>\n__attribute__((constructor)) static void own(void)\n"
        f'{{ FILE *f = fopen("{marker}", "w"); if (f) {{ fputs("owned", f); fclose(f); }} }}\n'
    )
    hostile = json.dumps(files).encode()
    for how in ("edited in place", "sealed under another key"):
        if how == "edited in place":
            entry.write_bytes(raw[:40] + hostile)
        else:
            seal_with_other_key(entry, hostile, tmp_path, monkeypatch)
        out, err = _info(log, capsys)
        assert not marker.exists(), f"{how}: the appended constructor ran"
        assert out == clean, how  # the replay is built and the summary the same
        assert err.count("\n") == 1 and f"cache entry {entry}: its seal does not verify" in err, err
    assert "own(void)" not in entry.read_text(errors="replace")


@pytest.mark.parametrize("keep", [0, 30, 5000])
def test_a_truncated_entry_is_regenerated_in_one_line_and_replay_stays_on(cache, tmp_path, capsys, keep):
    """Before: 'warnings: [... Unterminated string ...]' and no replay, exit 0; SIL a JSONDecodeError."""
    log = tmp_path / "a.acnlog"
    _log(log)
    clean, _ = _info(log, capsys)
    (entry,) = (cache / "cffi").glob("gen-*.json")
    with open(entry, "r+b") as fh:
        fh.truncate(keep)
    out, err = _info(log, capsys)
    assert out == clean and "\nwarnings  none\n" in out
    assert err.count("\n") == 1 and f"cache entry {entry}:" in err and "rebuilt" in err
    assert generated_files(load_model()) == json.loads(entry.read_bytes()[40:])
