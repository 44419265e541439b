"""A fleet's workers share the CPUs (accelnav.resources.threads divided among the jobs)."""

from __future__ import annotations

import logging
import os

import pytest

from accelnav import resources
from accelnav.data import smoothing
from accelnav.errors import UserError


def test_a_fleet_refuses_a_bad_thread_count_before_starting_its_workers(tmp_path, monkeypatch):
    monkeypatch.setenv(resources.THREADS_ENV, "none")
    with pytest.raises(UserError, match=resources.THREADS_ENV):
        smoothing.smooth_files([tmp_path / "a.npz", tmp_path / "b.npz"], tmp_path / "out", jobs=2)


def test_a_worker_takes_its_share_of_the_threads(monkeypatch):
    from accelnav import progress

    monkeypatch.setenv(resources.THREADS_ENV, "8")
    monkeypatch.setattr(progress, "VERBOSITY", progress.VERBOSITY)  # the worker's quiet, undone after
    log = logging.getLogger("accelnav")
    level = log.level
    try:
        smoothing._fleet_worker(3)
    finally:
        log.setLevel(level)
    assert os.environ[resources.THREADS_ENV] == "3"
