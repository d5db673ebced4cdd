"""The generated parts of the documentation, from the result files committed beside them.

Every table of results in ``docs/`` is written by this script, never by hand:

* ``docs/results/<study>/report.md`` of the tradeoff-family studies (``tradeoff``, ``variants``,
  ``variants/shipped``, ``baselines``): from the study's ``summary.json`` where it is committed,
  else from its ``tradeoff.parquet`` (fronts, recommendations and findings recomputed by
  ``study.studies.tradeoff.analyse``; the run-time sections -- exported shaders, side-by-side
  images -- exist only in a run's own summary);
* ``docs/results/failures/report.md``: from its ``failures.parquet`` (one row per scene and
  failure class) and ``summary.json`` (the command that ran it);
* ``docs/results/stability/<phase>/stability.md``: from the phase's ``summary.json``;
* ``docs/experiment-keys.md``: the experiment file's key table, from the schema.

Re-running a study into ``docs/results/<study>`` and then this script refreshes the pages::

    .venv/bin/python scripts/build_docs.py           # write the pages
    .venv/bin/python scripts/build_docs.py --check   # exit 1 if a committed page differs

``tests/test_docs.py`` runs the check, so a number in the docs cannot go stale by hand.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
DOCS = REPO / "docs"
RESULTS = DOCS / "results"
TRADEOFF_FAMILY = ("tradeoff", "variants", "variants/shipped", "baselines")
STABILITY_PHASES = ("stability/multistart", "stability/noise")
DEFAULT_TOLERANCE = 0.02

KEYS_HEADER = """# Experiment keys

An experiment file (TOML) describes one scene, how its reference is rendered and what is fitted.
Any key can be overridden on the command line with `--set key=value` (dotted name, TOML value).
Unknown keys, wrong types, out-of-range values and impossible combinations are refused with a
message naming the key. World units, `+y` up, the water plane at `y = 0`, linear RGB.

This table is generated from the schema in `study/scene/experiment.py`
(`scripts/build_docs.py`); `experiments/README.md` describes the shipped experiment files.

"""


def _tradeoff_summary(folder: Path) -> dict:
    """The study's summary: its committed ``summary.json``, else recomputed from its table."""
    from study.studies.tradeoff import analyse
    from study.sweep import read_table

    summary_file = folder / "summary.json"
    if summary_file.is_file():
        return json.loads(summary_file.read_text())
    rows = read_table(folder / "tradeoff.parquet")
    if not rows:
        raise FileNotFoundError(f"{folder}: neither summary.json nor a non-empty tradeoff.parquet")
    names = list(dict.fromkeys(r["job.experiment"] for r in rows if r.get("job.experiment")))
    summary, _ = analyse(rows, names, DEFAULT_TOLERANCE)
    return summary


def generated() -> dict[Path, str]:
    """Every generated page: path -> its Markdown."""
    from study.report.stability import stability_report_text
    from study.report.tradeoff import tradeoff_report_text
    from study.scene.experiment import schema_markdown

    pages = {DOCS / "experiment-keys.md": KEYS_HEADER + schema_markdown()}
    for study in TRADEOFF_FAMILY:
        folder = RESULTS / study
        pages[folder / "report.md"] = tradeoff_report_text(_tradeoff_summary(folder))
    pages[RESULTS / "failures" / "report.md"] = _failures_page(RESULTS / "failures")
    for phase in STABILITY_PHASES:
        folder = RESULTS / phase
        pages[folder / "stability.md"] = stability_report_text(_json(folder / "summary.json"))
    return pages


def _json(path: Path) -> dict:
    if not path.is_file():
        raise FileNotFoundError(f"{path} is missing: re-run the study into {path.parent}")
    return json.loads(path.read_text())


def _failures_page(folder: Path) -> str:
    """The failure catalogue's report from its table and the command that ran it."""
    from study.report.failures import failures_report_text, scenes_of
    from study.studies.failures import CLASSES
    from study.sweep import read_table

    command = _json(folder / "summary.json")["command"]
    rows = read_table(folder / "failures.parquet")
    return failures_report_text(scenes_of(rows), list(CLASSES), command)


def stale(pages: dict[Path, str]) -> list[Path]:
    """The pages whose committed text differs from ``pages``."""
    return [p for p, text in pages.items() if not p.is_file() or p.read_text() != text]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--check", action="store_true", help="compare, write nothing; exit 1 if stale")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(REPO))
    from study._io import write_text_atomic

    pages = generated()
    bad = stale(pages)
    if args.check:
        for p in bad:
            print(f"stale: {p.relative_to(REPO)} (run scripts/build_docs.py)", file=sys.stderr)
        return 1 if bad else 0
    for p in bad:
        write_text_atomic(p, pages[p])
        print(f"wrote {p.relative_to(REPO)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
