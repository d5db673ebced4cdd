"""The backend check stops with a clear message before Dr.Jit can abort on an old libLLVM."""

import os
import subprocess
import sys

import pytest

from study._backend import MIN_LLVM_MAJOR, BackendError, ensure_llvm, find_libllvm, init_backend


def test_working_llvm_found():
    assert ensure_llvm()[0] >= MIN_LLVM_MAJOR


def _run_with(libpath: str) -> subprocess.CompletedProcess:
    code = (
        "from study._backend import init_backend\n"
        "init_backend('llvm_ad_rgb')\n"
        "import drjit as dr, drjit.llvm as l\n"
        "print(dr.maximum(l.Float(1, 2), 1.5))\n"
    )
    env = dict(os.environ, DRJIT_LIBLLVM_PATH=libpath)
    return subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120
    )


def test_old_llvm_is_refused_cleanly():
    old = [p for v, p in find_libllvm() if v < MIN_LLVM_MAJOR]
    if not old:
        pytest.skip("no libLLVM older than the minimum on this machine")
    r = _run_with(old[0])
    assert r.returncode == 1, r.stderr  # a Python exception, not an abort (134/136)
    assert "BackendError" in r.stderr and "apt-get install libllvm19" in r.stderr


def test_missing_llvm_is_refused_cleanly(tmp_path):
    r = _run_with(str(tmp_path / "libLLVM-99.so"))
    assert r.returncode == 1, r.stderr
    assert "could not load libLLVM" in r.stderr


def test_unknown_variant():
    with pytest.raises(BackendError, match="unknown variant 'vulkan'.*llvm_ad_rgb"):
        init_backend("vulkan")
