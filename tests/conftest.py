"""Shared fixtures and helpers for the accelnav test suite."""

from __future__ import annotations

import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from accelnav.model.load import DEFAULT_MODEL, load_model, loads_model
from accelnav.resources import models_dir

# asserts in the shared helpers report their operands as the tests' own do
pytest.register_assert_rewrite("support")

REPO = Path(__file__).resolve().parents[1]  # the checkout: for ../shared and for reading docs only
TESTS = Path(__file__).resolve().parent
# helpers the tests share (never tests themselves): imported as ``from support import realdata``, since
# pytest puts this folder (the root conftest's) on sys.path; SUPPORT for the scripts run as programs
SUPPORT = TESTS / "support"
MODELS = models_dir()
SHARED_DATA = REPO.parent / "shared" / "data"


@pytest.fixture(scope="session")
def default_model():
    return load_model(DEFAULT_MODEL)


@pytest.fixture(scope="session")
def duty_model():
    return load_model(MODELS / "adxl202_duty.toml")


@pytest.fixture(scope="module", params=["default", "duty"])
def model(request, default_model, duty_model):
    """Each example sensor in turn, the analog default and the duty-cycle part (a module may override it)."""
    return default_model if request.param == "default" else duty_model


@pytest.fixture
def own_steady_cache(tmp_path, monkeypatch):
    """A test's own cache folder and no steady rows held from another test (fastsmooth.steady_gains)."""
    from accelnav.estimate import fastsmooth

    monkeypatch.setenv("ACCELNAV_CACHE_DIR", str(tmp_path / "cache"))
    fastsmooth.clear_steady_cache()
    yield
    fastsmooth.clear_steady_cache()


@pytest.fixture(scope="module")
def avr_tools():
    """simavr and avr-gcc, or a skip saying what is missing (a failure under ACCELNAV_REQUIRE_AVR=1)."""
    import os

    from accelnav.hil_sim.targets import simavr

    try:
        return simavr.require_avr()
    except simavr.AvrError as e:
        if os.environ.get("ACCELNAV_REQUIRE_AVR") == "1":
            pytest.fail(f"ACCELNAV_REQUIRE_AVR=1 but {e}")
        pytest.skip(str(e))


@pytest.fixture(scope="module")
def man():
    """The default model's frame manifest (a module may override it, as test_frames does per model)."""
    from accelnav.hil_sim.targets.firmware import manifest

    return manifest(None)


@pytest.fixture(scope="module")
def replay(man):
    """The host's replay of the default firmware's filter: the compact mode's block frames need it."""
    from accelnav.link.decoder import replay_for

    return replay_for(man, load_model())


def model_text(path: Path = DEFAULT_MODEL) -> str:
    return Path(path).read_text()


def edited_model(replacements: list[tuple[str, str]], base: Path = DEFAULT_MODEL, source: str = "bad.toml"):
    """The default model's text with each (old, new) replaced exactly once, loaded."""
    text = model_text(base)
    for old, new in replacements:
        assert text.count(old) == 1, f"test setup: {old!r} must occur once in {base.name}"
        text = text.replace(old, new)
    return loads_model(text, source=source)


def state_sd(P):
    """The standard deviations sqrt(P_ii) of a covariance (or a stack of them)."""
    return np.sqrt(np.einsum("...ii->...i", P))


def assert_states(x, P, x_ref, P_ref, rtol, what=""):
    """States and covariances equal the reference's within rtol, scaled by the reference's own sigma
    (sqrt(P_ii P_jj) for a covariance entry)."""
    sd = state_sd(P_ref)
    assert_rel_close(x, x_ref, sd, rtol, f"{what} x")
    assert_rel_close(P, P_ref, sd[..., :, None] * sd[..., None, :], rtol, f"{what} P")


def assert_rel_close(actual, ref, scale, rtol, what=""):
    """|actual - ref| <= rtol * (|ref| + scale) elementwise, with a readable failure.

    ``scale`` carries the quantity's own size where ref itself may pass through
    zero (a state's standard deviation, a covariance's sqrt(P_ii P_jj)).
    """
    actual, ref, scale = np.asarray(actual), np.asarray(ref), np.asarray(scale)
    err = np.abs(actual - ref)
    bound = rtol * (np.abs(ref) + scale)
    bad = err > bound
    if bad.any():
        idx = np.unravel_index(np.argmax(np.where(bad, err - bound, -np.inf)), err.shape)
        raise AssertionError(
            f"{what}: {int(bad.sum())} of {err.size} values off; worst at {idx}: "
            f"actual {actual[idx]!r}, reference {ref[idx]!r}, bound {bound[idx]:.3g}"
        )


@pytest.fixture(scope="session")
def wheel(tmp_path_factory):
    """(wheel file, its member names, a folder it is unpacked into): built once per session from the checkout."""
    if not (REPO / "pyproject.toml").is_file():
        pytest.skip("not a source checkout: no wheel to build")
    out = tmp_path_factory.mktemp("dist")
    done = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w", str(out), str(REPO)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    (whl,) = out.glob("accelnav-*.whl")
    site = tmp_path_factory.mktemp("site")
    with zipfile.ZipFile(whl) as z:
        z.extractall(site)
        names = z.namelist()
    return whl, names, site
