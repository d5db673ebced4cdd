"""Instructions of the SPIR-V executor beyond the study's shaders, each against Mesa llvmpipe:
screen-space derivatives over pixel quads (with the water's helper pixels), mipmapped texture
lookups (implicit level of detail, bias, Lod, Grad, offsets, Proj, texelFetch, textureSize),
``discard``, early returns, ``switch``, uniform blocks and structs, arrays indexed per pixel;
derivatives with respect to constants against central differences.

Two frames: the study's water frame (``spirv.translated.render`` against ``GLRenderer``
with the study's vertex shader), and a full-screen frame whose only input is ``gl_FragCoord``
(:func:`_executed` against :func:`_gl_full`), where a test binds its own textures and blocks.
"""

from __future__ import annotations


import drjit as dr
import drjit.llvm.ad as m
import numpy as np
import pytest

from helpers.synthetic import synthetic_inputs
from shaders_port.pipeline.texture import LINEAR, NEAREST, REPEAT, Texture2D, box_mip_chain
from shaders_port.spirv import translated as spirv_port
from shaders_port.spirv.execute import Executor
from shaders_port.spirv.loops import UnsupportedInstruction
from shaders_port.spirv.module import Module, compile_fragment
from shaders_port.spirv.quads import QUADS_KEY, quads_of_pixels
from shaders_port.spirv.user_shader import UserShader

W, H = 16, 12  # the full-screen frame (even: every quad whole)
_VERT = "#version 330 core\nin vec2 pos;\nvoid main() { gl_Position = vec4(pos, 0.0, 1.0); }\n"


@pytest.fixture(scope="module")
def water():
    return synthetic_inputs(width=48, height=36)


def _moderngl():
    mgl = pytest.importorskip("moderngl")
    try:
        return mgl, mgl.create_context(standalone=True, backend="egl", require=330)
    except Exception as exc:  # no headless OpenGL here
        pytest.skip(f"no headless OpenGL: {exc}")


def _gl_full(frag: str, textures=(), blocks=(), uniforms=()) -> np.ndarray:
    """``frag`` drawn over the W x H frame on llvmpipe: (H, W, 4), row 0 = window y 0.
    ``textures``: (name, levels, min filter, mag filter); ``blocks``: (name, std140 bytes);
    ``uniforms``: (name, value)."""
    mgl, ctx = _moderngl()
    try:
        prog = ctx.program(vertex_shader=_VERT, fragment_shader=frag)
        pts = np.array([-1, -1, 1, -1, -1, 1, 1, -1, 1, 1, -1, 1], np.float32)
        vao = ctx.vertex_array(prog, [(ctx.buffer(pts.tobytes()), "2f", "pos")])
        for unit, (name, levels, fmin, fmag) in enumerate(textures):
            h, w, c = levels[0].shape
            tex = ctx.texture((w, h), c, levels[0].tobytes(), dtype="f4")
            if len(levels) > 1:
                tex.build_mipmaps()
                for k, lv in enumerate(levels[1:], 1):
                    tex.write(np.ascontiguousarray(lv).tobytes(), level=k)
            tex.filter = (getattr(mgl, fmin), getattr(mgl, fmag))
            tex.repeat_x = tex.repeat_y = True
            tex.use(unit)
            prog[name].value = unit
        for k, (name, data) in enumerate(blocks):
            ctx.buffer(data).bind_to_uniform_block(k)
            prog[name].binding = k
        for name, value in uniforms:
            prog[name].value = value
        rb = ctx.renderbuffer((W, H), 4, dtype="f4")
        fbo = ctx.framebuffer([rb])
        fbo.use()
        fbo.clear(0.0, 0.0, 0.0, 0.0)
        vao.render(mgl.TRIANGLES)
        return np.frombuffer(fbo.read(components=4, dtype="f4"), np.float32).reshape(H, W, 4)
    finally:
        ctx.release()


