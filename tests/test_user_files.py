"""The user's scene files: reading, validation (errors name the key and the file), the sun
found in an HDR map, cache keys on file contents, the mesh in the reference and in the
reflection textures, and the example files' script."""

from __future__ import annotations

import math
import shutil
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

from helpers import REPO, experiments
from helpers.experiments import replaced
from study.config.experiment import ExperimentError, load_experiment, validate
from study.config import files as uf
from study.config.floor import albedo_over_pool
from study.config.image_maths import latlong_lookup

FILES = REPO / "experiments" / "files"
USER = REPO / "experiments" / "user_files.toml"
TINY = replaced(experiments.TINY, "reference.spp=8")


def _exr(path, channels):
    import OpenEXR

    hdr = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    OpenEXR.File(hdr, {k: np.ascontiguousarray(v, np.float32) for k, v in channels.items()}).write(
        str(path)
    )
    return path


def _exp(**sets):
    return validate({}, [f"{k}={v}" for k, v in sets.items()])


def _hm(path):
    return {"floor.shape": '"heightmap"', "floor.heightmap": f'"{path}"'}


# ---- validation ---------------------------------------------------------------------------


def _bad_cases(tmp):
    rgb = _exr(tmp / "rgb.exr", {"RGB": np.full((8, 8, 3), 0.5)})
    nan = np.zeros((8, 8))
    nan[3, 4] = np.nan
    sky = np.full((8, 16, 3), 0.5)
    sky[2, 3, 1] = -1.0
    png8 = tmp / "h8.png"
    Image.fromarray(np.zeros((8, 8), np.uint8)).save(png8)
    (tmp / "junk.exr").write_bytes(b"not an exr at all")
    (tmp / "junk.ply").write_text("solid nonsense\n")
    return {
        "missing": (_hm(tmp / "none.exr"), "floor.heightmap", "no such file"),
        "extension": (_hm(tmp / "h.txt"), "floor.heightmap", "expected a .exr"),
        "unreadable": (_hm(tmp / "junk.exr"), "floor.heightmap", "not a readable image"),
        "channels": (_hm(rgb), "floor.heightmap", "expected one channel"),
        "nan": (_hm(_exr(tmp / "nan.exr", {"Y": nan})), "floor.heightmap", "NaN or infinite"),
        "8bit": (_hm(png8), "floor.heightmap", "16-bit PNG"),
        "no_map": ({"floor.shape": '"heightmap"'}, "floor.shape", "needs floor.heightmap"),
        "shape": ({"floor.heightmap": f'"{rgb}"'}, "floor.heightmap", "set floor.shape"),
        "extent": (
            {**_hm(_exr(tmp / "y.exr", {"Y": np.zeros((8, 8))})), "floor.extent": "[-1, -1, 1, 1]"},
            "floor.heightmap",
            "does not cover the water",
        ),
        "albedo_range": (
            {"floor.albedo_image": f'"{_exr(tmp / "a.exr", {"RGB": np.full((8, 8, 3), 1.5)})}"'},
            "floor.albedo_image",
            "in [0, 1]",
        ),
        "sky_negative": (
            {"sky.envmap": f'"{_exr(tmp / "s.exr", {"RGB": sky})}"'},
            "sky.envmap",
            "negative",
        ),
        "sky_aspect": ({"sky.envmap": f'"{rgb}"'}, "sky.envmap", "twice as wide"),
        "no_sun": (
            {
                "sky.envmap": f'"{_exr(tmp / "flat.exr", {"RGB": np.ones((8, 16, 3))})}"',
                "sun.source": '"envmap"',
            },
            "sky.envmap",
            "no sun",
        ),
        "sun_without_map": ({"sun.source": '"envmap"'}, "sun.source", "needs sky.envmap"),
        "sun_radius": (
            {
                "sky.envmap": f'"{_exr(tmp / "s2.exr", {"RGB": np.ones((8, 16, 3))})}"',
                "sun.radius": "1.0",
            },
            "sun.radius",
            "below one texel",
        ),
        "ply": ({"mesh.file": f'"{tmp / "junk.ply"}"'}, "mesh.file", "not a PLY"),
        "texture_alone": (
            {"mesh.texture": f'"{FILES / "rock_texture.png"}"'},
            "mesh.texture",
            "without mesh.file",
        ),
    }


