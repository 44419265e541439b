"""accelnav.cachefile: the cache key (where it lives, who may change it), sealed entries (what a reader
refuses), the one line a bad entry gets, and two processes building one entry (issue 30)."""

from __future__ import annotations

import multiprocessing
import os
import stat

import numpy as np
import pytest
from support.cachekey import private_cache, seal_with_other_key
from support.said import listen, warned

from accelnav import cachefile
from accelnav.errors import AccelnavWarning, UserError


@pytest.fixture
def cache(tmp_path, monkeypatch):
    return private_cache(tmp_path, monkeypatch)


def test_the_key_is_made_once_private_and_outside_the_cache(cache, tmp_path):
    first = cachefile.secret()
    path = cachefile.key_path()
    assert path == tmp_path / "config" / "cache.key"
    assert stat.S_IMODE(path.stat().st_mode) == 0o600 and len(first) == 32
    cachefile.forget_secret()
    assert cachefile.secret() == first  # read back, not made again
    assert not any(cache.rglob("*key*")) and not list(path.parent.glob(".cache.key.*"))


def test_the_xdg_config_folder_holds_the_key_by_default(cache, tmp_path, monkeypatch):
    monkeypatch.delenv(cachefile.KEY_ENV)
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xdg"))
    assert cachefile.key_path() == tmp_path / "xdg" / "accelnav" / "cache.key"


def test_no_key_to_be_had_keeps_nothing_and_says_so_once(cache, tmp_path, monkeypatch):
    """A home that cannot take the key (here a file where its folder should be): each entry is built, used,
    and not kept, since no later run could verify it."""
    (tmp_path / "config").write_text("not a folder")
    path = cache / "entry"
    with pytest.warns(AccelnavWarning) as said:  # a warning to act on: the key's home needs mending
        assert bytes(cachefile.cached(path, lambda: b"built", limit=100)) == b"built"
        assert bytes(cachefile.cached(path, lambda: b"built", limit=100)) == b"built"
    assert len(said) == 1 and "nothing is read from or kept in the cache this run" in str(said[0].message)
    assert not path.exists()


def test_a_key_inside_the_cache_folder_is_refused(cache, monkeypatch):
    monkeypatch.setenv(cachefile.KEY_ENV, str(cache / "cache.key"))
    with pytest.raises(UserError, match="lies inside the cache folder"):
        cachefile.secret()


@pytest.mark.parametrize("bad", ["group-writable", "not hex", "short", "symlink"])
def test_a_key_file_others_can_change_or_not_a_key_is_refused_in_one_line(cache, bad, tmp_path):
    path = cachefile.key_path()
    path.parent.mkdir(parents=True)
    good = os.urandom(32).hex() + "\n"
    if bad == "symlink":
        (tmp_path / "elsewhere").write_text(good)
        path.symlink_to(tmp_path / "elsewhere")
    else:
        path.write_text({"not hex": "x" * 64, "short": good[:20]}.get(bad, good))
        path.chmod(0o620 if bad == "group-writable" else 0o600)
    with pytest.raises((UserError, OSError)) as err:
        cachefile._read_key(path)
    assert "\n" not in str(err.value)


def test_a_sealed_entry_round_trips_and_refuses_each_forgery(cache, tmp_path, monkeypatch):
    path = cache / "e" / "entry-abc"
    assert cachefile.write_sealed(path, b"payload ", b"in parts")
    assert bytes(cachefile.read_sealed(path, 100)) == b"payload in parts"
    blob = path.read_bytes()

    path.write_bytes(blob[:-1] + b"X")  # an edit in place
    with pytest.raises(ValueError, match="does not verify"):
        cachefile.read_sealed(path, 100)
    seal_with_other_key(path, b"payload in parts", tmp_path, monkeypatch)  # re-sealed by someone else
    with pytest.raises(ValueError, match="does not verify"):
        cachefile.read_sealed(path, 100)
    other = cache / "e" / "entry-def"  # our own seal, moved under another entry's name
    other.write_bytes(blob)
    with pytest.raises(ValueError, match="does not verify"):
        cachefile.read_sealed(other, 100)
    path.write_bytes(blob[:20])
    with pytest.raises(ValueError, match="not a sealed entry"):
        cachefile.read_sealed(path, 100)
    path.write_bytes(blob)
    with pytest.raises(ValueError, match="more than an entry"):
        cachefile.read_sealed(path, 10)