def _executed(frag: str, bindings: dict | None = None, label="full.frag", grad=None):
    """``frag`` executed over the W x H frame: (H, W, 4) (row 0 = window y 0) and None;
    ``grad``: a constant's name whose forward derivative is returned too."""
    x, y = np.meshgrid(np.arange(W), np.arange(H))
    x, y = x.ravel(), y.ravel()
    b = {
        "gl_FragCoord": [m.Float(x + 0.5), m.Float(y + 0.5), 0.5, 1.0],
        QUADS_KEY: quads_of_pixels(m, x, y, len(x)),
        **(bindings or {}),
    }
    mod = Module(compile_fragment(frag, label), label=label)
    if grad is not None:
        dr.enable_grad(b[grad])
    ex = Executor(mod, m, b, differentiate=grad is not None)
    try:
        (out,) = [v for v in ex.run().values() if v is not None]
    finally:
        ex.release()  # no Dr.Jit value left for the garbage collector to free in a recording
    out = [m.Float(c) if isinstance(c, dr.ArrayBase) else m.Float(np.full(W * H, c)) for c in out]
    img = np.stack([c.numpy() for c in out], -1).reshape(H, W, 4)
    if grad is None:
        return img, None
    dr.forward(b[grad])
    J = np.stack([dr.grad(c).numpy() for c in out], -1).reshape(H, W, 4)
    dr.disable_grad(b[grad])
    return img, J


def _water_pair(inputs, src: str, values=None):
    """The user shader ``src`` on the water frame: executor output dict and GL rgba, mask."""
    from shaders_port.gl.renderer import run_glsl

    _moderngl()[1].release()
    spec = spirv_port.ShaderSpec(src, "user.frag")
    out = spirv_port.render(inputs, None, spec=spec).numpy()
    rgba, mask = run_glsl("water_refraction", inputs, source=src)
    assert np.array_equal(out["mask"] > 0, mask)
    return out, rgba, mask


# ---- derivatives ----------------------------------------------------------------------------

_DERIV = """#version 450 core
in vec3 varyingVecWorldPosition;
in vec3 varyingVecEye;
out vec4 fragColor;
uniform float WAVE = 3.0;
void main(void)
{
    vec3 p = varyingVecWorldPosition;
    float v = sin(p.x * WAVE) + p.z * p.x * 4.0;
    vec3 e = normalize(varyingVecEye);
    if (p.x > 0.0) {
        v = v * 2.0;  // a derivative inside a selection: both sides run on every lane
    }
    fragColor = vec4(dFdx(v) * 10.0 + dFdxCoarse(e.x), dFdy(v) * 10.0 - dFdyFine(e.z),
                     fwidth(v) + fwidthCoarse(e.y) + dFdxFine(p.z) + dFdyCoarse(p.x), 1.0);
}
"""


def test_derivatives_match_llvmpipe(water):
    """Every derivative form is llvmpipe's fine difference over the quad, helpers included
    (the water's edge pixels take differences with helper pixels outside it)."""
    out, rgba, mask = _water_pair(water, _DERIV)
    d = np.abs(out["color"] - rgba[..., :3])[mask]
    assert mask.sum() > 300
    assert np.abs(out["color"][mask]).max() > 0.05
    assert d.max() <= 1e-4, d.max()


def test_llvmpipe_derivatives_are_fine_in_every_form():
    """The measured rule :mod:`spirv.quads` follows: on llvmpipe dFdxCoarse equals dFdxFine
    (each row its own difference), and quads sit at even window coordinates."""
    frag = """#version 450 core
out vec4 c;
void main() { float x = gl_FragCoord.x, y = gl_FragCoord.y; float v = 10.0*x*x + y*y + 100.0*x*y;
    c = vec4(dFdxCoarse(v), dFdyCoarse(v), dFdx(v), dFdy(v)); }
"""
    gl = _gl_full(frag)
    mine, _ = _executed(frag)
    assert np.array_equal(gl, mine)
    assert gl[0, 0, 0] != gl[1, 0, 0]  # rows of one quad differ: the fine difference


def test_derivative_jacobian_matches_central_differences(water):
    shader = UserShader(_DERIV, "deriv.frag", {"constants": {"WAVE": [1.0, 6.0]}})
    base = shader.render(water).numpy()
    out, J = shader.render_with_jacobian(water, None, ["WAVE"])
    assert np.array_equal(out.numpy()["color"], base["color"])
    h = 1e-2
    p = shader.render(water, {"WAVE": 3.0 + h}).numpy()["color"]
    q = shader.render(water, {"WAVE": 3.0 - h}).numpy()["color"]
    fd = (p - q) / (2 * h)
    mask = base["mask"] > 0
    assert np.abs(fd[mask]).max() > 0.1
    err = np.abs(J[..., 0] - fd)[mask]
    assert err.max() <= 1e-3 * np.abs(fd[mask]).max() + 2e-3, err.max()


