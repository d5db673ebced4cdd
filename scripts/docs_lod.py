"""The docs' page of the level-of-detail policies on seven scenes (``docs/results/lod/report.md``),
generated from committed tradeoff summaries:

* the default scene: ``docs/results/tradeoff/summary.json`` (``study tradeoff
  experiments/default.toml``);
* ``docs/results/lod/<scene>/summary.json``: ``study tradeoff experiments/<scene>.toml --out
  docs/results/lod/<scene>`` for deep_steps, grazing and calm, and for view k of
  ``experiments/views.toml`` the same with ``--set camera.position=... --set camera.target=...
  --set 'camera.views=[]' --set 'name="views-view<k>"'`` (the view's camera); only the
  summary and the drawn policy's ``policy.frag``, ``policy.json`` and ``bands/`` (``policy/``)
  are kept. ``lod.png`` beside each is drawn from the summary (``study.report.lod``).

``python scripts/docs_lod.py FOLDER EXPERIMENT [KEY=VALUE ...]`` recomputes the ``lod`` of a
tradeoff folder's summary from its ``tradeoff.parquet`` (the experiment and the overrides of its
run), as a re-run of the tradeoff would, without measuring a point again: the policy is chosen
from the points' maps, then drawn and exported into ``FOLDER/policy`` again.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
# scene -> the folder of its tradeoff summary, under docs/results
SCENES = {
    "default": "tradeoff",
    "views-view1": "lod/views-view1",
    "views-view2": "lod/views-view2",
    "views-view3": "lod/views-view3",
    "deep_steps": "lod/deep_steps",
    "grazing": "lod/grazing",
    "calm": "lod/calm",
}


def _lod(results: Path, scene: str, folder: str) -> dict:
    path = results / folder / "summary.json"
    if not path.is_file():
        raise FileNotFoundError(f"{path} is missing: re-run the tradeoff into {path.parent}")
    lod = json.loads(path.read_text())["scenes"][scene].get("lod")
    if not lod:
        raise ValueError(f"{path}: {scene} has no level-of-detail finding (screened without maps)")
    return lod


def lod_page(results: Path) -> str:
    """The Markdown of ``results/lod/report.md`` (see the module doc)."""
    sys.path.insert(0, str(REPO))
    from study.report.lod import EXPORT_METHOD, METHOD, export_table, lod_table, pays

    rows = [(f"[{scene}](../{folder}/lod.png)", _lod(results, scene, folder))
            for scene, folder in SCENES.items()]  # fmt: skip
    paying = [scene for scene, (_, lod) in zip(SCENES, rows) if pays(lod)]
    intro = (
        "*Written by `scripts/build_docs.py` (`scripts/docs_lod.py`) from the committed "
        "summaries of `study tradeoff` on each scene (the default scene's in "
        "`docs/results/tradeoff/`, the others in `docs/results/lod/<scene>/`). What a policy is "
        "and how it is drawn: "
        "[level of detail](../../tradeoff.md#level-of-detail-a-shader-per-band).*"
    )
    verdict = (
        f"Bands pay (held out and drawn: within one standard error at a ratio of at most 0.8) on "
        f"{len(paying)} of {len(SCENES)} scenes" + (f": {', '.join(paying)}." if paying else ".")
    )
    lines = ["# Level of detail on seven scenes", "", intro, "", METHOD, "", *lod_table(rows)]
    links = dict(zip((cell for cell, _ in rows), SCENES.values()))
    drawn = [
        "## The policies drawn",
        "",
        EXPORT_METHOD,
        "",
        *export_table(rows, lambda e: "policy.frag, policy.json"),
        "",
        "The files: "
        + ", ".join(
            f"{cell.split(']')[0][1:]}: [policy.frag](../{folder}/policy/policy.frag), "
            f"[policy.json](../{folder}/policy/policy.json)"
            for cell, folder in links.items()
        )
        + ".",
    ]
    return "\n".join([*lines, "", verdict, "", *drawn, ""])


def refresh(folder: Path, experiment: str, overrides: list[str]) -> dict:
    """Recompute the ``lod`` of ``folder``'s ``summary.json`` from its ``tradeoff.parquet``
    with the current ``study.studies.lod`` (the experiment file and the ``--set`` overrides of
    its tradeoff), draw the policy into ``folder/policy`` again (``study.studies.lod_export``)
    and write the summary (and a tradeoff folder's ``report.md``) back; returns the finding."""
    sys.path.insert(0, str(REPO))
    from study._backend import init_backend
    from study._io import write_json
    from study.config.experiment import load_experiments
    from study.report.tradeoff import write_tradeoff_report
    from study.studies.lod import full_points, scene_policies
    from study.studies.lod_export import export_policies
    from study.sweep import read_table, scene_spec

    exp = load_experiments([experiment], overrides)[0]
    recs = full_points(read_table(folder / "tradeoff.parquet"), exp.name)
    summary = json.loads((folder / "summary.json").read_text())
    found = scene_policies(exp, recs, summary["tolerance"])
    summary["scenes"][exp.name]["lod"] = found
    init_backend("llvm_ad_rgb")
    export_policies([exp], [scene_spec(experiment, overrides)], summary, folder, "llvm_ad_rgb",
                    print)  # fmt: skip
    write_json(folder / "summary.json", summary)
    if (folder / "report.md").is_file():  # a tradeoff's own folder: its report says it too
        write_tradeoff_report(folder, summary)
    return found


if __name__ == "__main__":
    # python scripts/docs_lod.py                       the page, on stdout
    # python scripts/docs_lod.py FOLDER EXPERIMENT [K=V ...]   refresh FOLDER's lod
    if len(sys.argv) > 2:
        print(json.dumps(refresh(Path(sys.argv[1]), sys.argv[2], sys.argv[3:]), indent=1)[:2000])
    else:
        print(lod_page(REPO / "docs" / "results"))
