"""Animated experiments (``study.scene.animation``): the two sides' waves move together, the frames
share what does not move and are cached apart, and the temporal error measures what it says."""

from __future__ import annotations

import json

import numpy as np
import pytest

from helpers.experiments import small_experiment
from helpers.experiments import TINY as CLI_TINY
from helpers.port_checks import port_normals
from study.scene.shader_waves import angles_deg

# 0.2 s a frame: the layers move 0.06 texture units (0.12 world units) from frame to frame
ANIMATED = {"animation.frames": 3, "animation.time_step": 0.2}


@pytest.fixture(scope="module")
def animated(mi):
    """A small animated experiment, its frames and their shader inputs built through one
    ``FrameShared`` (as ``study calibrate`` builds them), plus what it built once."""
    from study.scene.animation import FrameShared, frames_of
    from study.scene.shader_inputs import build_shader_inputs

    exp = small_experiment(**ANIMATED)
    frames = frames_of(exp)
    shared = FrameShared()
    inputs = [build_shader_inputs(e, shared=shared) for e in frames]
    return {"exp": exp, "frames": frames, "inputs": inputs, "shared": shared}


def _reference_normals(mi, scene, xz: np.ndarray) -> np.ndarray:
    """(N, 3) shading normals of the scene's water surface under world points ``xz`` (N, 2),
    found by rays cast straight down from above the waves."""
    n = len(xz)
    o = mi.Point3f(
        mi.Float(xz[:, 0].astype(np.float32)),
        mi.Float(np.full(n, 0.5, np.float32)),
        mi.Float(xz[:, 1].astype(np.float32)),
    )
    si = scene.ray_intersect(mi.Ray3f(o, mi.Vector3f(0.0, -1.0, 0.0)))
    assert np.array(si.is_valid()).all()
    return np.array(si.sh_frame.n).T.reshape(n, 3)


def test_port_normal_map_at_frame_k_matches_the_reference_surface_at_frame_k(mi, animated):
    """The port's normal at frame k (its normal map looked up at frame k's wave1..wave4) against
    the normal of the reference's displaced water mesh at frame k under the same point: the
    matching frame agrees within the normal-averaging and filtering approximations, every other
    frame (the surface not moved, or moved by another frame's offsets) is far off."""
    from study.scene.mitsuba_scene import build_scene, set_waves

    frames = animated["frames"]
    scene = build_scene(frames[0], 8, 8)  # frame 0's scene, moved below (as calibrate does)
    port = [port_normals(i.with_resolution(96, 96)) for i in animated["inputs"]]
    angle = np.zeros((len(frames), len(frames)))
    for j, e in enumerate(frames):  # the reference surface at frame j
        set_waves(scene, e)
        for k, (xz, n) in enumerate(port):  # the port at frame k
            angle[k, j] = angles_deg(n, _reference_normals(mi, scene, xz)).mean()
    matched = np.diag(angle)
    mismatched = angle[~np.eye(len(frames), dtype=bool)]
    # measured: 0.24-0.34 degrees matched, 5.7-9.2 degrees between frames
    assert matched.max() < 0.1 * mismatched.min(), angle
    assert matched.max() < 0.6, angle


def test_moved_scene_renders_as_one_built_for_the_frame(mi):
    """``set_waves`` on frame 0's scene renders frame 2 bit for bit as a scene built for it."""
    from study.scene.animation import frame_experiment
    from study.scene.mitsuba_scene import build_scene, set_waves

    exp = small_experiment(**ANIMATED)
    f0, f2 = frame_experiment(exp, 0), frame_experiment(exp, 2)
    moved = build_scene(f0, 16, 16)
    set_waves(moved, f2)
    a = np.array(mi.render(moved, spp=4, seed=3))
    b = np.array(mi.render(build_scene(f2, 16, 16), spp=4, seed=3))
    c = np.array(mi.render(build_scene(f0, 16, 16), spp=4, seed=3))
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)  # the waves did move


def test_still_only_commands_refuse_an_animated_experiment(tmp_path, capsys):
    """failures, stability and a fit over several experiments say that they take still
    frames and how to run them (exit code 2, nothing written); so does calibrate for the texture
    noise decorrelation, which it does not do over frames."""
    from helpers import REPO
    from study.cli import main

    exp = str(REPO / "experiments" / "animated.toml")
    for args in (
        ["failures", exp],
        ["stability", exp],
        ["calibrate", exp, str(REPO / "experiments" / "default.toml")],
    ):
        assert main(args + ["--out", str(tmp_path / "x")]) == 2
        err = capsys.readouterr().err
        assert "animation.frames = 8" in err and "--set animation.frames=1" in err, err
    assert not (tmp_path / "x").exists()
    decorrelate = ["--set", 'fit.input_noise="decorrelate"']
    assert main(["calibrate", exp, "--out", str(tmp_path / "y")] + decorrelate) == 2
    err = capsys.readouterr().err
    assert "not built for an animated experiment" in err and "--set animation.frames=1" in err