def test_every_bad_file_is_refused_naming_key_and_file(tmp_path):
    for name, (sets, key, text) in _bad_cases(tmp_path).items():
        with pytest.raises(ExperimentError) as err:
            _exp(**sets)
        msg = str(err.value)
        assert key in msg and text in msg, (name, msg)
        files = [v.strip('"') for k, v in sets.items() if k in uf.FILE_KEYS]
        assert all(f in msg for f in files if key in uf.FILE_KEYS), (name, msg)
        assert len(msg) < 600, (name, msg)


def test_a_long_path_is_named_with_its_file(tmp_path):
    """A missing file in a deep folder: the error keeps the file's name and the folder's tail
    (a message cut at a fixed length from the start lost the name)."""
    deep = tmp_path / ("d" * 60) / ("e" * 60)
    missing = deep / "floor_height.exr"
    with pytest.raises(ExperimentError) as err:
        _exp(**{"floor.shape": '"heightmap"', "floor.heightmap": f'"{missing}"'})
    msg = str(err.value)
    assert str(missing) in msg and "no such file" in msg, msg
    very = tmp_path / ("f" * 300) / "floor_height.exr"
    with pytest.raises(ExperimentError) as err:
        _exp(**{"floor.shape": '"heightmap"', "floor.heightmap": f'"{very}"'})
    # a folder name longer than the file system allows: named, clipped, never a traceback
    msg = str(err.value)
    assert "...f" in msg and "/floor_height.exr" in msg and "File name too long" in msg, msg
    assert len(msg) < 600


def test_relative_paths_resolve_against_the_experiment_file():
    exp = load_experiment(USER)
    for key in uf.FILE_KEYS:
        if exp[key]:
            assert exp[key].startswith(str(FILES)), (key, exp[key])
    assert set(exp.digests) == {k for k in uf.FILE_KEYS if exp[k]} == set(uf.FILE_KEYS)


# ---- heightmap and albedo -----------------------------------------------------------------


def test_heightmap_png16_and_exr_give_the_same_floor(tmp_path):
    from study.scene.mitsuba_scene import floor_of

    rng = np.random.default_rng(0)
    h = rng.integers(0, 65536, size=(16, 12)).astype(np.uint16)
    Image.fromarray(h).save(tmp_path / "h.png")
    _exr(tmp_path / "h.exr", {"Y": h / 65535.0})
    ext = "[-5, -6, 7, 6]"
    e1 = _exp(
        **_hm(tmp_path / "h.png"),
        **{"floor.extent": ext, "floor.height_scale": "0.5", "floor.depth": "2"},
    )
    e2 = _exp(
        **_hm(tmp_path / "h.exr"),
        **{"floor.extent": ext, "floor.height_scale": "0.5", "floor.depth": "2"},
    )
    # texel centres: x = -5 + (i + 0.5) * 1, z = -6 + (j + 0.5) * 0.75
    i, j = np.meshgrid(np.arange(12), np.arange(16))
    x, z = -5 + (i + 0.5), -6 + (j + 0.5) * 0.75
    want = -2 + 0.5 * h / 65535.0
    np.testing.assert_allclose(floor_of(e1, x, z), want, atol=1e-6)
    np.testing.assert_allclose(floor_of(e2, x, z), want, atol=1e-6)
    assert e1.scene_hash() != e2.scene_hash()  # different files, different scenes


def test_albedo_png_is_decoded_from_srgb(tmp_path):
    img = np.zeros((8, 8, 3), np.uint8)
    img[...] = (128, 0, 255)
    Image.fromarray(img).save(tmp_path / "a.png")
    exp = _exp(**{"floor.albedo_image": f'"{tmp_path / "a.png"}"'})
    a = albedo_over_pool(exp.values)
    np.testing.assert_allclose(a[0, 0], [0.2158605, 0.0, 1.0], atol=1e-5)


# ---- sky and sun --------------------------------------------------------------------------


def _sky_with_sun(h, elev, azim, radius, radiance):
    sys.path.insert(0, str(REPO / "scripts"))
    from make_example_files import sky

    return sky(h, elev, azim, radius, radiance)


