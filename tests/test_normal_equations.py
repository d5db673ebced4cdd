"""The fit's normal equations formed where the shader runs (``study.fit.normal_equations``,
``fit.normal_equations = "device"``): the same A, g and loss as the host forms from the residual
and its Jacobian, a compressed system with exactly those, the same fit, and refusals in one
line."""

from __future__ import annotations

import os

import numpy as np
import pytest
from helpers.experiments import small_experiment
from helpers.synthetic import FITTED, GLINT_START, GLINT_TRUTH, relative_errors, synthetic_inputs
from hypothesis import example, given, settings
from hypothesis import strategies as st

from shaders_port import Constants
from shaders_port.spirv.user_shader import UserShader
from shaders_port.variants import get_variant
from study.calibration.fitting import FitOptions
from study.config.experiment import ExperimentError
from study.fit.calibrate import make_problem
from study.fit.joint import JointModel
from study.fit.losses import transformed
from study.fit.model import ShaderModel, expand_parameters
from study.fit.normal_equations import RANK_RTOL, NormalEquations, from_residual
from study.fit.solvers import CALIBRATION_SETTINGS, fit
from study.fit.spirv_model import SpirvModel

NAMES = expand_parameters(FITTED)


def _target(inputs, s: int = 1) -> np.ndarray:
    """The port at the known truth on ``inputs``, box-averaged over s x s samples."""
    img = get_variant("water_refraction").render(inputs, Constants(**GLINT_TRUTH)).numpy()
    img = np.asarray(img["color"], np.float32)
    h, w = img.shape[0] // s, img.shape[1] // s
    return img.reshape(h, s, w, s, 3).mean(axis=(1, 3)).astype(np.float32)


def _assert_same(device: NormalEquations, host: NormalEquations, rtol: float) -> None:
    assert device.m == host.m and device.nonfinite == 0
    assert np.abs(device.A - host.A).max() <= rtol * np.abs(host.A).max()
    assert np.abs(device.g - host.g).max() <= rtol * np.abs(host.g).max()
    assert device.rr == pytest.approx(host.rr, rel=rtol)


@pytest.mark.parametrize("s", [1, 2])
def test_the_device_forms_the_normal_equations_of_the_residual(s):
    """A = J^T J, g = J^T r and r^T r formed from the lanes in Dr.Jit equal the host's from the
    model's residual and Jacobian (float32 images: agreement to 1e-6), with one sample a pixel
    and with the footprint's 2 x 2 samples folded."""
    inputs = synthetic_inputs(48 * s, 36 * s)
    model = ShaderModel("water_refraction", inputs, _target(inputs, s), supersample=s)
    start = Constants(**GLINT_START)
    host = from_residual(*model.residual_and_jacobian(start, NAMES))
    _assert_same(model.normal_equations(start, NAMES), host, 1e-6)


def test_a_users_shader_through_spirv_forms_them_too():
    """The SPIR-V executor's lanes (a user's file) go through the same hook."""
    src = (
        "#version 330 core\n// @study constant K 0.0 2.0\nconst float K = 1.5;\n"
        "// @study constant T 0.0 1.0\nconst float T = 0.5;\n"
        "in vec3 varyingVecWorldPosition;\nout vec4 color;\n"
        "void main() { color = vec4(T * fract(varyingVecWorldPosition) + K * K, 1.0); }\n"
    )
    inputs = synthetic_inputs(48, 36)
    rng = np.random.default_rng(1)
    model = SpirvModel(UserShader(src, "k.frag"), inputs, rng.random((36, 48, 3), np.float32))
    vals = {"K": 0.7, "T": 0.3}
    host = from_residual(*model.residual_and_jacobian(vals, ["K", "T"]))
    _assert_same(model.normal_equations(vals, ["K", "T"]), host, 1e-6)


def test_non_finite_pixels_on_the_device_are_an_error_naming_the_constants():
    src = (
        "#version 330 core\n// @study constant K 0.0 2.0\nconst float K = 1.5;\n"
        "in vec3 varyingVecWorldPosition;\nout vec4 color;\n"
        "void main() { color = vec4(fract(varyingVecWorldPosition) + sqrt(K - 1.2), 1.0); }\n"
    )
    inputs = synthetic_inputs(48, 36)
    model = SpirvModel(UserShader(src, "k.frag"), inputs, np.zeros((36, 48, 3), np.float32))
    assert model.normal_equations({"K": 1.5}, ["K"]).nonfinite == 0
    with pytest.raises(FloatingPointError) as err:
        model.normal_equations({"K": 1.0}, ["K"])
    msg = str(err.value)
    assert "non-finite water pixels at K=1.0" in msg and "narrow the range" in msg


