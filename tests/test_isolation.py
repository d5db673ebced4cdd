"""Each test sees only its own cache: neither a module-scoped fixture nor a test reads or writes
the project's ``.cache`` (a module fixture set up before the per-test cache once did)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from helpers import REPO

_SEEN: dict = {}


@pytest.fixture(scope="module")
def module_cache_dir():
    from study.scene.cache import cache_dir

    return cache_dir()


def test_module_fixtures_see_a_temporary_cache(module_cache_dir):
    assert REPO not in module_cache_dir.parents and module_cache_dir != REPO / ".cache"
    assert Path(os.environ["STUDY_CACHE"]) != module_cache_dir  # the test's own is another


@pytest.mark.parametrize("k", [0, 1])
def test_each_test_has_its_own_cache(k):
    """Run in either order (pytest-randomly), the second sees another folder than the first."""
    from study.scene.cache import cache_dir

    d = cache_dir()
    assert REPO not in d.parents
    assert all(other != d for other in _SEEN.values())
    _SEEN[k] = d