@pytest.mark.parametrize("rotation", [0.0, 30.0, -75.0])
def test_sun_found_in_the_map_follows_the_rotation(tmp_path, rotation):
    _exr(tmp_path / "sky.exr", {"RGB": _sky_with_sun(256, 35.0, 120.0, 3.0, (50.0, 45.0, 40.0))})
    exp = _exp(
        **{
            "sky.envmap": f'"{tmp_path / "sky.exr"}"',
            "sun.source": '"envmap"',
            "sky.rotation": str(rotation),
            "sky.scale": "2.0",
        }
    )
    from study.scene.user_scene import sun_summary

    s = sun_summary(exp)
    assert s["elevation_deg"] == pytest.approx(35.0, abs=0.5)
    assert (s["azimuth_deg"] - (120.0 + rotation) + 180) % 360 - 180 == pytest.approx(0.0, abs=0.8)
    disc = 2 * math.pi * (1 - math.cos(math.radians(3.0)))
    assert s["solid_angle_sr"] == pytest.approx(disc, rel=0.25)
    # the region's mean radiance: the disc's (x 2 for sky.scale) plus the sky under it
    assert s["radiance"][0] == pytest.approx(2 * 50.0, rel=0.15)


def test_shader_cube_map_is_the_map_without_its_sun(tmp_path):
    from study.scene.geometry import cubemap_directions
    from study.scene.user_scene import reference_sky, shader_cubemap

    _exr(tmp_path / "sky.exr", {"RGB": _sky_with_sun(128, 40.0, 250.0, 4.0, (9.0, 8.4, 7.0))})
    exp = _exp(**{"sky.envmap": f'"{tmp_path / "sky.exr"}"', "sun.source": '"envmap"'})
    cube = shader_cubemap(exp, 16)
    ref = reference_sky(exp)
    assert ref.max() > 8.0 and cube.max() < 2.0  # the sun stays in the reference only
    d = cubemap_directions(16) * np.array([1.0, -1.0, 1.0])  # stored y-flipped
    no_sun = _sky_with_sun(128, 40.0, 250.0, 4.0, (0.0, 0.0, 0.0))
    want = latlong_lookup(no_sun.astype(np.float64), d)
    sun = np.array(
        [
            math.cos(math.radians(40)) * math.cos(math.radians(250)),
            math.sin(math.radians(40)),
            math.cos(math.radians(40)) * math.sin(math.radians(250)),
        ]
    )
    away = (d * np.array([1.0, -1.0, 1.0])) @ sun < math.cos(math.radians(15))
    assert np.abs(cube - want)[away].mean() < 0.02


def test_explicit_sun_is_added_to_the_map(tmp_path):
    from study.scene.user_scene import reference_sky, sun_of

    _exr(tmp_path / "sky.exr", {"RGB": np.full((64, 128, 3), 0.5)})
    exp = _exp(
        **{
            "sky.envmap": f'"{tmp_path / "sky.exr"}"',
            "sun.radius": "5",
            "sun.radiance": "[10, 10, 10]",
        }
    )
    ref = reference_sky(exp)
    assert ref.max() == pytest.approx(10.5) and ref.min() == pytest.approx(0.5)
    d, rad = sun_of(exp)
    np.testing.assert_allclose(rad, [10, 10, 10])


# ---- cache keys ---------------------------------------------------------------------------


def test_file_contents_are_in_the_cache_keys(tmp_path):
    for name in ("heightmap.png", "albedo.png", "sky.exr", "rock.obj", "rock_texture.png"):
        shutil.copy(FILES / name, tmp_path / name)
    shutil.copy(USER, tmp_path / "user.toml")
    text = (tmp_path / "user.toml").read_text().replace("files/", "")
    (tmp_path / "user.toml").write_text(text)
    a = load_experiment(tmp_path / "user.toml")
    b = load_experiment(USER)  # same contents, other paths
    assert a.scene_hash() == b.scene_hash() and a.inputs_hash() == b.inputs_hash()
    with open(tmp_path / "rock.obj", "a") as f:
        f.write("# changed\n")
    c = load_experiment(tmp_path / "user.toml")
    assert c.scene_hash() != a.scene_hash() and c.inputs_hash() != a.inputs_hash()


# ---- mesh ---------------------------------------------------------------------------------


def test_obj_and_ply_load_to_the_same_placed_mesh(mi):
    from study.scene.user_scene import mesh_bounds

    sets = {"mesh.position": "[0.5, 0.2, -0.3]", "mesh.scale": "1.1", "mesh.rotation": "10"}
    a = mesh_bounds(mi, _exp(**{"mesh.file": f'"{FILES / "rock.obj"}"', **sets}))
    b = mesh_bounds(mi, _exp(**{"mesh.file": f'"{FILES / "rock.ply"}"', **sets}))
    np.testing.assert_allclose(a[0], b[0], atol=1e-4)
    np.testing.assert_allclose(a[1], b[1], atol=1e-4)
    assert a[0][1] == pytest.approx(0.2 + 1.1 * 0.36, abs=1e-4)


