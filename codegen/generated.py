"""Every generated file of a model: :func:`generate`, the one function that writes what the firmware build
needs (the filter and the frame code; ``accelnav codegen``, ``accelnav.generate``, the firmware's make
files and the SIL/PIL runners all call it), and :func:`generated_files`, its output cached on disk: what
the firmware builds (SIL, PIL) and what the host's replay of the firmware's filter compiles are one and
the same output of the generator.

The generator takes seconds (the gain schedule's longer), so its output is kept in the cache
(:func:`accelnav.native.cbuild.cache_dir`) keyed by the model's text and the source of every module of
the generator: an edited generator never serves stale C. A model the generator refuses is refused
here each time (nothing is cached for it).

The cached text is compiled (SIL, the log replay), so it is a sealed entry (:mod:`accelnav.cachefile`):
verified under the user's key before any of it is used, and checked to hold the files the generator
writes; an entry edited, truncated or not sealed by this user is regenerated with one line on stderr.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from accelnav.cachefile import cached
from accelnav.model.load import Model
from accelnav.native.cbuild import cache_dir

from .emit_c import emit
from .frames import emit_frames


def generate(
    model: Model, *, form: str | None = None, arith: str = "fixed", prefix: str = "accelnav"
) -> dict[str, str]:
    """PREFIX.{h,c,json} (the filter) and, for the fixed-point filter the firmware runs, acnframe.{h,c,json}
    (the frame layout the firmware and the host's decoder share, derived from the filter's manifest)."""
    files = emit(model, form=form, arith=arith, prefix=prefix)
    if arith == "fixed":
        files.update(emit_frames(model, json.loads(files[f"{prefix}.json"])))
    return files


def _key(model: Model) -> str:
    key = hashlib.sha256(model.text.encode())
    here = Path(__file__).parent  # the generator's modules and the C runtime it copies (csrc/)
    for p in sorted([*here.glob("*.py"), *here.glob("csrc/*.h")]):
        key.update(p.read_bytes())
    return key.hexdigest()[:20]


MAX_GENERATED_BYTES = 64 << 20  # the gain schedule of a long fast run is a few MB of C


def _files(data) -> dict[str, str]:
    """The cached JSON as the generator's files (ValueError if it is not: a foreign or damaged entry)."""
    try:
        files = json.loads(bytes(data))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"not the generator's JSON ({exc})") from None
    if not isinstance(files, dict) or not all(isinstance(k, str) and isinstance(v, str) for k, v in files.items()):
        raise ValueError("not a map of file names to text")
    missing = {f"accelnav.{e}" for e in "hc"} - files.keys()
    if missing:
        raise ValueError(f"no {', '.join(sorted(missing))}")
    return files


def generated_files(model: Model) -> dict[str, str]:
    """accelnav.{h,c,json} (the filter) and acnframe.{h,c,json} (the frames) of ``model``."""
    path = cache_dir() / f"gen-{_key(model)}.json"
    data = cached(path, lambda: json.dumps(generate(model)).encode(), limit=MAX_GENERATED_BYTES, check=_files)
    return _files(data)