def test_links_and_fifos_at_an_entry_are_neither_followed_nor_waited_on(cache, tmp_path):
    cache.mkdir()
    target = tmp_path / "target"
    target.write_bytes(b"keep me")
    link, fifo = cache / "link-entry", cache / "fifo-entry"
    link.symlink_to(target)
    os.mkfifo(fifo)
    for path, reason in ((link, "symbolic link"), (fifo, "not a regular file")):
        with pytest.raises(ValueError, match=reason):
            cachefile.read_sealed(path, 100)
        assert bytes(cachefile.cached(path, lambda: b"built", limit=100)) == b"built"
        assert path.is_file() and not path.is_symlink()  # replaced by a rename, not written through
    assert target.read_bytes() == b"keep me"


def test_a_bad_entry_is_rebuilt_with_one_line_a_missing_one_silently(cache, caplog):
    listen(caplog)
    path = cache / "one"
    assert bytes(cachefile.cached(path, lambda: b"first", limit=100)) == b"first"
    assert caplog.records == []
    assert bytes(cachefile.cached(path, lambda: pytest.fail("rebuilt a good entry"), limit=100)) == b"first"
    path.write_bytes(path.read_bytes()[:-2])
    assert bytes(cachefile.cached(path, lambda: b"second", limit=100)) == b"second"
    (line,) = warned(caplog)
    assert line.startswith(f"cache entry {path}: ") and "rebuilt" in line
    assert bytes(cachefile.read_sealed(path, 100)) == b"second"


def test_a_check_refuses_a_verified_payload_that_does_not_fit(cache, caplog):
    path = cache / "two"
    cachefile.write_sealed(path, b"old shape")

    def check(data):
        if bytes(data) != b"new shape":
            raise ValueError("not the shape")

    assert bytes(cachefile.cached(path, lambda: b"new shape", limit=100, check=check)) == b"new shape"
    (line,) = warned(caplog)
    assert "not the shape; rebuilt" in line


def test_a_folder_that_cannot_be_written_costs_only_time(cache, caplog):
    cache.mkdir()
    (cache / "sub").write_text("a file where a folder should be")
    assert bytes(cachefile.cached(cache / "sub" / "x", lambda: b"built", limit=100)) == b"built"
    assert any("not kept" in line for line in warned(caplog)), warned(caplog)


# -- two processes building one entry ---------------------------------------------------------------

ROUNDS = 100
N = 400


def _design():
    from accelnav.model.design import axis_design
    from accelnav.model.load import load_model

    return axis_design(load_model(), 0)


def _mask():
    valid = np.ones(N, dtype=bool)
    valid[::7] = False  # not all valid: the per-sample gains, the entry ACCELNAV_GAIN_CACHE keeps
    return valid


def _builder(folder: str, log: str, out: str, go) -> None:
    """One process of a round: the gains of one (design, N, mask) through the cache folder."""
    from accelnav.estimate import fastsmooth as fs

    real = fs._compute_gains

    def counted(*a, **k):
        with open(log, "a") as fh:
            fh.write(f"{os.getpid()}\n")
        return real(*a, **k)

    fs._compute_gains = counted
    go.wait()
    g = fs.plain_gains(_design(), N, _mask(), cache_dir=folder)
    np.savez(out, **{k: getattr(g, k) for k in ("K", "Cs", "P_prior", "P_post", "Ps")})


def test_two_processes_building_one_gain_entry_100_rounds(cache, tmp_path):
    from accelnav.estimate import fastsmooth as fs

    fs.clear_gain_cache()
    ref = fs.plain_gains(_design(), N, _mask())  # no disk cache: computed here
    fs.clear_gain_cache()
    cachefile.secret()  # the key made before the fork: both processes seal with it
    ctx = multiprocessing.get_context("fork")
    builds = []
    for r in range(ROUNDS):
        folder, log = tmp_path / f"round{r}", tmp_path / f"log{r}"
        go = ctx.Event()
        procs = [
            ctx.Process(target=_builder, args=(str(folder), str(log), str(tmp_path / f"out{r}-{i}.npz"), go))
            for i in range(2)
        ]
        for p in procs:
            p.start()
        go.set()
        for p in procs:
            p.join(60)
            assert p.exitcode == 0, f"round {r}: a builder ended with {p.exitcode}"
        builds.append(len(log.read_text().split()))
        for i in range(2):
            with np.load(tmp_path / f"out{r}-{i}.npz") as got:
                for k in got.files:
                    assert np.array_equal(got[k], getattr(ref, k)), f"round {r} process {i}: {k}"
        entry = next(folder.glob("gains-*.npz"))
        assert fs._gains_from(cachefile.read_sealed(entry, 1 << 24), ref.key, N).K.shape == ref.K.shape
        assert not [p for p in folder.iterdir() if p.name.endswith(".tmp")]
    assert builds == [1] * ROUNDS, f"rounds with two builds: {[r for r, b in enumerate(builds) if b != 1]}"
