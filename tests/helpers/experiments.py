"""The shipped experiments shrunk for tests, as ``--set`` overrides."""

from __future__ import annotations

from helpers import REPO

DEFAULT = REPO / "experiments" / "default.toml"

# the default experiment shrunk: 32x32, few spp, coarse meshes and textures
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
    # a tradeoff's level-of-detail policy is tested where a test asks for it (tests/test_search.py)
    "tradeoff.lod=false",
    # the squared error alone (a third of the default's fit time); the default, FLIP from the
    # squared error's solution, is tested where a test asks for it (tests/test_flip_loss.py)
    'fit.loss="linear"',
]

# smaller still, for whole CLI runs (render / preview / calibrate / export): 24x24, 16 spp
TINY = [
    "resolution=[24,24]",
    "fit.resolution=[24,24]",
    'fit.loss="linear"',  # as SMALL_OVERRIDES
    "reference.spp=16",
    "reference.water_mesh=48",
    "reference.texture_size=32",
    "reference.texture_spp=4",
    "waves.normal_map_size=32",
]


def replaced(overrides: list[str], *changes: str) -> list[str]:
    """``overrides`` with ``changes`` (``KEY=VALUE``) replacing the values of their keys or
    added after them: ``replaced(TINY, "reference.spp=8")``."""
    d = dict(o.split("=", 1) for o in overrides)
    d.update(c.split("=", 1) for c in changes)
    return [f"{k}={v}" for k, v in d.items()]


def sets(overrides) -> list[str]:
    """``["--set", KEY=VALUE, ...]`` for the command line."""
    return [a for kv in overrides for a in ("--set", kv)]


def small_experiment(**overrides):
    """The default experiment, shrunk for tests: 32x32, few spp, coarse meshes and textures."""
    from study import load_experiment

    base = dict(o.split("=", 1) for o in SMALL_OVERRIDES)
    base.update({k: str(v) for k, v in overrides.items()})
    return load_experiment(DEFAULT, [f"{k}={v}" for k, v in base.items()])
