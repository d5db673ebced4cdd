from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
FAILURES = Path(__file__).parent / "_failures"


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


# the default experiment shrunk for tests, as ``--set`` overrides
SMALL_OVERRIDES = [
    "resolution=[32, 32]",
    "fit.resolution=[32, 32]",
    "reference.spp=16",
    "reference.water_mesh=96",
    "reference.texture_size=64",
    "reference.texture_spp=8",
    "reference.lighting_size=32",
    "reference.wall_spp=8",
    "waves.normal_map_size=64",
]


def small_experiment(**overrides):
    """The default experiment, shrunk for tests: 32x32, few spp, coarse meshes and textures."""
    from study import load_experiment

    base = dict(o.split("=", 1) for o in SMALL_OVERRIDES)
    base.update({k: str(v) for k, v in overrides.items()})
    return load_experiment(
        REPO / "experiments" / "default.toml", [f"{k}={v}" for k, v in base.items()]
    )


def save_failure(name: str, **images) -> Path:
    """Write actual / expected / error images of a failed comparison to tests/_failures/."""
    from study import write_exr

    FAILURES.mkdir(exist_ok=True)
    for key, img in images.items():
        write_exr(FAILURES / f"{name}.{key}.exr", img)
    return FAILURES


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    """The random order's seed, also under ``-q``: a failure's order can be replayed."""
    seed = getattr(config.option, "randomly_seed", None)
    if seed is not None and config.pluginmanager.has_plugin("randomly"):
        terminalreporter.write_line(
            f"test order: pytest-randomly seed {seed} "
            f"(replay with -p randomly --randomly-seed={seed})"
        )