def test_frames_are_still_experiments_with_their_own_keys():
    """Frame k's offsets follow wave_i(k) = offsets_i + k dt v_i; frame 0 is the experiment as a
    still (same reference and inputs keys); each frame has its own keys; the offsets-free key is
    shared by the frames only."""
    from study.scene.animation import frame_experiment, frame_offsets, offsets_free_key

    exp = small_experiment(**ANIMATED)
    still = small_experiment()
    f = [frame_experiment(exp, k) for k in range(3)]
    v = np.asarray(exp["animation.velocities"])
    for k in range(3):
        want = np.asarray(exp["waves.offsets"]) + k * 0.2 * v
        np.testing.assert_allclose(frame_offsets(exp, k), want, rtol=0, atol=1e-15)
        assert f[k]["animation.frames"] == 1
    assert f[0].scene_hash() == still.scene_hash() and f[0].inputs_hash() == still.inputs_hash()
    assert len({e.scene_hash() for e in f}) == 3 and len({e.inputs_hash() for e in f}) == 3
    assert len({offsets_free_key(e) for e in f}) == 1
    other = small_experiment(**ANIMATED, **{"water.ior": 1.4})
    assert offsets_free_key(other) != offsets_free_key(f[0])
    with pytest.raises(ValueError, match="animation.frames"):
        frame_offsets(exp, 3)


def test_shared_parts_are_built_once_and_give_the_fresh_inputs(mi, animated):
    """The frames build world y (of the texture and of the lighting grid), the dry render, the
    lighting scene, the skylight's two sample patterns and the maps once; frame 1's inputs built
    through them equal frame 1's inputs built alone, array for array, and the frames' refraction
    textures differ (the light through the moving waves moves)."""
    from study.scene.shader_inputs import build_shader_inputs

    shared = animated["shared"]
    assert sorted(shared.built) == [
        "dry_render",
        "lighting_scene",
        "maps",
        "pool_world_y",
        "sky_samples0",
        "sky_samples1",
        "world_y",
    ]
    assert all(shared.reused[n] == 2 for n in shared.built)
    fresh = build_shader_inputs(animated["frames"][1])
    got = animated["inputs"][1]
    for name, value in vars(fresh).items():
        if isinstance(value, np.ndarray):
            assert np.array_equal(value, getattr(got, name)), name
    want = np.asarray(animated["frames"][1]["waves.offsets"], np.float32)  # the uniforms' float
    np.testing.assert_array_equal(got.waves, want)
    t = [i.refraction_texture for i in animated["inputs"]]
    assert not np.array_equal(t[0], t[1]) and not np.array_equal(t[1], t[2])


def test_temporal_error_of_known_motions():
    """A shader that changes exactly as the reference has no temporal error; a still one has the
    reference's whole change as its error and a change ratio of 0; one that moves twice as much
    has the reference's change as error and a ratio of 2. Fewer than two frames are refused."""
    from study._metrics import temporal_errors

    rng = np.random.default_rng(0)
    refs = [rng.random((6, 5, 3)) for _ in range(4)]
    mask = np.ones((6, 5), bool)
    mask[0] = False
    same = temporal_errors(refs, [r + 0.1 for r in refs], mask)
    assert same["trmse"] == pytest.approx(0.0, abs=1e-12)
    assert same["change_ratio"] == pytest.approx(1.0)
    still = temporal_errors(refs, [refs[0]] * 4, mask)
    assert still["trmse"] == pytest.approx(still["reference_change"])
    assert still["change_ratio"] == 0.0
    double = temporal_errors(refs, [2 * r for r in refs], mask)
    assert double["trmse"] == pytest.approx(double["reference_change"])
    assert double["change_ratio"] == pytest.approx(2.0)
    assert np.all(double["maps"]["flicker"][0] == 0.0)  # outside the mask
    # passes whose noise is the same in every frame (shared seeds) leave dR without noise;
    # independent noise of s.d. 0.1 per pass leaves sqrt(2) 0.1 / sqrt(8) in dR
    noise = rng.normal(0.0, 0.1, (8, 6, 5, 3))
    shared = [r + noise for r in refs]
    own = [r + rng.normal(0.0, 0.1, (8, 6, 5, 3)) for r in refs]
    t = temporal_errors([p.mean(0) for p in shared], refs, mask, passes=shared)
    assert t["noise"] == pytest.approx(0.0, abs=1e-12) and t["noise_pairs"] == 3
    t = temporal_errors([p.mean(0) for p in own], refs, mask, passes=own[:3] + [None])
    assert t["noise"] == pytest.approx(np.sqrt(2) * 0.1 / np.sqrt(8), rel=0.15)
    assert t["noise_pairs"] == 2
    assert t["trmse_excess"] < t["trmse"]
    assert t["reference_change_excess"] < t["reference_change"]
    assert t["change_ratio_excess"] > t["change_ratio"]
    with pytest.raises(ValueError, match="animation.frames"):
        temporal_errors(refs[:1], refs[:1], mask)
    bad = [r.copy() for r in refs]
    bad[2][3, 3, 0] = np.nan
    with pytest.raises(ValueError, match="not finite"):
        temporal_errors(refs, bad, mask)