def test_derivative_in_a_lane_dependent_loop_is_refused(water):
    src = _DERIV.replace(
        "    fragColor = vec4(",
        "    float s = 0.0;\n    for (float t = 0.0; t < v; t += 1.0) { s += dFdx(t); }\n"
        "    fragColor = vec4(s + ",
    )
    spec = spirv_port.ShaderSpec(src, "loopderiv.frag")
    with pytest.raises(UnsupportedInstruction, match=r"OpDPdx.*loop.*loopderiv\.frag:15"):
        spirv_port.render(water, None, spec=spec)


# ---- mipmaps ---------------------------------------------------------------------------------


def _levels(seed=0, n=32, c=3) -> list:
    """A texture with distinct levels: level k holds noise plus k (each level recognisable)."""
    rng = np.random.default_rng(seed)
    chain = box_mip_chain(rng.random((n, n, c)).astype(np.float32))
    return [(lv + np.float32(k)).astype(np.float32) for k, lv in enumerate(chain)]


def _texture(levels, filt, mipmap) -> Texture2D:
    t = Texture2D.from_numpy(m, levels[0], filt, REPEAT)
    lv = tuple((m.Float(a.ravel()), a.shape[1], a.shape[0]) for a in levels[1:])
    return Texture2D(t.data, t.width, t.height, t.channels, filt, REPEAT, lv, mipmap)


_MIP = """#version 450 core
uniform sampler2D T;
uniform float SCALE = 1.0;
out vec4 c;
void main() {
    vec2 p = gl_FragCoord.xy;
    vec2 uv = SCALE * vec2(p.x * 0.11 + p.y * 0.031, p.y * 0.17 * (1.0 + p.x * 0.1))
              / (1.0 + 0.05 * p.y);
    c = vec4(%s);
}
"""
LOOKUPS = {
    "implicit": "texture(T, uv).rgb, 1.0",
    "bias": "texture(T, uv, -0.6).rgb, 1.0",
    "lod": "textureLod(T, uv, 1.0 + 0.13 * p.x).rgb, 1.0",
    "grad": "textureGrad(T, uv, vec2(0.02 * p.x, 0.01), vec2(0.0, 0.03 * p.y)).rgb, 1.0",
    "offset": "textureOffset(T, uv, ivec2(2, -1)).rgb, 1.0",
    "lod_offset": "textureLodOffset(T, uv, 0.4 + 0.23 * p.x, ivec2(-3, 1)).rgb, 1.0",
    "proj": "textureProj(T, vec3(uv * 2.0, 2.0 + 0.1 * p.y)).rgb, 1.0",
    "fetch": "texelFetch(T, ivec2(p) / 2, 1).rgb, float(textureSize(T, 2).x)",
    "size": "vec2(textureSize(T, 0)), vec2(textureSize(T, 3)) + float(textureQueryLevels(T))",
}
FILTERS = {  # GL min filter -> (filter within a level, between levels)
    "LINEAR_MIPMAP_LINEAR": (LINEAR, LINEAR),
    "NEAREST_MIPMAP_NEAREST": (NEAREST, NEAREST),
    "LINEAR_MIPMAP_NEAREST": (LINEAR, NEAREST),
}


@pytest.mark.parametrize("lookup", sorted(LOOKUPS))
@pytest.mark.parametrize("fmin", sorted(FILTERS))
def test_mipmapped_lookups_match_llvmpipe(lookup, fmin):
    levels = _levels()
    filt, mip = FILTERS[fmin]
    frag = _MIP % LOOKUPS[lookup]
    fmag = "LINEAR" if filt == LINEAR else "NEAREST"
    gl = _gl_full(frag, [("T", levels, fmin, fmag)])
    mine, _ = _executed(frag, {"T": _texture(levels, filt, mip), "SCALE": 1.0})
    lvl = np.floor(gl[..., :3])
    assert len(np.unique(lvl)) >= (1 if lookup in ("size", "fetch") else 2)  # several levels
    assert np.abs(mine - gl).max() <= 2e-5, np.abs(mine - gl).max()


def test_box_mip_chain_equals_gl_generated_mipmaps():
    mgl, ctx = _moderngl()
    try:
        a = np.random.default_rng(3).random((32, 16, 3)).astype(np.float32)
        tex = ctx.texture((16, 32), 3, a.tobytes(), dtype="f4")
        tex.build_mipmaps()
        chain = box_mip_chain(a)
        for k, lv in enumerate(chain):
            got = np.frombuffer(tex.read(level=k), np.float32).reshape(lv.shape)
            assert np.abs(got - lv).max() <= 1e-6, k
    finally:
        ctx.release()