@settings(max_examples=40, deadline=None)
@given(
    m=st.integers(2, 40),
    k=st.integers(1, 6),
    dead=st.integers(0, 2),
    seed=st.integers(0, 2**32 - 1),
)
# A of condition 4e7, 4e11 and 1e12: the rounding puts g^T A^+ g above r^T r
@example(m=4, k=4, dead=0, seed=1162471)
@example(m=4, k=5, dead=1, seed=358570766)
@example(m=6, k=6, dead=0, seed=1768824040)
def test_the_compressed_system_has_the_same_normal_equations_and_loss(m, k, dead, seed):
    """J~^T J~ = A, J~^T r~ = g and |r~|^2 = r^T r, also when columns of J are 0 (a constant
    no scored pixel reads) or J has fewer rows than columns. The loss exactly; g to 1e-8, or to
    the rounding an ill-conditioned A allows (eps * cond(A) of the eigenvalues kept: a
    computed g^T A^+ g above r^T r is the rounding of A^+, and the loss is kept exact)."""
    rng = np.random.default_rng(seed)
    J = rng.normal(size=(m, k)) * rng.uniform(0.01, 100, size=k)
    J[:, : min(dead, k - 1)] = 0.0
    r = rng.normal(size=m)
    ne = from_residual(r, J)
    rt, Jt = ne.compressed()
    assert rt.shape == (k + 1,) and Jt.shape == (k + 1, k)
    scale = np.abs(ne.A).max() + 1e-300
    assert np.abs(Jt.T @ Jt - ne.A).max() <= 1e-10 * scale
    w = np.linalg.eigvalsh(ne.A)
    kept = w[w > RANK_RTOL * w.max()]
    g_rtol = max(1e-8, 4 * np.finfo(np.float64).eps * kept.max() / kept.min())
    assert np.abs(Jt.T @ rt - ne.g).max() <= g_rtol * (np.abs(ne.g).max() + np.sqrt(scale))
    assert rt @ rt == pytest.approx(r @ r, rel=1e-10)


def test_joint_equations_are_those_of_the_stacked_residual():
    inputs = synthetic_inputs(48, 36)
    models = [ShaderModel("water_refraction", inputs, _target(inputs)) for _ in range(2)]
    joint = JointModel(models, ["a", "b"])
    start = Constants(**GLINT_START)
    host = from_residual(*joint.residual_and_jacobian(start, NAMES))
    _assert_same(joint.normal_equations(start, NAMES), host, 1e-6)


def test_the_fit_takes_the_same_steps_and_recovers_the_truth():
    """Levenberg-Marquardt on the compressed system takes the full residual's steps (same step
    count, constants within 1e-6) and recovers the known truth; the stall rule still counts the
    residuals the system stands for."""
    inputs = synthetic_inputs(64, 48)
    model = ShaderModel("water_refraction", inputs, _target(inputs))
    start = Constants(**GLINT_START)
    out = {}
    for on_device in (False, True):
        problem = make_problem(model, start, NAMES, progress=False, on_device=on_device)
        out[on_device] = fit(
            problem, None, solver="levenberg_marquardt", settings=CALIBRATION_SETTINGS
        )
        assert problem.jax_residual({n: p.default for n, p in problem.params.items()},
                                    NAMES).count == 3 * int(model.mask.sum())  # fmt: skip
    a, b = out[False], out[True]
    assert b.n_jac_calls == a.n_jac_calls and b.iterations == a.iterations
    for n in NAMES:
        assert b.constants[n] == pytest.approx(a.constants[n], rel=1e-6, abs=1e-9)
    fitted = Constants(**GLINT_START).replace(
        **{k: v for k, v in _constants_of(b.constants).items()}
    )
    assert max(relative_errors(fitted, GLINT_TRUTH, FITTED).values()) < 1e-3


def _constants_of(scalars: dict) -> dict:
    """{'water_color[1]': v, ...} -> Constants keyword values (colours as tuples)."""
    out: dict = {}
    base = Constants(**GLINT_START)
    for name, v in scalars.items():
        if "[" in name:
            key, i = name[:-1].split("[")
            comps = list(out.get(key, getattr(base, key)))
            comps[int(i)] = v
            out[key] = tuple(comps)
        else:
            out[name] = v
    return out


def test_a_loss_transformed_on_the_host_is_refused_in_one_line():
    exp = small_experiment(**{"fit.normal_equations": '"device"'})
    assert FitOptions.of(exp).normal_equations == "device"
    with pytest.raises(ExperimentError, match='fit.normal_equations = "solver"'):
        FitOptions.of(exp, loss="flip", normal_equations="device")
    inputs = synthetic_inputs(48, 36)
    model = transformed(ShaderModel("water_refraction", inputs, _target(inputs)), "log", 67.0)
    with pytest.raises(ValueError, match='needs fit.loss = "linear"'):
        make_problem(model, Constants(**GLINT_START), NAMES, progress=False, on_device=True)


def test_the_kernel_ledger_counts_each_stage_apart():
    """``study._kernels.KernelLedger``: what was launched between two takes is that stage's; a
    stage that launches nothing counts nothing; the history flag is restored."""
    import drjit as dr
    from drjit.llvm import Float64

    from study._kernels import KernelLedger

    was = dr.flag(dr.JitFlag.KernelHistory)
    with KernelLedger() as ledger:
        x = dr.arange(Float64, 4099)
        dr.eval(x * x + 0.5)
        first = ledger.take("compute")
        second = ledger.take("nothing")
        float(dr.sum(x)[0])
        third = ledger.take("read back")
    assert first["by_kind"].get("JIT", 0) >= 1 and first["launches"] >= 1
    assert second["launches"] == 0 and second["copies"] == 0
    assert third["copies"] >= 1 and third["copy_bytes"] >= 8
    assert set(ledger.stages) == {"compute", "nothing", "read back"}
    assert dr.flag(dr.JitFlag.KernelHistory) == was


def test_the_backend_keeps_jax_on_the_host_unless_told_otherwise(monkeypatch):
    """``init_backend`` sets JAX to the host where the user has not chosen (on a GPU machine a
    CUDA JAX would take the GPU's memory from Dr.Jit); a value the user set stays."""
    from study._backend import init_backend

    monkeypatch.delenv("JAX_PLATFORMS", raising=False)
    monkeypatch.setenv("XLA_PYTHON_CLIENT_PREALLOCATE", "true")
    init_backend("llvm_ad_rgb")
    assert os.environ["JAX_PLATFORMS"] == "cpu"
    assert os.environ["XLA_PYTHON_CLIENT_PREALLOCATE"] == "true"
