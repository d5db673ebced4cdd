"""The exported WGSL run on WebGPU: wgpu (wgpu-native) on Mesa's lavapipe, Vulkan on the CPU.

:class:`WgslRenderer` draws an export's ``wgsl/water.vert.wgsl`` and ``wgsl/<shader>.frag.wgsl``
for a :class:`~shaders_port.inputs.ShaderInputs` as ``shaders_port.gl.renderer.GLRenderer``
draws the GLSL on llvmpipe: the same textures (float32; the filter and wrap of each from the GL
renderer's table; the cube map's faces in GL order, which is WebGPU's layer order), the same
uniforms, packed at the offsets of the export's reflection (``wgsl/*.reflect.json``), the water
quad without depth test, into an ``rgba32float`` target of the inputs' size. Its
:meth:`~WgslRenderer.render` is the ``render(constants)`` that
``shaders_port.gl.compare.compare_port_gl`` takes (``renderer=``).

The fitted constants are ``override`` declarations of the fragment shader: by default the
pipeline keeps their defaults (the file's own values); with ``overrides=True`` every override is
set at pipeline creation (``constants={"<id>": value}``) from the constants ``render`` is given.

The water rectangle is drawn as it is (lavapipe snaps vertices to a sub-pixel grid as llvmpipe
does, and matches the port as closely). One difference is WebGPU's by design: a cube map is
filtered across its faces (seamless), where the port and the GL check filter each face on its own
(``GL_TEXTURE_CUBE_MAP_SEAMLESS`` off), so a sky discontinuous at its seams differs there, as in
the WebGL 2 viewer.
"""

from __future__ import annotations

import functools
import json
from pathlib import Path

import numpy as np

from shaders_port.gl.renderer import MIPMAPPED, OPTIONAL_SAMPLERS, OPTIONAL_VEC3, SAMPLERS
from shaders_port.pipeline.normal_maps import DERIVED_MAPS
from shaders_port.pipeline.texture import box_mip_chain
from shaders_port.inputs import Constants, ShaderInputs, normal_matrix
from shaders_port.variants import get_variant

ADAPTER_HELP = (
    "no Vulkan adapter of Mesa's lavapipe for wgpu; install it with `apt-get install "
    "mesa-vulkan-drivers` (scripts/setup.sh does) and the Python package wgpu (the dev extra)"
)
_MASK_FRAG = "@fragment\nfn main() -> @location(0) vec4<f32> {\n    return vec4<f32>(1.0);\n}\n"
_VIEW = {"texture_2d": "2d", "texture_cube": "cube", "texture_3d": "3d",
         "texture_2d_array": "2d-array", "texture_cube_array": "cube-array"}  # fmt: skip
_DTYPES = {"f32": np.float32, "i32": np.int32, "u32": np.uint32, "bool": np.uint32}


@functools.lru_cache(maxsize=1)
def _lavapipe_adapter():
    try:
        import wgpu
    except ImportError as exc:
        raise RuntimeError(f"{ADAPTER_HELP} ({exc})") from exc
    adapters = [
        a for a in wgpu.gpu.enumerate_adapters_sync()
        if a.info["backend_type"] == "Vulkan" and "llvmpipe" in a.info["device"]
    ]  # fmt: skip
    if not adapters:
        raise RuntimeError(ADAPTER_HELP)
    if "float32-filterable" not in adapters[0].features:
        raise RuntimeError(
            "lavapipe lacks float32-filterable, which the linear float textures need"
        )
    return adapters[0]


def lavapipe_device():
    """A wgpu device on Mesa's lavapipe (the Vulkan adapter whose device is llvmpipe) with the
    feature ``float32-filterable``; RuntimeError naming ``mesa-vulkan-drivers`` without one."""
    return _lavapipe_adapter().request_device_sync(required_features=["float32-filterable"])


def pack_block(block: dict, values: dict) -> bytes:
    """The bytes of a uniform block of the WGSL reflection (``uniform_blocks[i]``): each member
    whose GLSL name is in ``values`` at its offset (a matrix, a (R, C) array acting on column
    vectors, column by column ``matrix_stride`` bytes apart); the rest zero."""
    buf = bytearray(block["size"])
    for m in block["members"]:
        if m["glsl"] not in values:
            continue
        v = np.asarray(values[m["glsl"]])
        scalar = m["type"].rsplit("<", 1)[-1].rstrip(">") if "<" in m["type"] else m["type"]
        dtype = _DTYPES[scalar]
        if "matrix_stride" in m:
            for c in range(v.shape[1]):
                col = np.ascontiguousarray(v[:, c], dtype).tobytes()
                at = m["offset"] + c * m["matrix_stride"]
                buf[at : at + len(col)] = col
        else:
            data = np.ascontiguousarray(v, dtype).ravel().tobytes()
            buf[m["offset"] : m["offset"] + len(data)] = data
    return bytes(buf)