def test_mipmapped_lookup_derivative_matches_central_differences():
    """d colour / d SCALE through the implicit level of detail (trilinear weights) and the
    bilinear weights."""
    levels = _levels(c=3)
    tex = _texture(levels, LINEAR, LINEAR)
    frag = _MIP % LOOKUPS["implicit"]
    s0, h = 1.0, 1e-3
    _, J = _executed(frag, {"T": tex, "SCALE": m.Float(s0)}, grad="SCALE")
    p, _ = _executed(frag, {"T": tex, "SCALE": s0 + h})
    q, _ = _executed(frag, {"T": tex, "SCALE": s0 - h})
    fd = (p - q) / (2 * h)
    fp = (p - _executed(frag, {"T": tex, "SCALE": s0})[0]) / h
    smooth = np.abs(fp - fd) <= 0.05 * np.abs(fd) + 1e-2  # no texel or level boundary crossed
    assert smooth.mean() >= 0.8 and np.abs(fd[smooth]).max() > 1.0
    err = np.abs(J - fd)[smooth]
    assert err.max() <= 2e-2 * np.abs(fd[smooth]).max(), err.max()


def test_study_textures_are_not_mipmapped(water):
    """The study's samplers have no mip chain: lookups are unchanged by it (the executor's
    images equal the ports', tests/test_spirv_exec.py)."""
    import drjit.llvm.ad as mm

    from shaders_port.pipeline.raster import prepare

    P = prepare(water, mm)
    assert all(not t.levels for t in (P.refractionTexture, P.normalMap, P.worldYComponent))


# ---- discard, returns, switch, blocks, arrays ---------------------------------------------

_DISCARD = """#version 450 core
in vec3 varyingVecWorldPosition;
out vec4 fragColor;
float shade(float x) {
    if (x < -0.5) return 0.25;     // an early return from a function
    return x * 0.5;
}
void main(void)
{
    vec3 p = varyingVecWorldPosition;
    fragColor = vec4(0.2, 0.3, 0.4, 1.0);
    if (p.z > 0.6) return;         // an early return from main
    if (sin(p.x * 9.0) > 0.7) discard;
    for (int i = 0; i < 8; i++) {
        if (float(i) * 0.1 > p.z + 0.7) discard;   // a discard inside a loop
    }
    fragColor = vec4(shade(p.x), fract(p.z * 3.0), 0.1, 1.0);
}
"""


def test_discard_and_returns_match_llvmpipe(water):
    out, rgba, mask = _water_pair(water, _DISCARD)
    gl_discarded = mask & (rgba[..., 3] == 0.0)
    assert 20 < gl_discarded.sum() < 0.8 * mask.sum()
    assert np.array_equal(out["discarded"] > 0, gl_discarded)
    # fract(3 z) of varyings rounded differently from GL's interpolation (a few ulps of z)
    assert np.abs(out["color"] - rgba[..., :3])[mask].max() <= 1e-5


def test_discarded_pixels_leave_the_scored_mask(water):
    from study.fit.model import Diagnostics

    out = spirv_port.render(water, None, spec=spirv_port.ShaderSpec(_DISCARD, "d.frag")).numpy()
    diag = Diagnostics({k: v for k, v in out.items() if k not in ("color", "mask")})
    mask = out["mask"] > 0
    assert diag.summary(mask)["discarded_pixels"] == int((out["discarded"] > 0).sum()) > 0


_FLOW = """#version 450 core
struct Light { vec3 pos; vec3 color; };
layout(std140) uniform Params { float gain; vec3 tint; int mode; };
uniform Light lights[2];
out vec4 c;
const float WEIGHTS[4] = float[](0.1, 0.4, 0.7, 1.0);
void main() {
    ivec2 q = ivec2(gl_FragCoord.xy);
    float acc[4] = float[](0.0, 0.0, 0.0, 0.0);
    acc[(q.x + q.y) % 4] = 1.0;                   // a store at an index per pixel
    float w = WEIGHTS[q.x % 4] + acc[q.y % 4];    // loads at indices per pixel
    Light l = lights[q.y % 2];
    c = vec4(0.05, 0.1, 0.15, 1.0);               // what an early return leaves
    vec3 col;
    switch ((q.x % 5) - 2 + mode) {
        case -2: col = l.color; break;
        case -1: col = vec3(0.5);                 // falls through
        case 0: col = tint * 0.5 + l.pos.x; break;
        case 3: return;
        default: col = vec3(gain);
    }
    c = vec4(col * w, 1.0);
}
"""


