"""Resolution as a choice the tool makes: presets for ``resolution`` / ``fit.resolution`` and the
rule of ``fit.resolution = "auto"`` (pure functions; no rendering)."""

from __future__ import annotations

import math

import pytest
from helpers import REPO

from study.config import experiment as experiment_module
from study.config.errors import ExperimentError
from study.config.experiment import load_experiment
from study.config.resolution import FIT_PIXELS, PRESETS, auto_fit_resolution

DEFAULT = REPO / "experiments" / "default.toml"


def _load(*sets: str):
    return load_experiment(DEFAULT, list(sets))


@pytest.mark.parametrize("name,size", [("720p", [1280, 720]), ("1080p", [1920, 1080]),
                                       ("1440p", [2560, 1440])])  # fmt: skip
def test_a_preset_is_its_width_and_height(name, size):
    exp = _load(f'resolution="{name}"', 'fit.resolution="auto"')
    assert exp.resolution == size
    same = _load(f"resolution={size}", 'fit.resolution="auto"')
    assert exp.scene_hash() == same.scene_hash() and exp.inputs_hash() == same.inputs_hash()


def test_fit_resolution_takes_a_preset_that_divides_resolution():
    assert _load('resolution="1440p"', 'fit.resolution="720p"').fit.resolution == [1280, 720]
    with pytest.raises(ExperimentError, match=r"fit.resolution \[1920, 1080\] must divide"):
        _load('fit.resolution="1080p"')  # resolution stays 256 x 256


@pytest.mark.parametrize("key", ["resolution", "fit.resolution"])
def test_an_unknown_preset_names_the_key_and_the_presets(key):
    with pytest.raises(ExperimentError, match=rf"^{key}: expected .* or a preset, got '4k'.*1440p"):
        _load(f'{key}="4k"')
    with pytest.raises(ExperimentError, match=r"resolution: expected .* or a preset, got 'auto'"):
        _load('resolution="auto"')  # auto is the fit's choice only


@pytest.mark.parametrize(
    "size,device,fit",
    [
        ([256, 256], "llvm", [128, 128]),  # the default experiment's fit, as before
        ([1920, 1080], "llvm", [160, 90]),
        ([1280, 720], "llvm", [160, 90]),
        ([2560, 1440], "llvm", [160, 90]),
        ([128, 128], "llvm", [128, 128]),
        ([256, 256], "cuda", [256, 256]),
        ([1920, 1080], "cuda", [1920, 1080]),  # full resolution up to 1080p
        ([1280, 720], "cuda", [1280, 720]),
        ([2560, 1440], "cuda", [1280, 720]),
    ],
)
def test_auto_fit_resolution(size, device, fit):
    assert auto_fit_resolution(size, device) == fit


@pytest.mark.parametrize("device", sorted(FIT_PIXELS))
def test_auto_is_the_largest_whole_division_within_the_budget(device):
    for w, h in [(320, 240), (640, 480), (1000, 1000), (96, 64), (3840, 2160), *PRESETS.values()]:
        fw, fh = auto_fit_resolution([w, h], device)
        f = w // fw
        assert w == f * fw and h == f * fh and fw * fh <= FIT_PIXELS[device]
        g = math.gcd(w, h)
        smaller = [d for d in range(1, f) if g % d == 0]
        assert all((w // d) * (h // d) > FIT_PIXELS[device] for d in smaller), (w, h, f)


def test_auto_without_a_common_factor_names_the_fix():
    with pytest.raises(ExperimentError, match=r'fit.resolution = "auto".*\[1366, 767\].*set fit'):
        auto_fit_resolution([1366, 767], "llvm")
    with pytest.raises(ValueError, match="device must be one of"):
        auto_fit_resolution([256, 256], "metal")


def test_auto_follows_the_device_of_the_run(monkeypatch):
    """The experiment's ``variant`` before a backend is chosen; then the run's
    (``Experiment.on_backend``, and the variant ``init_backend`` set when it already ran)."""
    monkeypatch.setattr(experiment_module, "active_variant", lambda: None)
    exp = _load('resolution="1080p"', 'fit.resolution="auto"')
    assert exp.fit.resolution == [160, 90] and exp.auto["fit.resolution"] == "auto"
    gpu = exp.on_backend("cuda_ad_rgb")
    assert gpu.fit.resolution == [1920, 1080] and gpu.resolution == [1920, 1080]
    assert gpu.on_backend("llvm_ad_rgb").fit.resolution == [160, 90]
    assert exp.on_backend("llvm_ad_rgb") is exp
    as_gpu = _load('resolution="1080p"', 'fit.resolution="auto"', 'variant="cuda_ad_rgb"')
    assert as_gpu.fit.resolution == [1920, 1080]
    monkeypatch.setattr(experiment_module, "active_variant", lambda: "cuda_ad_rgb")
    assert _load('resolution="1080p"', 'fit.resolution="auto"').fit.resolution == [1920, 1080]


def test_an_explicit_fit_resolution_is_kept_on_any_device():
    exp = _load('resolution="1080p"', "fit.resolution=[480, 270]")
    assert exp.on_backend("cuda_ad_rgb") is exp and exp.fit.resolution == [480, 270]