def test_mesh_into_the_water_is_refused(mi):
    from study.scene.user_scene import check_scene

    exp = _exp(**{"mesh.file": f'"{FILES / "rock.obj"}"', "mesh.position": "[0, -0.35, 0]"})
    with pytest.raises(ExperimentError, match=r"mesh.file: .*into the water.*rock\.obj"):
        check_scene(exp)


def test_mesh_texture_needs_texture_coordinates(mi, tmp_path):
    from study.scene.user_scene import check_scene

    text = "\n".join(
        l for l in (FILES / "rock.obj").read_text().splitlines() if not l.startswith("vt")
    )
    text = text.replace("f ", "F ").replace("F ", "f ")
    import re

    text = re.sub(r"(\d+)/\d+", r"\1", text)
    (tmp_path / "bare.obj").write_text(text + "\n")
    exp = _exp(
        **{
            "mesh.file": f'"{tmp_path / "bare.obj"}"',
            "mesh.texture": f'"{FILES / "rock_texture.png"}"',
        }
    )
    with pytest.raises(ExperimentError, match="mesh.texture needs texture coordinates"):
        check_scene(exp)


def test_mesh_is_in_the_reference_and_the_reflection_textures(mi):
    from study.scene.mitsuba_scene import build_scene
    from study.scene.shader_inputs import build_shader_inputs

    exp = load_experiment(USER, TINY)
    scene = build_scene(exp)
    ray = mi.Ray3f(mi.Point3f(0.0, 5.0, -5.3), mi.Vector3f(0.0, -1.0, 0.0))
    si = scene.ray_intersect(ray)
    assert bool(si.is_valid()[0]) and float(si.p.y[0]) > 0.36  # the ridge, above the water
    inputs = build_shader_inputs(exp, 24, 24)
    tm = inputs.tex_matrix1
    s, t = tm[0, 0] * 0.0 + tm[0, 3], tm[1, 2] * -5.3 + tm[1, 3]  # texel under (0, -5.3)
    n = inputs.refl_world_y.shape[0]
    y = inputs.refl_world_y[int(t * n), int(s * n)]
    assert y == pytest.approx(float(si.p.y[0]), abs=0.1)
    assert (inputs.refl_world_y > exp["pool.wall_height"] + 0.01).mean() > 0.05
    assert inputs.refl_texture[int(t * n), int(s * n)].max() > 0.0


# ---- example files ------------------------------------------------------------------------


def test_example_files_script_reproduces_the_shipped_files(tmp_path):
    res = subprocess.run(
        [sys.executable, str(REPO / "scripts" / "make_example_files.py"), "--out", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert res.returncode == 0, res.stderr
    for p in sorted(FILES.iterdir()):
        if p.suffix == ".exr":  # compare texels (the header may carry a writer version)
            a, b = (
                uf._read_image("k", str(p), "a"),
                uf._read_image("k", str(tmp_path / p.name), "b"),
            )
            assert np.array_equal(a, b), p.name
        else:
            assert (tmp_path / p.name).read_bytes() == p.read_bytes(), p.name


@pytest.mark.slow
def test_user_files_experiment_calibrates_end_to_end(tmp_path):
    """`study calibrate experiments/user_files.toml` at tiny sizes: reference, inputs with the
    mesh, fit of water_reflection, export and GL check, report."""
    from study.cli import main

    tiny = replaced(TINY, "fit.max_steps=3")
    assert main(["calibrate", str(USER), "--out", str(tmp_path), *experiments.sets(tiny)]) == 0
    summary = __import__("json").loads((tmp_path / "constants.json").read_text())
    assert summary["shader"] == "water_reflection"
    assert (
        summary["gl_check"]["passed"]
        and (tmp_path / "shaders" / "core" / "water_reflection.frag").is_file()
    )
    assert {
        "inputs.mesh_reflection_s",
        "inputs.lighting_s",
        "fit_s",
        "gl_check_s",
        "figures_s",
        "total_s",
    } <= set(summary["timings"])
    report = (tmp_path / "report.md").read_text()
    assert "inputs.mesh_reflection_s" in report and "gl_check_s" in report
