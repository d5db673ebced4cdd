"""What can be checked of the GPU benchmark without a GPU: ``benchmarks/gpu_session.sh`` parses
and plans its steps in order (``--dry-run``), its bundle asks for the pinned packages for the
device's Python, the committed CPU measurement carries the other side of its parity check, and
``benchmarks/bench_gpu.py``'s sizes, ratios, parity and tables (no rendering)."""

from __future__ import annotations

import importlib.util
import re
import subprocess
import tomllib

import pytest
from helpers import REPO

SCRIPT = REPO / "benchmarks" / "gpu_session.sh"
BENCH_JSON = REPO / "docs" / "results" / "gpu" / "bench.json"


def _bench():
    spec = importlib.util.spec_from_file_location("bench_gpu", REPO / "benchmarks" / "bench_gpu.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _dry(*args, tmp_path) -> str:
    env = {"PATH": "/usr/bin:/bin", "OUT": str(tmp_path / "out"), "HOME": str(tmp_path)}
    r = subprocess.run(["bash", str(SCRIPT), "--dry-run", *args], capture_output=True, text=True,
                       env=env, timeout=60)  # fmt: skip
    assert r.returncode == 0, r.stderr
    return r.stdout + r.stderr


def test_the_session_script_parses():
    r = subprocess.run(["bash", "-n", str(SCRIPT)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr


def test_the_dry_run_plans_parity_then_1080p_cold_and_warm_then_the_tradeoff(tmp_path):
    text = _dry(tmp_path=tmp_path)
    steps = [text.index(s) for s in ("step 1: parity at 256x256", "step 2: 1920x1080",
                                     "step 3: the tradeoff")]  # fmt: skip
    assert steps == sorted(steps)
    assert "--passes cold warm" in text and "--parity-with" in text
    assert "runs only if 300 s" in text and "--backend cuda_ad_rgb" in text
    assert not (tmp_path / "out").exists()  # nothing ran


def test_the_tradeoff_alone_runs_step_3_with_workers_sharing_the_device(tmp_path):
    text = _dry("--tradeoff", tmp_path=tmp_path)
    assert "step 3: the tradeoff" in text and "step 1" not in text and "step 2" not in text
    assert "--workers 4" in text and "--backend cuda_ad_rgb" in text
    assert 'fit.normal_equations="device"' in text


def test_the_bundle_downloads_the_pinned_packages_for_the_devices_python(tmp_path):
    text = _dry("--build-bundle", tmp_path=tmp_path)
    assert "--python-version 3.12" in text and "--only-binary=:all:" in text
    pins = dict(
        d.split("==")
        for d in tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["dependencies"]
    )
    asked = dict(re.findall(r"\s([A-Za-z][\w.-]*)==([\w.]+)", text.split("pip download", 1)[1]))
    assert asked and all(pins[k] == v for k, v in asked.items() if k in pins), asked
    assert {"mitsuba", "drjit", "OpenEXR", "moderngl"} <= set(asked)


def test_the_committed_cpu_measurement_is_the_other_side_of_the_parity():
    bench = _bench()
    text = SCRIPT.read_text()
    sets = re.search(r"BENCH_SETS=\((.*)\)", text).group(1)
    overrides = re.findall(r"--set '([^']*)'", sets)
    found = bench.cpu_results_from(str(BENCH_JSON), overrides)
    assert any(r["size"] == [256, 256] and r["params"] for r in found)


def test_sizes_take_presets_and_refuse_the_rest():
    bench = _bench()
    assert bench.parse_size("1080p") == [1920, 1080] and bench.parse_size("256x256") == [256, 256]
    with pytest.raises(SystemExit, match="give WxH"):
        bench.parse_size("huge")


def _result(variant, fitted, rel_se, seconds, size=(256, 256)):
    params = {"bumptex_mult": {"fitted": fitted, "rel_se": rel_se, "status": "fitted"},
              "frozen_one": {"fitted": None, "rel_se": None, "status": "frozen"}}  # fmt: skip
    p = {"seconds": seconds, "total": sum(seconds.values()), "memory": {"drjit_peak": 2**20}}
    fit = {"fit_resolution": [128, 128], "spp": 128, "noise": 0.01, "water_pixels": 9000}
    return {"size": list(size), "variant": variant, "passes": {"cold": p}, "params": params, **fit}


def test_parity_is_the_difference_in_combined_standard_errors():
    bench = _bench()
    cpu = _result("llvm_ad_rgb", 1.0, 0.03, {"reference": 30.0})
    gpu = _result("cuda_ad_rgb", 1.05, 0.04, {"reference": 1.5})
    z = bench.parity([cpu, gpu])["256x256"]["bumptex_mult"]["z"]
    assert z == pytest.approx(0.05 / (0.03**2 + 0.042**2) ** 0.5)
    assert "frozen_one" not in bench.parity([cpu, gpu])["256x256"]


def test_the_tables_give_each_backend_and_their_ratio():
    bench = _bench()
    from docs_gpu import gpu_bench_page

    inv = {
        "title": "t", "command": "benchmarks/bench_gpu.py", "overrides": [],
        "stages": ["startup", "setup", "reference"], "parity": None,
        "machine": {"cpu": "c", "cores": 2, "load_before": [1, 1, 1], "load_after": [2, 2, 2]},
        "results": [_result("llvm_ad_rgb", 1.0, 0.03, {"reference": 30.0}),
                    _result("cuda_ad_rgb", 1.0, 0.03, {"reference": 1.5}),
                    {"size": [1920, 1080], "variant": "cuda_ad_rgb", "error": "over 9 s"}],
    }  # fmt: skip
    page = gpu_bench_page({"runs": [inv]})
    assert "| reference (path traced) | 30.0 | 1.5 | 20.0x |" in page
    assert "1920x1080 on cuda_ad_rgb: not measured (over 9 s)" in page
    assert "\n".join(bench.invocation_lines(inv)) in page  # the benchmark prints the page's
