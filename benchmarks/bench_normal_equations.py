"""Where a fit's seconds go, and the fit with its normal equations formed on the device.

Run: ``.venv/bin/python benchmarks/bench_normal_equations.py [--sizes 256 512 1024]
[--json docs/results/normal-equations/bench.json]``. On the synthetic pool of the tests
(``tests/helpers/synthetic.py``), at size x size pixels, the target is the port at known
constants (``GLINT_TRUTH``) and each fit starts at ``GLINT_START``, fitting the seven constants
of ``FITTED`` with Levenberg-Marquardt and the calibration's settings. For each size, in one
process, side by side, with ``fit.normal_equations`` = ``solver`` (the solver receives the
residual and the Jacobian, 3 x water pixels rows) and ``device`` (Dr.Jit forms J^T J, J^T r and
r^T r; the solver receives k + 1 rows, ``study.fit.normal_equations``):

* one Jacobian evaluation (median of 3 after a warm-up): seconds; the kernels Dr.Jit launched,
  by kind, and how many of its JIT kernels were compiled, taken from its kernel cache or
  replayed from a frozen recording (``study._kernels``); the bytes the host receives (the
  arrays the evaluation reads back, from their sizes: on the CPU backend they are not copied,
  on a GPU they cross the bus);
* the whole fit, twice (the first includes the compile of the solver for its size): seconds,
  of them the seconds in the model's evaluations (the rest is the solver on the host), steps,
  Jacobian evaluations, and the largest relative difference of the constants between the two
  forms.

The JSON file is the source of ``docs/results/normal-equations/report.md``
(``scripts/docs_normal_equations.py``).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]

import drjit as dr  # noqa: E402
import numpy as np  # noqa: E402

import study._backend  # noqa: E402,F401
from bench_gpu import machine  # noqa: E402
from study._kernels import KernelLedger  # noqa: E402
from helpers.synthetic import FITTED, GLINT_START, GLINT_TRUTH, synthetic_inputs  # noqa: E402
from shaders_port import Constants  # noqa: E402
from shaders_port.variants import get_variant  # noqa: E402
from study.fit.calibrate import make_problem  # noqa: E402
from study.fit.model import ShaderModel, expand_parameters, get_value  # noqa: E402
from study.fit.solvers import CALIBRATION_SETTINGS, fit  # noqa: E402

SHADER = "water_refraction"
FORMS = ("solver", "device")


def _model(size: int) -> ShaderModel:
    inputs = synthetic_inputs(size, size)
    target = get_variant(SHADER).render(inputs, Constants(**GLINT_TRUTH)).numpy()["color"]
    return ShaderModel(SHADER, inputs, np.asarray(target, np.float32))


def _read_back_bytes(model: ShaderModel, names: list[str], start, form: str) -> int:
    k = len(names)
    if form == "device":
        return 8 * (k + 1) ** 2 + 8  # the Gram matrix and the count of non-finite pixels
    out, _ = model._shade_with_jacobian(start, names)
    images = 4 * (out.color.shape[0] * out.color.shape[1]) * (3 + 1 + len(out.diagnostics))
    return images + 4 * 3 * k * dr.width(out.lanes)


def evaluation(model: ShaderModel, names: list[str], start, form: str) -> dict:
    """One Jacobian evaluation in ``form``: seconds (median of 3), kernels, bytes read back."""

    def once():
        if form == "device":
            return model.normal_equations(start, names)
        return model.residual_and_jacobian(start, names)

    once()  # compile and record
    seconds = []
    for _ in range(3):
        t = time.perf_counter()
        once()
        seconds.append(time.perf_counter() - t)
    with KernelLedger() as ledger:
        once()
        kernels = ledger.take("evaluation")
    return {"seconds": statistics.median(seconds), "kernels": kernels,
            "read_back_bytes": _read_back_bytes(model, names, start, form)}  # fmt: skip


def fits(model: ShaderModel, names: list[str], start, form: str) -> list[dict]:
    """The fit twice in ``form`` (the first compiles the solver for its size)."""
    out = []
    for _ in range(2):
        problem = make_problem(model, start, names, progress=False, on_device=form == "device")
        t = time.perf_counter()
        res = fit(problem, None, solver="levenberg_marquardt", settings=CALIBRATION_SETTINGS)
        seconds = time.perf_counter() - t
        out.append({
            "seconds": seconds,
            "seconds_in_model": res.seconds_in_model,
            "steps": res.iterations,
            "jacobian_evaluations": res.n_jac_calls,
            "value_evaluations": res.n_value_calls,
            "loss": res.loss,
            "constants": {n: float(res.constants[n]) for n in names},
        })  # fmt: skip
    return out


def bench_size(size: int) -> dict:
    model = _model(size)
    names = expand_parameters(FITTED)
    start = Constants(**GLINT_START)
    row = {"size": size, "residuals": int(3 * model.mask.sum()), "k": len(names), "forms": {}}
    for form in FORMS:
        row["forms"][form] = {"evaluation": evaluation(model, names, start, form),
                              "fits": fits(model, names, start, form)}  # fmt: skip
    a = row["forms"]["solver"]["fits"][-1]["constants"]
    b = row["forms"]["device"]["fits"][-1]["constants"]
    row["max_rel_constant_difference"] = max(abs(b[n] / a[n] - 1) for n in names if a[n])
    row["truth"] = {n: get_value(Constants(**GLINT_TRUTH), n) for n in names}
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[256, 512, 1024])
    ap.add_argument("--json", type=Path, default=None)
    a = ap.parse_args()
    cpu = machine(gpu=False)
    rows = []
    for size in a.sizes:
        rows.append(bench_size(size))
        r = rows[-1]
        for form in FORMS:
            f = r["forms"][form]
            print(f"{size}x{size} {form}: evaluation {f['evaluation']['seconds']:.3f} s, "
                  f"read back {f['evaluation']['read_back_bytes'] / 1e6:.2f} MB, fit "
                  f"{f['fits'][0]['seconds']:.2f} s cold / {f['fits'][1]['seconds']:.2f} s "
                  f"warm", flush=True)  # fmt: skip
    result = {
        "command": "benchmarks/bench_normal_equations.py --sizes "
        + " ".join(map(str, a.sizes))
        + (f" --json {a.json}" if a.json else ""),
        "machine": f"{cpu['cpu']}, {cpu['cores']} cores, Dr.Jit LLVM backend",
        "load_average_after": list(os.getloadavg()),
        "shader": SHADER,
        "rows": rows,
    }
    if a.json:
        a.json.parent.mkdir(parents=True, exist_ok=True)
        tmp = a.json.with_suffix(".tmp")
        tmp.write_text(json.dumps(result, indent=1) + "\n")
        tmp.replace(a.json)
        print(f"wrote {a.json}")


if __name__ == "__main__":
    main()
