"""Valid but extreme experiments through ``study preview`` at tiny sizes: each completes, or
stops with one clear error naming a key, within a time bound (a subprocess with a timeout, so
a hang fails instead of stalling the suite); and the same experiment with the same constants
gives bit-identical outputs.

The range ends of every numeric key are run (``slow``), and random combinations of ends
(``slow``); a quick subset of the riskiest combinations runs by default. The upper ends of
the keys that only set cost (image, texture, mesh and normal-map sizes, sample counts) are
left out: they are slow by design, not wrong."""

from __future__ import annotations

import json
import random
import subprocess
import sys

import numpy as np
import pytest

from helpers import REPO
from study.config.experiment import SCHEMA

CASE_SECONDS = 120  # per case, tiny sizes, 2 shared cores (the first one compiles the kernels)
COST_KEYS = {
    "resolution",
    "fit.resolution",
    "reference.texture_size",
    "reference.water_mesh",
    "waves.normal_map_size",
    "reference.spp",
    "reference.texture_spp",
    "reference.max_spp",
    "fit.max_steps",
    "reference.max_depth",
    # the top-down lighting's sample counts and sizes (its upper ends take minutes, by design)
    "reference.lighting_size",
    "reference.bounce_spp",
    "reference.sun_photons",
    "reference.sky_directions",
    "reference.wall_spp",
}
SKIP = {"name", "description", "fit.parameters", "fit.solver", "fit.max_steps"}


def _toml(v) -> str:
    return json.dumps(v)


def _ends(key: str):
    """[(label, [KEY=VALUE, ...])] for the range ends and choices of one key."""
    f = SCHEMA[key]
    if key in SKIP or f.kind in ("path", "extent") or key.startswith("mesh."):
        return []
    if f.choices and f.kind == "str":
        return [(f"{key}={c}", [f"{key}={_toml(c)}"]) for c in f.choices if c != f.default]
    if f.kind == "vec2x4":
        return [(f"{key}=huge", [f"{key}=[[1e9, -1e9], [0, 0], [0.5, 0.5], [-1e9, 1e9]]"])]
    if f.lo is None:  # camera vectors: far away / close
        if key == "camera.position":
            return [
                ("camera.position=close", ["camera.position=[0.0, 0.001, 0.01]"]),
                ("camera.position=far", ["camera.position=[0.0, 1e4, 1e4]"]),
            ]
        if key == "camera.target":
            return [("camera.target=far", ["camera.target=[1e6, -1e6, 1e6]"])]
        return []
    out = []
    for end, v in (("lo", f.lo), ("hi", f.hi)):
        if end == "hi" and key in COST_KEYS:
            continue
        if f.kind == "int" or key in ("resolution", "fit.resolution"):
            v = int(v)
        val = [v] * {"vec2": 2, "vec3": 3, "vec4": 4}.get(f.kind, 1)
        text = _toml(val if f.kind.startswith("vec") else v)
        sets = [f"{key}={text}"]
        if key == "resolution":
            sets.append(f"fit.resolution={text}")
        if key == "reference.target_noise" or key == "reference.max_spp":
            sets += (
                ['reference.spp="auto"', "reference.max_spp=4"]
                if key != "reference.max_spp"
                else ['reference.spp="auto"']
            )
        out.append((f"{key}={end}", sets))
    return out


def range_end_cases():
    return [c for key in SCHEMA for c in _ends(key)]


def random_cases(n: int, seed: int = 0):
    rng = random.Random(seed)
    pool = range_end_cases()
    out = []
    for i in range(n):
        picks = rng.sample(pool, rng.randint(3, 6))
        out.append(
            (f"random{i}:" + "+".join(p[0] for p in picks), [s for p in picks for s in p[1]])
        )
    return out


