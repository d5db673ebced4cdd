"""One switch, no code path written twice: ``study._backend.init_backend`` chooses the backend,
and every stage that runs Dr.Jit (the hand ports, the SPIR-V executor, the fit's models, their
Jacobians and residuals, Adam's variables, the GL check's port render) takes it from there
through ``shaders_port.pipeline.texture.backend_types``. A CUDA backend asked for on a machine
without CUDA is refused with the fix."""

from __future__ import annotations

import json

import drjit as dr
import numpy as np
import pytest
from helpers import REPO
from helpers.experiments import TINY, sets
from helpers.synthetic import synthetic_inputs

from shaders_port.pipeline import texture
from study._backend import BackendError, init_backend

NO_CUDA = not dr.has_backend(dr.JitBackend.CUDA)
needs_no_cuda = pytest.mark.skipif(not NO_CUDA, reason="this machine has a CUDA device")
EXPERIMENT = str(REPO / "experiments" / "default.toml")


@needs_no_cuda
def test_cuda_without_a_cuda_device_is_refused_naming_the_fix(tmp_path, capsys, mi):
    with pytest.raises(BackendError, match=r"no CUDA device.*--backend llvm_ad_rgb"):
        init_backend("cuda_ad_rgb")
    assert texture.resolve_backend(None) == "llvm"  # the refusal changed nothing
    from study.cli import main

    rc = main(["preview", EXPERIMENT, "--backend", "cuda_ad_rgb", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 2 and "no CUDA device" in err and "--backend llvm_ad_rgb" in err
    assert not (tmp_path / "o" / "preview.json").exists()
    with pytest.raises(RuntimeError, match=r"no CUDA device.*llvm_ad_rgb"):
        texture.backend_types("cuda")  # a library caller asking for CUDA explicitly


@pytest.fixture
def default_backend(monkeypatch):
    """Set the process's default backend for one test (restored after it)."""

    def set_to(name: str) -> None:
        monkeypatch.setattr(texture, "_DEFAULT_BACKEND", [name])

    return set_to


def _stages(inputs, ref):
    """Each Dr.Jit stage of a calibration, given no backend: {name: callable}."""
    from shaders_port import Constants
    from shaders_port.spirv.translated import Translated
    from shaders_port.variants import get_variant
    from study.fit.calibrate import make_problem
    from study.fit.model import ShaderModel

    variant = get_variant("water_refraction")
    c = Constants()
    return {
        "hand port": lambda: variant.render(inputs, c).numpy()["color"],
        "hand port Jacobian": lambda: variant.render_with_jacobian(inputs, c, ["bumptex_mult"])[1],
        "SPIR-V executor": lambda: Translated(variant).render(inputs, c).numpy()["color"],
        "model residual": lambda: ShaderModel("water_refraction", inputs, ref).residual(c),
        "Adam's variables": lambda: make_problem(
            ShaderModel("water_refraction", inputs, ref), c, ["bumptex_mult"], progress=False
        ).drjit_float(1.0),
    }


@needs_no_cuda
def test_every_stage_given_no_backend_takes_the_runs(default_backend, mi):
    """With the default set to CUDA on a machine without it, every stage refuses (none runs on
    a backend of its own); set to LLVM, every stage runs, as with ``backend="llvm"`` given."""
    inputs = synthetic_inputs(24, 16, tex=32)
    default_backend("llvm")
    from shaders_port import Constants
    from shaders_port.variants import get_variant

    ref = get_variant("water_refraction").render(inputs, Constants()).numpy()["color"] + 0.01
    default_backend("cuda")
    for name, stage in _stages(inputs, ref).items():
        with pytest.raises(RuntimeError, match="no CUDA device"):
            stage()
            pytest.fail(f"{name} ran without the run's backend")
    default_backend("llvm")
    ran = {name: stage() for name, stage in _stages(inputs, ref).items()}
    assert type(ran["Adam's variables"]).__module__ == "drjit.llvm.ad"
    explicit = get_variant("water_refraction").render(inputs, Constants(), backend="llvm")
    assert np.array_equal(ran["hand port"], explicit.numpy()["color"])


def test_calibrate_end_to_end_through_the_one_dispatch(tmp_path, monkeypatch, mi):
    """``study calibrate --backend llvm_ad_rgb`` on a tiny scene: reference, shader inputs, fit
    (residuals, Jacobians), export and GL check; every Dr.Jit backend asked for on the way
    (``backend_types``) resolves to the one the switch chose."""
    from study.cli import main

    seen = []
    resolve = texture.resolve_backend

    def spy(backend):
        seen.append(resolve(backend))
        return seen[-1]

    monkeypatch.setattr(texture, "resolve_backend", spy)
    out = tmp_path / "cal"
    args = ["calibrate", EXPERIMENT, "--backend", "llvm_ad_rgb", "--out", str(out)]
    rc = main(args + sets(TINY + ["fit.max_steps=2"]))
    assert rc == 0
    assert seen and set(seen) == {"llvm"}, set(seen)
    result = json.loads((out / "constants.json").read_text())
    assert result["backend"] == "llvm_ad_rgb"
    assert 0.0 < result["fit_error"]["flip"] < 1.0  # the fitted constants at the fit's pixels
    assert (out / "shaders").is_dir()