def uniform_values(inputs: ShaderInputs) -> dict:
    """GLSL uniform name -> value of the study's shaders for ``inputs``, as the GL renderer sets
    them (matrices as (R, C) arrays on column vectors), with ``glFramebufferHeight``."""
    i = inputs
    vals = {
        "WaterTransformationMatrix": np.eye(4),
        "uModelViewProjectionMatrix": i.view_proj,
        "uModelViewProjectionMatrixInverse": np.linalg.inv(i.view_proj.astype(np.float64)),
        "uNormalMatrix": normal_matrix(i.view_proj),
        "uTextureMatrix0": i.tex_matrix0,
        "uTextureMatrix1": i.tex_matrix1,
        "viewpos": i.viewpos,
        "lightpos": i.lightpos,
        "lightcolor": i.lightcolor,
        "screenSize": (i.width, i.height),
        "glFramebufferHeight": i.height,
    }
    vals.update({f"wave{k + 1}": i.waves[k] for k in range(4)})
    if i.reflection_view_proj is not None:
        vals["o2v_projection_reflection"] = i.reflection_view_proj
    for uname, field in OPTIONAL_VEC3.items():
        if getattr(i, field) is not None:
            vals[uname] = getattr(i, field)
    return vals


def override_values(constants: Constants, overrides: list) -> dict:
    """``constants={"<id>": value}`` for every override of the reflection's ``overrides``, from
    ``constants`` (a colour's ``waterColor_g`` from ``waterColor[1]``)."""
    glsl = constants.to_glsl_dict()
    out = {}
    for o in overrides:
        name = o["name"]
        if name in glsl:
            out[str(o["id"])] = float(glsl[name])
        else:
            base, comp = name.rsplit("_", 1)
            out[str(o["id"])] = float(glsl[base]["rgba".index(comp)])
    return out


def _texture_arrays(inputs: ShaderInputs) -> dict:
    """GLSL sampler name -> (array, cube?) of the inputs, as the GL renderer uploads them."""
    i = inputs
    out = {
        "refractionTexture": i.refraction_texture,
        "worldYComponent": i.world_y,
        "normalMap": i.normal_map,
        "reflectionTexture": i.cubemap,
        "fresnelLookup": i.fresnel_lut[None, :, :],
        "worldYComponentReflection": i.refl_world_y,
        "reflectionBottom": i.refl_texture,
        # the maps derived from the normal map (slopeMoments mipmapped: MIPMAPPED)
        **{s: texels(i.normal_map) for s, texels in DERIVED_MAPS.items()},
    }
    out.update(
        {s: getattr(i, f) for s, f in OPTIONAL_SAMPLERS.items() if getattr(i, f) is not None}
    )
    return out