QUICK = [
    ("waves.components=64+normal_tile=lo", ["waves.components=64", "waves.normal_tile=0.01"]),
    (
        "loop caps=hi+steps=lo",
        [
            "constants.loop_cap=10000",
            "constants.refl_loop_cap=10000",
            "constants.steps_grazing=0.5",
            "constants.steps_steep=0.5",
            'fit.shader="water_reflection"',
        ],
    ),
    (
        "bright sun+sky",
        [
            "sun.radius=20",
            "sun.radiance=[1e6, 1e6, 1e6]",
            "sky.zenith=[1e4, 1e4, 1e4]",
            "sun.elevation=0",
        ],
    ),
    ("dense water", ["water.ior=3", "water.sigma_t=[1000, 1000, 1000]", "water.albedo=[1, 1, 1]"]),
    ("floor at the surface", ["floor.depth=0.01"]),
    ("wide fov, tiny pool", ["camera.fov_y=170", "pool.half_extent=[0.1, 0.1]"]),
    ("largest reference seed", ["reference.seed=268435455"]),  # once beyond Mitsuba's 32-bit seeds
]


def run_cases(cases, tmp_path):
    (tmp_path / "cases.json").write_text(json.dumps(cases))
    cmd = [
        sys.executable,
        str(REPO / "tests" / "helpers" / "preview_driver.py"),
        str(tmp_path / "cases.json"),
        str(tmp_path / "out"),
    ]
    try:
        res = subprocess.run(
            cmd, capture_output=True, text=True, timeout=60 + CASE_SECONDS * len(cases), cwd=REPO
        )
        stdout = res.stdout
    except subprocess.TimeoutExpired as exc:
        stdout = exc.stdout.decode() if isinstance(exc.stdout, bytes) else (exc.stdout or "")
        started = [json.loads(l)["start"] for l in stdout.splitlines() if l.startswith('{"start"')]
        pytest.fail(f"timed out; the case running was {started[-1] if started else '?'}")
    recs = [json.loads(l) for l in stdout.splitlines() if l.startswith('{"case"')]
    assert len(recs) == len(cases), (res.returncode, res.stderr[-3000:])
    problems = []
    for r in recs:
        if r["status"] == "crash":
            problems.append(f"{r['case']}: crashed\n{r['message']}")
        elif r["status"] == "error":
            msg = r["message"]
            if "\n" in msg or len(msg) > 600 or not any(k in msg for k in SCHEMA):
                problems.append(f"{r['case']}: unclear error {msg[:400]!r}")
        if r["seconds"] > CASE_SECONDS:
            problems.append(f"{r['case']}: {r['seconds']:.0f} s > {CASE_SECONDS} s")
    assert not problems, "\n".join(problems)
    return recs


def test_quick_extremes_complete_or_stop_clearly(tmp_path):
    recs = run_cases(QUICK, tmp_path)
    status = {r["case"]: r["status"] for r in recs}
    assert status["waves.components=64+normal_tile=lo"] == "ok"  # once a hang
    assert status["floor at the surface"] == "error"  # the floor above the troughs


@pytest.mark.slow
def test_every_range_end_completes_or_stops_clearly(tmp_path):
    cases = range_end_cases()
    assert len(cases) > 80
    run_cases(cases, tmp_path)


@pytest.mark.slow
def test_random_combinations_of_ends_complete_or_stop_clearly(tmp_path):
    run_cases(random_cases(24), tmp_path)


def test_same_experiment_same_constants_bit_identical(tmp_path, monkeypatch):
    """Two previews from empty caches (reference, shader inputs and port all recomputed)."""
    from study._io import read_exr
    from study.commands import run_preview

    sets = [
        "resolution=[16,16]",
        "fit.resolution=[16,16]",
        "reference.spp=4",
        "reference.water_mesh=24",
        "reference.texture_size=16",
        "reference.texture_spp=2",
        "waves.normal_map_size=16",
        'fit.shader="water_reflection"',
    ]
    out = []
    for i in range(2):
        monkeypatch.setenv("STUDY_CACHE", str(tmp_path / f"cache{i}"))
        run_preview(REPO / "experiments" / "default.toml", tmp_path / f"out{i}", sets)
        out.append(tmp_path / f"out{i}")
    for name in ("reference.exr", "port.exr"):
        a, b = read_exr(out[0] / name)[0], read_exr(out[1] / name)[0]
        assert a.tobytes() == b.tobytes(), name
    ia = np.load(next((tmp_path / "cache0" / "inputs").glob("*.npz")))
    ib = np.load(next((tmp_path / "cache1" / "inputs").glob("*.npz")))
    for k in ia.files:
        assert np.asarray(ia[k]).tobytes() == np.asarray(ib[k]).tobytes(), k