TINY_ANIMATED = CLI_TINY + [
    "reference.lighting_size=16",
    "reference.wall_spp=4",
    "fit.max_steps=4",
    "animation.frames=2",
    "animation.time_step=0.2",
]


@pytest.mark.slow
def test_calibrate_on_an_animated_experiment_end_to_end(tmp_path, capsys):
    """``study calibrate`` on 2 frames: the per-frame and temporal record, the animation, the
    exported shaders with the frames' wave uniforms (GL-checked per frame); a second run finds
    every frame's reference (with its passes) and inputs in the cache."""
    from PIL import Image

    from helpers import REPO
    from study.cli import main
    from study.scene.animation import frame_offsets

    exp = str(REPO / "experiments" / "default.toml")
    sets = [a for kv in TINY_ANIMATED for a in ("--set", kv)]
    assert main(["calibrate", exp, "--out", str(tmp_path / "a")] + sets) == 0
    out = tmp_path / "a"
    summary = json.loads((out / "constants.json").read_text())
    a = summary["animation"]
    for name in ("start", "single_frame", "all_frames"):
        s = a["scores"][name]
        assert len(s["flip"]) == 2 and all(np.isfinite(s["flip"]))
        assert s["flip_mean"] == pytest.approx(np.mean(s["flip"]))
        t = s["temporal"]
        assert t["noise_pairs"] == 1 and np.isfinite([t["trmse"], t["noise"]]).all()
    fitted, start = a["scores"]["all_frames"]["rmse_mean"], a["scores"]["start"]["rmse_mean"]
    assert fitted < start
    with Image.open(out / "animation.webp") as im:
        assert im.n_frames == 2 and im.size == (72, 40)
    offsets = json.loads((out / "shaders" / "animation.json").read_text())
    from study.config.experiment import load_experiment

    e = load_experiment(exp, TINY_ANIMATED)
    for k in range(2):
        np.testing.assert_array_equal(offsets["frames"][k], frame_offsets(e, k))
    assert "uniform vec2 wave1;" in (out / "shaders" / "core" / "water.vert").read_text()
    assert summary["gl_check"]["passed"] and len(summary["gl_check"]["frames"]) == 2
    report = (out / "report.md").read_text()
    assert "## FLIP per frame" in report and "animation.webp" in report
    capsys.readouterr()
    assert main(["calibrate", exp, "--out", str(tmp_path / "b")] + sets) == 0
    err = capsys.readouterr().err
    assert err.count("reference: cached") == 2 and err.count("shader inputs: cached") == 2
    again = json.loads((tmp_path / "b" / "constants.json").read_text())
    assert again["constants"] == summary["constants"]
    assert again["animation"]["scores"]["all_frames"]["temporal"]["noise_pairs"] == 1


@pytest.mark.slow
def test_tradeoff_on_an_animated_experiment_scores_motion(tmp_path):
    """``study tradeoff`` on 2 frames: the search and fits on frame 0, then every full point
    scored on both frames; frame 0 of the motion scores is the still point itself (same
    constants, same reference, same FLIP); the report has the motion section and its chart."""
    from helpers import REPO
    from study.cli import main
    from study.sweep import read_table

    exp = str(REPO / "experiments" / "default.toml")
    plan = [
        'tradeoff.variants=["water_refraction"]',
        "tradeoff.steps_grazing=[10.0]",
        "tradeoff.steps_steep=[3.0]",
        "tradeoff.loop_cap=[40]",
        "tradeoff.scales=[0.5,1.0]",
        "tradeoff.converged_scale=4.0",
        "tradeoff.gl_repeats=3",
    ]
    sets = [a for kv in TINY_ANIMATED + plan for a in ("--set", kv)]
    out = tmp_path / "t"
    args = ["tradeoff", exp, "--out", str(out), "--workers", "1", "--search", "exhaustive"]
    assert main(args + sets) == 0
    full = {r["key"]: r for r in read_table(out / "tradeoff.parquet")}
    motion = read_table(out / "motion.parquet")
    assert len(motion) == len(full) == 3 and all(m["status"] == "ok" for m in motion)
    still = {(r["job.kind"], r["flip"]) for r in full.values()}
    for m in motion:
        assert len(m["flip_frames"]) == 2 and len(m["pair_ms"]) == 1
        assert (m["job.kind"], m["flip_frames"][0]) in still  # frame 0 is the still point
        assert m["trmse"] == pytest.approx(m["pair_ms"][0] ** 0.5)
        # the raymarch converged with the point's own constants, beside each schedule
        assert (m["job.kind"] == "converged") == (m.get("converged_trmse") is None)
    summary = json.loads((out / "summary.json").read_text())
    mo = summary["scenes"]["default"]["motion"]
    assert mo["frames"] == 2 and mo["still"] == summary["scenes"]["default"]["recommended"]["label"]
    assert {b["label"] for b in mo["banding"]} == {
        "water_refraction (5, 1.5, 20)",
        "water_refraction (10, 3, 40)",
    }
    report = (out / "report.md").read_text()
    assert "### In motion (2 frames)" in report and "motion.png" in report
    assert (out / "motion.png").stat().st_size > 10_000
