"""Fixtures and hooks only; what tests share otherwise is in ``helpers/``."""

import pytest


@pytest.fixture(scope="session")
def mi():
    """Mitsuba with the default LLVM variant (after the libLLVM check)."""
    from study import init_backend

    init_backend("llvm_ad_rgb")
    import mitsuba

    return mitsuba


@pytest.fixture(scope="session", autouse=True)
def _session_cache(tmp_path_factory):
    """Nothing in a test session reads or writes the project's ``.cache``: the session's own
    cache is set before any fixture runs (module fixtures run before function ones)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("STUDY_CACHE", str(tmp_path_factory.mktemp("session_cache")))
        yield


@pytest.fixture(scope="module", autouse=True)
def _module_cache(tmp_path_factory, _session_cache):
    """Module-scoped fixtures (a shared reference, a CLI run) see their module's own cache."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("STUDY_CACHE", str(tmp_path_factory.mktemp("module_cache")))
        yield


@pytest.fixture(autouse=True)
def _private_cache(tmp_path_factory, monkeypatch, _module_cache):
    """Every test uses a fresh reference cache, never the user's."""
    monkeypatch.setenv("STUDY_CACHE", str(tmp_path_factory.mktemp("cache")))


# pytest-xdist: the files each worker ran, in order (on the controller; empty without xdist)
_WORKER_FILES: dict[str, list[str]] = {}


def pytest_runtest_logreport(report):
    node = getattr(report, "node", None)  # set by pytest-xdist on the controller's reports
    if node is not None and report.when == "setup":
        files = _WORKER_FILES.setdefault(node.gateway.id, [])
        path = report.nodeid.split("::", 1)[0]
        if path not in files:
            files.append(path)


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    """The random order's seed, also under ``-q``: a failure's order can be replayed. The order
    is a sort by a hash of the seed and each name, so a subset of the files keeps its relative
    order: under pytest-xdist (``--dist loadfile``: whole files per worker), a failed run also
    prints each worker's files, and the replay of one worker's share runs them as it did."""
    seed = getattr(config.option, "randomly_seed", None)
    if seed is not None and config.pluginmanager.has_plugin("randomly"):
        terminalreporter.write_line(
            f"test order: pytest-randomly seed {seed} "
            f"(replay with -p randomly --randomly-seed={seed})"
        )
        if exitstatus != 0:
            for worker, files in sorted(_WORKER_FILES.items()):
                terminalreporter.write_line(
                    f"{worker} ran, in order (replay in one process: python -m pytest "
                    f"-p randomly --randomly-seed={seed} FILES): {' '.join(files)}"
                )