class WgslRenderer:
    """Draw an export's WGSL pair (``folder``: the export's ``shaders/``; ``shader``: the
    fragment shader's file stem, e.g. ``water_refraction``) for ``inputs`` (as the variant's
    application uploads them: ``Variant.prepare_inputs``) on lavapipe.
    ``overrides``: set the overrides from the constants :meth:`render` is given (else the
    file's defaults)."""

    def __init__(self, folder, shader: str, inputs: ShaderInputs, *, overrides: bool = False):
        self.device = lavapipe_device()  # first: RuntimeError naming what to install
        import wgpu

        try:  # the textures as the variant's application uploads them (game precision)
            inputs = get_variant(shader).prepare_inputs(inputs)
        except ValueError:  # a file of no registered shader: the inputs as given
            pass
        self.wgpu, self.inputs, self.overrides = wgpu, inputs, overrides
        folder = Path(folder) / "wgsl"
        self.stages = {}
        for stage, stem in (("vert", "water"), ("frag", shader)):
            path = folder / f"{stem}.{stage}.wgsl"
            refl = json.loads(path.with_name(f"{stem}.{stage}.reflect.json").read_text())
            self.stages[stage] = (path.read_text(), refl)
        d = self.device
        self.modules = {s: d.create_shader_module(code=t) for s, (t, _) in self.stages.items()}
        self.modules["mask"] = d.create_shader_module(code=_MASK_FRAG)
        self._layout, self._bind_group = self._bindings()
        self._pipelines, self._mask = {}, None

    # -- set-up -----------------------------------------------------------------------------
    def _texture(self, arr: np.ndarray, cube: bool, mipmapped: bool = False):
        """A float32 texture of ``arr`` ((H, W[, C]) or cube (6, F, F, C)), C = 1, 2 or 4 (3 is
        padded with alpha 1); row 0 at t = 0 as GL's; ``mipmapped``: with its box-filtered mip
        chain (``pipeline.texture.box_mip_chain``, the levels the GL check's llvmpipe makes)."""
        a = np.asarray(arr, np.float32)
        a = a[..., None] if a.ndim == (3 if cube else 2) else a
        if a.shape[-1] == 3:
            a = np.concatenate([a, np.ones(a.shape[:-1] + (1,), np.float32)], -1)
        fmt = {1: "r32float", 2: "rg32float", 4: "rgba32float"}[a.shape[-1]]
        h, w = a.shape[-3:-1]
        layers = 6 if cube else 1
        usage = self.wgpu.TextureUsage.TEXTURE_BINDING | self.wgpu.TextureUsage.COPY_DST
        chain = box_mip_chain(a) if mipmapped else [a]
        tex = self.device.create_texture(
            size=(w, h, layers), format=fmt, usage=usage, mip_level_count=len(chain)
        )
        for k, lv in enumerate(chain):
            lh, lw = lv.shape[-3:-1]
            self.device.queue.write_texture(
                {"texture": tex, "mip_level": k}, np.ascontiguousarray(lv).tobytes(),
                {"bytes_per_row": lw * a.shape[-1] * 4, "rows_per_image": lh}, (lw, lh, layers),
            )  # fmt: skip
        return tex.create_view(dimension="cube" if cube else "2d")

    def _sampler(self, glsl: str):
        if glsl not in SAMPLERS:
            raise RuntimeError(f"the WGSL samples {glsl!r}, which ShaderInputs has no texture for")
        _, filt, repeat = SAMPLERS[glsl]
        wrap = "repeat" if repeat else "clamp-to-edge"
        mip = "linear" if glsl in MIPMAPPED else "nearest"
        return self.device.create_sampler(
            mag_filter=filt, min_filter=filt, mipmap_filter=mip, address_mode_u=wrap,
            address_mode_v=wrap, address_mode_w=wrap,
        )  # fmt: skip

    def _bindings(self):
        """The bind group layout of both stages (union of their reflections) and the bind
        group of the inputs: textures, samplers and the uniform buffers."""
        S, vis = self.wgpu.ShaderStage, {"vert": 1, "frag": 2}
        entries, resources = {}, {}
        arrays, values = _texture_arrays(self.inputs), uniform_values(self.inputs)
        for stage, (_, refl) in self.stages.items():
            blocks = {b["binding"]: b for b in refl["uniform_blocks"]}
            for b in refl["bindings"]:
                n = b["binding"]
                if n in entries:
                    entries[n]["visibility"] |= vis[stage]
                    continue
                entry = {"binding": n, "visibility": vis[stage]}
                if b["kind"] == "texture":
                    if b["glsl"] not in arrays:
                        raise RuntimeError(f"ShaderInputs has no texture for {b['glsl']!r}")
                    dim = _VIEW[b["type"].split("<")[0]]
                    entry["texture"] = {"sample_type": "float", "view_dimension": dim}
                    mips = b["glsl"] in MIPMAPPED
                    resources[n] = self._texture(arrays[b["glsl"]], dim == "cube", mips)
                elif b["kind"] == "sampler":
                    entry["sampler"] = {"type": "filtering"}
                    resources[n] = self._sampler(b["glsl"])
                else:
                    entry["buffer"] = {"type": "uniform"}
                    data = pack_block(blocks[n], values)
                    buf = self.device.create_buffer_with_data(
                        data=data, usage=self.wgpu.BufferUsage.UNIFORM
                    )
                    resources[n] = {"buffer": buf, "offset": 0, "size": len(data)}
                entries[n] = entry
        for e in entries.values():
            e["visibility"] = (S.VERTEX if e["visibility"] & 1 else 0) | (
                S.FRAGMENT if e["visibility"] & 2 else 0
            )
        layout = self.device.create_bind_group_layout(entries=list(entries.values()))
        group = self.device.create_bind_group(
            layout=layout, entries=[{"binding": n, "resource": r} for n, r in resources.items()]
        )
        return self.device.create_pipeline_layout(bind_group_layouts=[layout]), group

    def _vertices(self, corners) -> object:
        """A vertex buffer of the triangle strip over ``corners`` ((x, z) on y = 0): each
        vertex's inputs by the vertex reflection's locations (``aVertex`` (x, 0, z, 1),
        ``aMultiTexCoord0`` (x, z) / normal_tile)."""
        tile = self.inputs.normal_tile
        per = {"aVertex": lambda x, z: (x, 0.0, z, 1.0),
               "aMultiTexCoord0": lambda x, z: (x / tile, z / tile, 0.0, 1.0)}  # fmt: skip
        inputs = self.stages["vert"][1]["inputs"]
        data = np.array([[c for v in inputs for c in per[v["name"]](x, z)] for x, z in corners])
        return self.device.create_buffer_with_data(
            data=data.astype(np.float32).tobytes(), usage=self.wgpu.BufferUsage.VERTEX
        )

    def _pipeline(self, which: str, constants: dict):
        key = (which, tuple(sorted(constants.items())))
        if key not in self._pipelines:
            inputs = self.stages["vert"][1]["inputs"]
            attrs = [{"shader_location": v["location"], "offset": 16 * k, "format": "float32x4"}
                     for k, v in enumerate(inputs)]  # fmt: skip
            frag = {"module": self.modules[which], "entry_point": "main",
                    "targets": [{"format": "rgba32float"}]}  # fmt: skip
            if constants:
                frag["constants"] = constants
            self._pipelines[key] = self.device.create_render_pipeline(
                layout=self._layout,
                vertex={"module": self.modules["vert"], "entry_point": "main",
                        "buffers": [{"array_stride": 16 * len(inputs), "attributes": attrs}]},
                primitive={"topology": "triangle-strip"},
                fragment=frag,
            )  # fmt: skip
        return self._pipelines[key]

    # -- drawing ----------------------------------------------------------------------------
    def _draw(self, pipeline, corners) -> np.ndarray:
        w, h = self.inputs.width, self.inputs.height
        usage = self.wgpu.TextureUsage.RENDER_ATTACHMENT | self.wgpu.TextureUsage.COPY_SRC
        target = self.device.create_texture(size=(w, h, 1), format="rgba32float", usage=usage)
        enc = self.device.create_command_encoder()
        rp = enc.begin_render_pass(color_attachments=[{
            "view": target.create_view(), "load_op": "clear", "store_op": "store",
            "clear_value": (0.0, 0.0, 0.0, 0.0)}])  # fmt: skip
        rp.set_pipeline(pipeline)
        rp.set_bind_group(0, self._bind_group)
        rp.set_vertex_buffer(0, self._vertices(corners))
        rp.draw(4)
        rp.end()
        self.device.queue.submit([enc.finish()])
        raw = self.device.queue.read_texture(
            {"texture": target}, {"bytes_per_row": w * 16, "rows_per_image": h}, (w, h, 1)
        )
        return np.frombuffer(raw, np.float32).reshape(h, w, 4).copy()  # row 0: top

    def render(self, constants: Constants | None = None) -> tuple[np.ndarray, np.ndarray]:
        """One frame: (rgba (H, W, 4) float32 as the shader wrote it, 0 off the water; mask
        (H, W) bool, the water rectangle's coverage), row 0 at the top of the image."""
        x0, z0, x1, z1 = self.inputs.water_rect
        quad = [(x0, z0), (x1, z0), (x0, z1), (x1, z1)]
        frag_refl = self.stages["frag"][1]
        c = override_values(constants, frag_refl["overrides"]) if (
            self.overrides and constants is not None) else {}  # fmt: skip
        if self._mask is None:
            self._mask = self._draw(self._pipeline("mask", {}), quad)[..., 0] > 0.5
        mask = self._mask
        rgba = self._draw(self._pipeline("frag", c), quad)
        return np.where(mask[..., None], rgba, 0.0).astype(np.float32), mask.copy()

    def release(self) -> None:
        """Drop the pipelines and the device (idempotent)."""
        self._pipelines = {}
        device, self.device = getattr(self, "device", None), None
        if device is not None:
            device.destroy()

    def __enter__(self) -> "WgslRenderer":
        return self

    def __exit__(self, *exc) -> None:
        self.release()
