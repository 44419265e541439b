"""The documentation site: it builds with no warnings (-W), and its generated model-file reference is
the loader's own.

Sphinx and MyST are the `docs` extra. Without them these tests skip and say so; with
ACCELNAV_REQUIRE_DOCS=1 (set by .ci/run, which installs the extra) a missing one is a failure.
"""

from __future__ import annotations

import importlib.util
import math
import os
import re
import subprocess
import sys
import tomllib

import pytest
from conftest import MODELS, REPO

from accelnav.model.load import ModelError, loads_model

DOCS = REPO / "docs"
BUILD_TIMEOUT_S = 240  # the build takes 5-10 s here; this only stops a hung one


def _require(*modules: str) -> None:
    missing = [m for m in modules if importlib.util.find_spec(m) is None]
    if missing:
        reason = f"documentation tools not installed ({', '.join(missing)}): pip install '.[docs]'"
        if os.environ.get("ACCELNAV_REQUIRE_DOCS") == "1":
            pytest.fail(f"ACCELNAV_REQUIRE_DOCS=1 but {reason}")
        pytest.skip(reason)


@pytest.fixture(scope="module")
def docs_ext():
    _require("sphinx", "myst_parser")
    sys.path.insert(0, str(DOCS / "_ext"))
    try:
        import accelnav_docs
    finally:
        sys.path.remove(str(DOCS / "_ext"))
    return accelnav_docs


def test_docs_build_with_no_warnings(tmp_path):
    _require("sphinx", "myst_parser")
    cmd = [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-E", "-q", "-b", "html", str(DOCS), str(tmp_path)]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=BUILD_TIMEOUT_S)
    assert proc.returncode == 0, f"sphinx -W failed:\n{proc.stderr[-4000:]}"
    page = (tmp_path / "model-file.html").read_text()
    assert "sensor.duty_cycle.t2_period_s" in page  # the generated key table is on the page
    assert (tmp_path / "commands" / "smooth.html").is_file()
    # options as typed: no dash made typographic before an option's name, on any page
    dashed = {
        f"{html.relative_to(tmp_path)}: {m}"
        for html in tmp_path.rglob("*.html")
        for m in re.findall(r"(?<![\w\u2013\u2014-])[\u2013\u2014]{1,2}[a-z][\w-]*", html.read_text())
    }
    assert not dashed, sorted(dashed)
    assert "Without --fixes and --zupt" in (tmp_path / "commands" / "smooth.html").read_text()


def _flat_keys(data: dict, prefix: str = "") -> set[str]:
    keys = set()
    for k, v in data.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            keys |= {key} | _flat_keys(v, key + ".")
        elif isinstance(v, list) and v and all(isinstance(i, dict) for i in v):
            keys.add(key)
            for item in v:
                keys |= _flat_keys(item, key + "[].")
        else:
            keys.add(key)
    return keys


def test_every_key_of_every_shipped_model_is_in_the_reference(docs_ext):
    documented = {k.key for k in docs_ext.model_keys()}
    for path in sorted(MODELS.glob("*.toml")):
        missing = _flat_keys(tomllib.loads(path.read_text())) - documented
        assert not missing, f"{path.name}: keys not in the model-file reference: {sorted(missing)}"
    assert set(docs_ext.KEY_MEANINGS) == documented  # and every documented key has its meaning


def _toml(data: dict) -> str:
    """Just enough TOML for a model file: tables, one array of tables, scalars and number arrays."""

    def value(v):
        if isinstance(v, str):
            return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
        if isinstance(v, list):
            return "[" + ", ".join(value(i) for i in v) + "]"
        return repr(float(v)) if isinstance(v, float) else str(v)

    def table(name, d):
        lines = [f"[{name}]"] if name else []
        lines += [f"{k} = {value(v)}" for k, v in d.items() if not isinstance(v, (dict, list)) or k == "initial_sigma"]
        for k, v in d.items():
            if isinstance(v, dict):
                lines += table(f"{name}.{k}" if name else k, v)
            elif isinstance(v, list) and v and isinstance(v[0], dict):
                for item in v:
                    lines += [f"[[{k}]]"] + [f"{ik} = {value(iv)}" for ik, iv in item.items()]
        return lines

    return "\n".join(table("", data)) + "\n"


def _set(data: dict, key: str, v) -> None:
    *path, last = key.replace("[]", "").split(".")
    node = data
    for part in path:
        node = node[part][0] if isinstance(node[part], list) else node[part]
    node[last] = v


def _beyond(info) -> list[float]:
    """Values just outside the bounds the reference states for a number key."""
    out = []
    if info.hi is not None:
        out.append(info.hi * 2 + 1)
    if info.lo is not None:
        out.append(info.lo if info.lo_open else info.lo - max(1.0, abs(info.lo)))
    return out


def test_the_bounds_and_choices_in_the_reference_are_what_the_loader_refuses(docs_ext):
    """Set each key of each shipped model just beyond what the generated reference says it accepts: the
    loader must refuse it, naming that very key. A reference that states a bound the loader does not
    apply, or records a key under the wrong table, fails here."""
    checked = 0
    for path in sorted(MODELS.glob("*.toml")):
        base = tomllib.loads(path.read_text())
        loads_model(_toml(base), source=path.name)  # the writer above round-trips the shipped model
        for info in docs_ext.model_keys():
            bad = _beyond(info) if info.kind in ("number", "integer") else []
            if info.choices:
                bad = ["no-such-choice"]
            for v in bad:
                data = tomllib.loads(path.read_text())
                try:
                    _set(data, info.key, int(v) if info.kind == "integer" and math.isfinite(v) else v)
                except KeyError:
                    continue  # a table this model does not have (another sensor kind's)
                with pytest.raises(ModelError) as err:
                    loads_model(_toml(data), source=path.name)
                assert err.value.key.replace("[0]", "[]") == info.key, f"{path.name}: {info.key} = {v!r}: {err.value}"
                checked += 1
    assert checked > 30
