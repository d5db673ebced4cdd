"""The documentation: generated pages equal what their result files give, every figure the
docs script draws is there with the SHA-256 of the result files it was drawn from, and the site
builds with ``mkdocs build --strict`` (a broken link, a missing page or an image that is not
there fails)."""

from __future__ import annotations

import copy
import hashlib
import importlib.util
import json
import os
import re
import shutil
import subprocess

import pytest

from helpers import REPO


def _build_docs():
    spec = importlib.util.spec_from_file_location("build_docs", REPO / "scripts" / "build_docs.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_generated_pages_are_current():
    mod = _build_docs()
    pages = mod.generated()
    assert len(pages) >= 5
    stale = mod.stale(pages)
    assert not stale, (
        f"run scripts/build_docs.py: stale {[str(p.relative_to(REPO)) for p in stale]}"
    )


def test_a_hand_edited_number_is_caught(tmp_path, monkeypatch):
    """The check fails when a committed report differs from its result file by one digit."""
    mod = _build_docs()
    pages = mod.generated()
    page = mod.RESULTS / "variants" / "report.md"
    edited = {page: pages[page].replace("0.1529", "0.1528", 1)}
    assert edited[page] != pages[page] and mod.stale(edited) == [page]


def test_the_readme_quotes_make_runs_committed_result():
    """The README's and the docs' figures of ``make run`` are those of the run committed in
    docs/results/default (re-run ``make run``, copy its files there, run build_docs)."""
    c = json.loads((REPO / "docs" / "results" / "default" / "constants.json").read_text())
    e = c["error"]
    quoted = (
        f"RMSE {e['rmse']['default']:.4f} -> {e['rmse']['fitted']:.4f}, FLIP "
        f"{e['flip']['default']:.4f} -> {e['flip']['fitted']:.4f}"
    )
    assert quoted in (REPO / "README.md").read_text(), quoted
    fast = (REPO / "docs" / "fast-references.md").read_text()
    assert f"({e['flip']['fitted']:.4f} on `make run`)" in fast


def test_figure_ledger_hashes_recomputed():
    """Each figure of ``docs/results/figures.json`` is there, and each result file it lists has
    the SHA-256 the ledger gives (recomputed here, not by the script)."""
    ledger = json.loads((REPO / "docs" / "results" / "figures.json").read_text())
    assert ledger["drawn"] and "docs/results/tradeoff/images_default.png" in ledger["drawn"]
    for fig, sources in ledger["drawn"].items():
        assert (REPO / fig).is_file(), fig
        assert sources, f"{fig}: drawn from no file"
        for src, digest in sources.items():
            assert hashlib.sha256((REPO / src).read_bytes()).hexdigest() == digest, (fig, src)
    for fig, why in ledger["not_redrawn"].items():
        assert (REPO / fig).is_file() and why, fig


def test_figure_ledger_is_current():
    """Every figure under docs/results is listed, drawn or not, and the script would write the
    ledger as committed."""
    problems = _build_docs().ledger_problems()
    assert not problems, problems


def test_a_changed_result_file_or_a_missing_figure_is_caught():
    mod = _build_docs()
    committed = json.loads(mod.LEDGER.read_text())
    edited = copy.deepcopy(committed)
    fig = "docs/results/tradeoff/pareto.png"
    src = next(iter(edited["drawn"][fig]))
    edited["drawn"][fig][src] = "0" * 64
    assert any(src in p and "SHA-256" in p for p in mod.ledger_problems(edited))
    edited = copy.deepcopy(committed)
    edited["drawn"]["docs/results/tradeoff/nowhere.png"] = edited["drawn"][fig]
    assert any("nowhere.png: the figure is missing" in p for p in mod.ledger_problems(edited))
    edited = copy.deepcopy(committed)
    del edited["not_redrawn"]["docs/results/variants/pareto.png"]
    assert any("variants/pareto.png: not listed" in p for p in mod.ledger_problems(edited))


def test_the_front_pages_viewer_is_make_runs_committed_result():
    """The viewer the docs embed runs the constants of the make-run result committed beside it
    (copy out/default/viewer there when re-running make run)."""
    import numpy as np

    folder = REPO / "docs" / "results" / "default"
    c = json.loads((folder / "constants.json").read_text())
    text = (folder / "viewer" / "data.js").read_text()
    data = json.loads(text[text.index("{") : text.rindex("}") + 1])
    # the page's code is the templates' as they are (a changed viewer.js: copy the viewer again)
    for script in ("viewer.js", "bound.js"):
        assert (folder / "viewer" / script).read_text() == (
            REPO / "study" / "export" / "viewer" / script
        ).read_text(), script
    frag = data["shaders"]["frag"]
    for name in ("ATTENUATION_DISTANCE", "SPECULAR_STRENGTH", "SPECULAR_EXPONENT", "BumptexMult"):
        value = float(np.float32(c["constants"][name]))
        defined = re.findall(rf"#define (SPIRV_CROSS_CONSTANT_ID_\d+) (\S+)\n[^\n]*\n?"
                             rf"const float {name} = \1;", frag)  # fmt: skip
        assert defined and float(defined[0][1]) == value, (name, defined, value)


def test_mkdocs_build_strict(tmp_path):
    mkdocs = shutil.which("mkdocs", path=str(REPO / ".venv" / "bin")) or shutil.which("mkdocs")
    if mkdocs is None:
        pytest.fail("mkdocs is not installed: run `make setup` (it is a dev dependency)")
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    r = subprocess.run(
        [mkdocs, "build", "--strict", "--site-dir", str(tmp_path / "site")],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr[-4000:]
    assert (tmp_path / "site" / "index.html").is_file()
