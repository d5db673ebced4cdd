"""Write the small example scene files of ``experiments/user_files.toml`` (no downloads).

    .venv/bin/python scripts/make_example_files.py [--out experiments/files]

Files (all procedural, deterministic; world units, +y up, water plane y = 0):

* ``heightmap.png``: 16-bit greyscale, 128 x 128 texels over [-4.5, 4.5]^2 (row 0 at z = -4.5):
  a basin sloping down towards -x with a ridge and a round mound; texels in [0, 1]
  (the experiment scales them by ``floor.height_scale``);
* ``albedo.png``: 8-bit sRGB, 256 x 256 over the same square: sand with darker pebbles and
  a band of weed;
* ``sky.exr``: RGB lat-long HDR sky, 256 x 128 (Mitsuba's envmap convention), a blue
  gradient with soft clouds, a bright ground-coloured lower half and a sun disc of 4 degrees
  radius at elevation 40, azimuth 250 degrees (radiance about 9);
* ``rock.obj``: a closed rocky ridge (top surface, skirt, flat bottom) with texture
  coordinates, on the far (-z) side of the pool, its bottom at y = 0.36 (above the walls);
* ``rock.ply``: the same mesh as an ASCII PLY (x y z u v);
* ``rock_texture.png``: 8-bit sRGB stone texture for ``mesh.texture``;
* ``water_normals.png``: 8-bit RGB tangent-space normal map, 256 x 256, of the default
  experiment's wave height field (``waves.*`` of ``experiments/default.toml``, one repeat per
  ``waves.normal_tile``) as engines author one: RGB = ``0.5 n + 0.5`` with ``n`` = (along u =
  world x, along v = world z, up), slopes authored 8 times steeper than one layer of the
  waves (a shader scales them down), the top row at v = 1; read by the engine-style shaders of
  ``experiments/shaders/`` (``// @study normal_map``).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent


def heightmap(n: int = 128) -> np.ndarray:
    c = (np.arange(n) + 0.5) / n * 9.0 - 4.5
    x, z = np.meshgrid(c, c)  # row = z, column = x
    h = 0.55 + 0.25 * (x / 4.5)  # slope: deeper towards -x
    h += 0.25 * np.exp(-((x - 1.5) ** 2 + (z + 1.0) ** 2) / 0.8)  # mound
    h += 0.12 * np.exp(-((z - 1.8) ** 2) / 0.15) * (x > -2.5)  # ridge
    h += 0.03 * np.sin(3.1 * x + 1.3) * np.sin(2.7 * z)  # ripples
    return np.clip(h, 0.0, 1.0)


def albedo(n: int = 256) -> np.ndarray:
    rng = np.random.default_rng(7)
    c = (np.arange(n) + 0.5) / n * 9.0 - 4.5
    x, z = np.meshgrid(c, c)
    sand = np.array([0.62, 0.55, 0.40])
    img = np.broadcast_to(sand, (n, n, 3)).copy()
    img *= (0.9 + 0.1 * np.sin(5 * x + 2 * np.sin(3 * z)))[..., None]
    for _ in range(120):  # pebbles
        px, pz, r = rng.uniform(-4.5, 4.5), rng.uniform(-4.5, 4.5), rng.uniform(0.05, 0.18)
        inside = (x - px) ** 2 + (z - pz) ** 2 < r * r
        img[inside] = rng.uniform(0.15, 0.45) * np.array([1.0, 0.95, 0.9])
    weed = np.exp(-((z + 2.5 + 0.4 * np.sin(1.7 * x)) ** 2) / 0.2)[..., None]
    img = (1 - 0.7 * weed) * img + 0.7 * weed * np.array([0.12, 0.25, 0.08])
    return np.clip(img, 0.0, 1.0)


def sky(
    h: int = 128,
    sun_elevation: float = 40.0,
    sun_azimuth: float = 250.0,
    sun_radius: float = 4.0,
    sun_radiance=(9.0, 8.4, 7.0),
) -> np.ndarray:
    v = (np.arange(h) + 0.5) / h
    u = (np.arange(2 * h) + 0.5) / (2 * h)
    th, ph = np.meshgrid(v * np.pi, u * 2 * np.pi, indexing="ij")
    d = np.stack([np.sin(th) * np.sin(ph), np.cos(th), -np.sin(th) * np.cos(ph)], -1)
    y = d[..., 1:2]
    t = np.sqrt(np.clip(y, 0, 1))
    img = np.where(
        y >= 0,
        (1 - t) * np.array([0.85, 0.88, 0.95]) + t * np.array([0.22, 0.42, 0.88]),
        np.array([0.32, 0.3, 0.26]),
    )
    cloud = (np.sin(3 * ph + 1.0) * np.sin(5 * th) + 0.5 * np.sin(7 * ph + 2 * th)) * (
        y[..., 0] > 0.05
    )
    img = img + 0.15 * np.clip(cloud, 0, None)[..., None]
    e, a = math.radians(sun_elevation), math.radians(sun_azimuth)
    s = np.array([math.cos(e) * math.cos(a), math.sin(e), math.cos(e) * math.sin(a)])
    inside = (d @ s) >= math.cos(math.radians(sun_radius))
    img = img + inside[..., None] * np.asarray(sun_radiance)
    return img.astype(np.float32)


def rock(nx: int = 33, nz: int = 9):
    """(positions (V, 3), texcoords (V, 2), faces (F, 3)) of a closed ridge over
    x in [-4.8, 4.8], z in [-6.2, -4.4], bottom at y = 0.36."""
    xs, zs = np.linspace(-4.8, 4.8, nx), np.linspace(-6.2, -4.4, nz)
    x, z = np.meshgrid(xs, zs)  # (nz, nx)
    edge = np.minimum(np.minimum(x + 4.8, 4.8 - x), np.minimum(z + 6.2, -4.4 - z))
    top = 0.36 + np.clip(edge / 0.35, 0, 1) * (
        0.55 + 0.35 * np.sin(1.3 * x) ** 2 + 0.15 * np.cos(3.7 * x + 2 * z)
    )
    bottom = 0.36
    pos_top = np.stack([x, top, z], -1).reshape(-1, 3)
    pos_bot = np.stack([x, np.full_like(x, bottom), z], -1).reshape(-1, 3)
    uv_top = np.stack([(x + 4.8) / 9.6, (z + 6.2) / 1.8], -1).reshape(-1, 2)
    pos = np.concatenate([pos_top, pos_bot])
    uv = np.concatenate([uv_top, uv_top])
    idx = np.arange(nx * nz).reshape(nz, nx)
    faces = []
    for j in range(nz - 1):
        for i in range(nx - 1):
            a, b, c, d = idx[j, i], idx[j, i + 1], idx[j + 1, i], idx[j + 1, i + 1]
            faces += [(a, c, b), (b, c, d)]  # top, facing +y
            off = nx * nz
            faces += [(a + off, b + off, c + off), (b + off, d + off, c + off)]  # bottom, facing -y
    # skirt: the boundary of the top grid joined to the bottom grid's
    ring = np.concatenate([idx[0, :-1], idx[:-1, -1], idx[-1, :0:-1], idx[:0:-1, 0]])
    off = nx * nz
    for k in range(len(ring)):
        p, q = ring[k], ring[(k + 1) % len(ring)]
        faces += [(p, q, q + off), (p, q + off, p + off)]
    return pos, uv, np.array(faces, np.int64)


def rock_texture(n: int = 128) -> np.ndarray:
    c = (np.arange(n) + 0.5) / n
    u, v = np.meshgrid(c, c)
    base = np.array([0.42, 0.38, 0.33])
    strata = 0.75 + 0.25 * np.sin(40 * v + 3 * np.sin(9 * u))
    speck = 0.9 + 0.1 * np.sin(97 * u) * np.sin(71 * v)
    return np.clip(base * (strata * speck)[..., None], 0, 1)


def water_normals(n: int = 256, steeper: float = 8.0) -> np.ndarray:
    """(n, n, 3) uint8 tangent-space normal map of the default waves (see the module doc), rows
    top first (v = 1 at row 0)."""
    from study import load_experiment  # noqa: PLC0415 - the study's waves, only for this file
    from study.scene.geometry import Waves  # noqa: PLC0415

    exp = load_experiment(REPO / "experiments" / "default.toml")
    w = Waves(exp["waves.amplitude"], exp["waves.normal_tile"], exp["waves.components"],
              exp["waves.seed"], exp["waves.offsets"])  # fmt: skip
    c = (np.arange(n) + 0.5) / n
    u, v = np.meshgrid(c, c[::-1])  # row 0 at the top: v = 1
    _, hu, hv = w._h0(u, v)
    s = steeper * w.amplitude / w.tile
    t = np.stack([-s * hu, -s * hv, np.ones_like(hu)], -1)
    t /= np.linalg.norm(t, axis=-1, keepdims=True)
    return np.clip(np.rint((0.5 * t + 0.5) * 255.0), 0, 255).astype(np.uint8)


def linear_to_srgb8(img: np.ndarray) -> np.ndarray:
    x = np.clip(img, 0, 1)
    s = np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)
    return (s * 255 + 0.5).astype(np.uint8)


def write_obj(path: Path, pos, uv, faces) -> None:
    lines = ["# closed rocky ridge (scripts/make_example_files.py)"]
    lines += [f"v {p[0]:.6f} {p[1]:.6f} {p[2]:.6f}" for p in pos]
    lines += [f"vt {t[0]:.6f} {t[1]:.6f}" for t in uv]
    lines += [f"f {a + 1}/{a + 1} {b + 1}/{b + 1} {c + 1}/{c + 1}" for a, b, c in faces]
    path.write_text("\n".join(lines) + "\n")


def write_ply(path: Path, pos, uv, faces) -> None:
    head = [
        "ply",
        "format ascii 1.0",
        f"element vertex {len(pos)}",
        "property float x",
        "property float y",
        "property float z",
        "property float u",
        "property float v",
        f"element face {len(faces)}",
        "property list uchar int vertex_indices",
        "end_header",
    ]
    body = [f"{p[0]:.6f} {p[1]:.6f} {p[2]:.6f} {t[0]:.6f} {t[1]:.6f}" for p, t in zip(pos, uv)]
    body += [f"3 {a} {b} {c}" for a, b, c in faces]
    path.write_text("\n".join(head + body) + "\n")


def write_exr(path: Path, channels: dict) -> None:
    import OpenEXR

    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    OpenEXR.File(
        header, {k: np.ascontiguousarray(v, np.float32) for k, v in channels.items()}
    ).write(str(path))


def main(argv=None) -> None:
    from PIL import Image

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(REPO / "experiments" / "files"))
    out = Path(ap.parse_args(argv).out)
    out.mkdir(parents=True, exist_ok=True)
    h16 = (heightmap() * 65535 + 0.5).astype(np.uint16)
    Image.fromarray(h16).save(out / "heightmap.png")  # mode I;16
    Image.fromarray(linear_to_srgb8(albedo())).save(out / "albedo.png")
    write_exr(out / "sky.exr", {"RGB": sky()})
    pos, uv, faces = rock()
    write_obj(out / "rock.obj", pos, uv, faces)
    write_ply(out / "rock.ply", pos, uv, faces)
    Image.fromarray(linear_to_srgb8(rock_texture())).save(out / "rock_texture.png")
    Image.fromarray(water_normals()).save(out / "water_normals.png")
    for p in sorted(out.iterdir()):
        print(f"{p}  {p.stat().st_size} bytes")


if __name__ == "__main__":
    main()
