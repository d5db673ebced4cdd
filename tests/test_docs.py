"""The documentation: generated pages equal what their result files give, and the site builds
with ``mkdocs build --strict`` (a broken link, a missing page or an image that is not there
fails)."""

from __future__ import annotations

import importlib.util
import os
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
    import json

    c = json.loads((REPO / "docs" / "results" / "default" / "constants.json").read_text())
    e = c["error"]
    quoted = (
        f"RMSE {e['rmse']['default']:.4f} -> {e['rmse']['fitted']:.4f}, FLIP\n  "
        f"{e['flip']['default']:.4f} -> {e['flip']['fitted']:.4f} (`make run`)"
    )
    assert quoted in (REPO / "README.md").read_text(), quoted
    fast = (REPO / "docs" / "fast-references.md").read_text()
    assert f"({e['flip']['fitted']:.4f} on `make run`)" in fast


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
