"""Run ``study preview`` on many experiments in one process (tests/test_fuzz_preview.py).

    python tests/helpers/preview_driver.py CASES.json OUT_DIR

``CASES.json`` is a list of ``[name, [KEY=VALUE, ...]]``; each case is the default experiment
at tiny sizes with those overrides. One JSON line per case goes to stdout as soon as it
ends: ``{"case", "status": "ok" | "error" | "crash", "seconds", "message"}``; a line
``{"start": name}`` is printed before each case, so a hang names its case. ``error`` is a
clear stop (ExperimentError, ValueError, BackendError: what the CLI reports as one line);
``crash`` is any other exception (a bug), with its traceback.
"""

from __future__ import annotations

import json
import sys
import time
import traceback
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

TINY = [
    "resolution=[16,16]",
    "fit.resolution=[16,16]",
    "reference.spp=4",
    "reference.water_mesh=24",
    "reference.texture_size=16",
    "reference.texture_spp=1",
    "waves.normal_map_size=8",
]


def main() -> int:
    import contextlib
    import io

    from study._backend import BackendError
    from study.commands import run_preview
    from study.config.experiment import ExperimentError

    cases = json.loads(Path(sys.argv[1]).read_text())
    out = Path(sys.argv[2])
    for name, sets in cases:
        print(json.dumps({"start": name}), flush=True)
        t0 = time.perf_counter()
        rec = {"case": name}
        try:
            with contextlib.redirect_stderr(io.StringIO()):
                s = run_preview(
                    ROOT / "experiments" / "default.toml", out / name, TINY + list(sets)
                )
            rec.update(status="ok", message=f"rmse {s['error']['rmse']}")
        except (ExperimentError, ValueError, BackendError, FileNotFoundError) as exc:
            rec.update(status="error", message=str(exc))
        except Exception:  # noqa: BLE001 - a crash is what the test looks for
            rec.update(status="crash", message=traceback.format_exc())
        rec["seconds"] = time.perf_counter() - t0
        print(json.dumps(rec), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
