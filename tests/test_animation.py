"""Animated experiments (``study.scene.frames``): the two sides' waves move together, the frames
share what does not move and are cached apart, and the temporal error measures what it says."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import small_experiment

# 0.2 s a frame: the layers move 0.06 texture units (0.12 world units) from frame to frame
ANIMATED = {"animation.frames": 3, "animation.time_step": 0.2}


@pytest.fixture(scope="module")
def animated(mi):
    """A small animated experiment, its frames and their shader inputs built through one
    ``FrameShared`` (as ``study calibrate`` builds them), plus what it built once."""
    from study.scene.frames import FrameShared, frames_of
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


def _port_normals(inputs) -> tuple[np.ndarray, np.ndarray]:
    """The port's bumped normal (``normal_map_block``, the shader's four layers at the inputs'
    ``wave1..wave4``, ``BumptexMult = 1``) on its water pixels: ((N, 2) world x, z, (N, 3))."""
    from shaders_port._raster import prepare
    from shaders_port._texture import backend_types
    from shaders_port.water_refraction import normal_map_block

    m = backend_types("llvm")
    P = prepare(inputs, m)
    _, n = normal_map_block(m, P, 1.0)
    xz = P.raster.world[:, [0, 2]].astype(np.float64)
    return xz, np.array(n.numpy()).T.reshape(-1, 3)


def _mean_angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    c = np.clip((a * b).sum(-1) / np.linalg.norm(a, axis=-1) / np.linalg.norm(b, axis=-1), -1, 1)
    return float(np.degrees(np.arccos(c)).mean())


def test_port_normal_map_at_frame_k_matches_the_reference_surface_at_frame_k(mi, animated):
    """The port's normal at frame k (its normal map looked up at frame k's wave1..wave4) against
    the normal of the reference's displaced water mesh at frame k under the same point: the
    matching frame agrees within the normal-averaging and filtering approximations, every other
    frame (the surface not moved, or moved by another frame's offsets) is far off."""
    from study.scene.mitsuba_scene import build_scene, set_waves

    frames = animated["frames"]
    scene = build_scene(frames[0], 8, 8)  # frame 0's scene, moved below (as calibrate does)
    port = [_port_normals(i.with_resolution(96, 96)) for i in animated["inputs"]]
    angle = np.zeros((len(frames), len(frames)))
    for j, e in enumerate(frames):  # the reference surface at frame j
        set_waves(scene, e)
        for k, (xz, n) in enumerate(port):  # the port at frame k
            angle[k, j] = _mean_angle_deg(n, _reference_normals(mi, scene, xz))
    matched = np.diag(angle)
    mismatched = angle[~np.eye(len(frames), dtype=bool)]
    # measured: 0.24-0.34 degrees matched, 5.7-9.2 degrees between frames
    assert matched.max() < 0.1 * mismatched.min(), angle
    assert matched.max() < 0.6, angle


def test_moved_scene_renders_as_one_built_for_the_frame(mi):
    """``set_waves`` on frame 0's scene renders frame 2 bit for bit as a scene built for it."""
    from study.scene.frames import frame_experiment
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


def test_frames_are_still_experiments_with_their_own_keys():
    """Frame k's offsets follow wave_i(k) = offsets_i + k dt v_i; frame 0 is the experiment as a
    still (same reference and inputs keys); each frame has its own keys; the offsets-free key is
    shared by the frames only."""
    from study.scene.frames import frame_experiment, frame_offsets, offsets_free_key

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
    """The frames build world y, the dry render, the lighting scene and the maps once; frame 1's
    inputs built through them equal frame 1's inputs built alone, array for array, and the frames'
    refraction textures differ (the light through the moving waves moves)."""
    from study.scene.shader_inputs import build_shader_inputs

    shared = animated["shared"]
    assert sorted(shared.built) == ["dry_render", "lighting_scene", "maps", "world_y"]
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
    with pytest.raises(ValueError, match="animation.frames"):
        temporal_errors(refs[:1], refs[:1], mask)
    bad = [r.copy() for r in refs]
    bad[2][3, 3, 0] = np.nan
    with pytest.raises(ValueError, match="not finite"):
        temporal_errors(refs, bad, mask)
