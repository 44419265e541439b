"""A private cache for one test: the cache folder and the cache key both in the test's temporary folder
(never the user's ~/.cache or ~/.config), and the key read afresh."""

from __future__ import annotations

from pathlib import Path

from accelnav import cachefile


def private_cache(tmp_path: Path, monkeypatch) -> Path:
    """Point ACCELNAV_CACHE_DIR and ACCELNAV_CACHE_KEY_FILE into ``tmp_path``; returns the cache folder."""
    cache = tmp_path / "cache"
    monkeypatch.setenv("ACCELNAV_CACHE_DIR", str(cache))
    monkeypatch.setenv(cachefile.KEY_ENV, str(tmp_path / "config" / "cache.key"))
    monkeypatch.setattr(cachefile, "_secret", None)  # read afresh now; the key before restored afterwards
    monkeypatch.setattr(cachefile, "_ephemeral", False)
    return cache


def seal_with_other_key(path: Path, payload: bytes, tmp_path: Path, monkeypatch) -> None:
    """Write ``payload`` at ``path`` sealed as an attacker would: a well-formed entry under a key of theirs."""
    with monkeypatch.context() as m:
        m.setenv(cachefile.KEY_ENV, str(tmp_path / "attacker.key"))
        cachefile.forget_secret()
        assert cachefile.write_sealed(path, payload)
    cachefile.forget_secret()
