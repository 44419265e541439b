"""Issue 21 items 1, 2 and 6 at the generator: the banner refuses comment-closing text even from a model
built around the loader, --prefix is a C identifier whose files stay inside --out, and the l1 sums of
the range analysis are bounded work whatever the horizon."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys

import numpy as np
import pytest
from conftest import model_text

from accelnav.cli import main
from accelnav.codegen import ranges
from accelnav.codegen.emit_c import emit, write
from accelnav.codegen.frames import emit_frames
from accelnav.model.load import MAX_T_S, load_model


@pytest.fixture(scope="module")
def short_model():
    from accelnav.model.load import loads_model

    return loads_model(model_text().replace("max_run_s = 3600.0", "max_run_s = 60.0"), source="short.toml")


@pytest.mark.parametrize("name", ["x */ int evil; /* y", "a\nb", "caf\u00e9"])
def test_banner_refuses_what_the_loader_would(short_model, name):
    """Defence in depth: a Model made with dataclasses.replace never met the loader."""
    bad = dataclasses.replace(short_model, name=name)
    with pytest.raises(ValueError, match="banner"):
        emit(bad)
    with pytest.raises(ValueError, match="banner"):
        emit(bad, arith="float32")
    man = json.loads(emit(short_model)["accelnav.json"])
    with pytest.raises(ValueError, match="banner"):
        emit_frames(bad, man)


@pytest.mark.parametrize("prefix", ["../escaped", "acn; int x", "/tmp/abs", "int", "a/b", ""])
def test_prefix_refused_nothing_written(tmp_path, monkeypatch, capsys, prefix):
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "out"
    assert main(["codegen", str(load_model().source), "--out", str(out), "--prefix", prefix]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("accelnav: error: --prefix:"), err
    assert list(tmp_path.rglob("*")) == []  # not in --out, not beside it, not in the cwd
    with pytest.raises(ValueError, match="prefix"):
        emit(load_model(), prefix=prefix)


def test_write_keeps_files_inside_out(tmp_path):
    out = tmp_path / "out"
    for name in ("../escaped.c", "/tmp/abs.c", "sub/x.c"):
        with pytest.raises(ValueError, match="inside"):
            write({"ok.h": "", name: ""}, out)
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_l1_steady_bounded_for_a_pole_at_one():
    """phi rounded to 1.0 put a pole at 1 and a horizon of 4e13 terms summed one by one: run in a child
    with a generous timeout (a hang guard, not a timing assertion)."""
    code = (
        "import numpy as np\n"
        "from accelnav.codegen.ranges import _closed, _l1_steady\n"
        "K2 = np.array([0.05, 1e-6])\n"
        "B = np.column_stack([K2, [1.0, 0.0], [0.0, 1.0]])\n"
        "r = _l1_steady(_closed(K2, 1.0), B, 40 * 10**12)\n"
        "assert np.all(np.isfinite(r)) and np.all(r > 0), r\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)


@pytest.mark.parametrize("phi", [1.0, 0.999, 0.9])  # a pole at -0.7 and one near or at 1
def test_l1_tail_bound_never_below_the_sum(monkeypatch, phi):
    """Past L1_EXACT_TERMS the sum is bounded above in closed form: never below the exact sum."""
    K2 = np.array([1.5, 0.2])
    A, B = ranges._closed(K2, phi), np.column_stack([K2, [1.0, 0.0], [0.0, 1.0]])
    horizon = 5000
    monkeypatch.setattr(ranges, "L1_EXACT_TERMS", horizon)
    exact = ranges._l1_steady(A, B, horizon)
    monkeypatch.setattr(ranges, "L1_EXACT_TERMS", 300)
    bounded = ranges._l1_steady(A, B, horizon)
    assert np.all(bounded >= exact * (1 - 1e-12)), (bounded, exact)


@pytest.mark.parametrize("form", ["covariance", "gain_schedule"])
def test_largest_accepted_T_generates(tmp_path, form):
    """The largest T the loader accepts runs codegen to the end (a child with a hang guard)."""
    src = tmp_path / "longT.toml"
    src.write_text(model_text().replace("T = 300.0", f"T = {MAX_T_S!r}"))
    cmd = [sys.executable, "-m", "accelnav", "codegen", str(src), "--form", form, "--out", str(tmp_path / "o")]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "o" / "accelnav.c").exists()