def test_control_flow_blocks_and_arrays_match_llvmpipe():
    params = np.zeros(8, np.float32)  # std140: gain at 0, tint at 16, mode at 28
    params[0], params[4:7] = 1.5, (0.2, 0.4, 0.6)
    params = params.tobytes()[:28] + np.int32(1).tobytes()
    lights = {"lights[0].pos": (0.1, 0.2, 0.3), "lights[0].color": (0.9, 0.8, 0.7),
              "lights[1].pos": (0.5, 0.6, 0.7), "lights[1].color": (0.3, 0.2, 0.1)}  # fmt: skip
    gl = _gl_full(_FLOW, blocks=[("Params", params)], uniforms=list(lights.items()))
    b = {"gain": 1.5, "tint": [0.2, 0.4, 0.6], "mode": 1}
    b.update({k: list(v) for k, v in lights.items()})
    mine, _ = _executed(_FLOW, b)
    assert len(np.unique(gl[..., 0])) >= 5
    assert np.abs(mine - gl).max() <= 1e-6


def test_unbound_block_member_is_named():
    from shaders_port.spirv.execute import UnboundVariable

    lights = {f"lights[{i}].{f}": [0.0] * 3 for i in range(2) for f in ("pos", "color")}
    with pytest.raises(UnboundVariable, match=r"'tint'.*full\.frag:\d+"):
        _executed(_FLOW, {"gain": 1.5, "mode": 1, **lights})


def test_unsupported_instruction_is_still_named(water):
    src = _DERIV.replace("fragColor = vec4(", "fragColor = textureGather(S, p.xz) + vec4(")
    src = src.replace("out vec4 fragColor;", "out vec4 fragColor;\nuniform sampler2D S;")
    spec = spirv_port.ShaderSpec(src, "gather.frag", bindings=(("S", "normalMap"),))
    with pytest.raises(UnsupportedInstruction, match=r"OpImageGather.*gather\.frag:\d+"):
        spirv_port.render(water, None, spec=spec)


def test_frames_with_and_without_quads_are_kept_apart(water):
    """A shader without derivatives and one with them, reading the same inputs, on one
    frame: each gets its own lanes (the bindings cache tells them apart)."""
    plain = _DERIV.replace("dFdx(v)", "v").replace("dFdy(v)", "v").replace("fwidth(v)", "v")
    for name in ("dFdxCoarse(e.x)", "dFdyFine(e.z)", "fwidthCoarse(e.y)", "dFdxFine(p.z)"):
        plain = plain.replace(name, "0.0")
    plain = plain.replace("dFdyCoarse(p.x)", "0.0")
    a = spirv_port.render(water, None, spec=spirv_port.ShaderSpec(plain, "plain.frag"))
    b = spirv_port.render(water, None, spec=spirv_port.ShaderSpec(_DERIV, "deriv.frag"))
    mask = a.numpy()["mask"] > 0
    assert not np.array_equal(a.numpy()["color"][mask], b.numpy()["color"][mask])


def test_helper_pixels_of_a_z_up_shader_are_in_its_frame(water, tmp_path):
    # with `// @study up z` the world-space varyings are (x, -z, y) on the helper lanes too:
    # fwidth of each component equals the Y-up shader's of the component it came from, on
    # the water's edge pixels as inside (helpers left in the Y-up frame gave the
    # edge pixels derivatives wrong by up to 4.5 here)
    body = (
        "// @study constant GAIN 0.0 2.0\nin vec3 varyingVecWorldPosition;\n"
        "out vec4 fragColor;\nconst float GAIN = 1.0;\nvoid main() {\n"
        "    vec3 p = varyingVecWorldPosition;\n"
        "    fragColor = vec4(GAIN * vec3(fwidth(p.x), fwidth(p.%s), fwidth(p.%s)), 1.0);\n}\n"
    )
    (tmp_path / "y.frag").write_text("#version 330 core\n" + body % ("y", "z"))
    (tmp_path / "z.frag").write_text("#version 330 core\n// @study up z\n" + body % ("z", "y"))
    y_up = UserShader.from_file(tmp_path / "y.frag").render(water).numpy()
    z_up = UserShader.from_file(tmp_path / "z.frag").render(water).numpy()
    mask = y_up["mask"] > 0.5
    assert np.array_equal(mask, z_up["mask"] > 0.5)
    assert y_up["color"][mask][:, 2].min() > 0  # the derivatives are not all zero
    assert np.abs(y_up["color"] - z_up["color"]).max(-1)[mask].max() <= 1e-6
