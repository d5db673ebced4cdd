"""What the hand-written pages say: every shader name and FLIP/RMSE figure comes from a committed
result file (``scripts/docs_figures.py``), and the pages read as a manual (present tense, no
history)."""

from __future__ import annotations

import importlib.util
import re
import sys

import pytest

from helpers import REPO

# words that tell the project's history rather than how it works
HISTORY = re.compile(r"\b(?:now|no longer|was|before this|the issue|mended)\b", re.I)
# a reference to the project's source: a path under a source folder, a Python file, a module
SOURCE_REF = re.compile(
    r"(?<![\w/.-])(?:study|shaders_port|scripts|tests|benchmarks)/[\w./{},*-]*"
    r"|(?<![\w/.-])[\w-]+\.py\b"
    r"|(?<![\w/.-])(?:study|shaders_port)(?:\.[a-z_]\w*)+"
)
# a "for contributors" note: a heading (to the next heading of its level or above) or an
# admonition (to the next unindented line)
CONTRIBUTORS = re.compile(r"^(#+) For contributors\b", re.I | re.M)
MAX_SOURCE_REFS = 3


def _figures():
    sys.path.insert(0, str(REPO / "scripts"))
    path = REPO / "scripts" / "docs_figures.py"
    spec = importlib.util.spec_from_file_location("docs_figures", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _prose(text: str) -> str:
    """A page's text without code blocks, inline code and HTML comments."""
    text = re.sub(r"```.*?```", "", text, flags=re.S)
    text = re.sub(r"<!--.*?-->", "", text, flags=re.S)
    return re.sub(r"`[^`\n]*`", "", text)


def outside_contributors(text: str) -> str:
    """A page's text without its "For contributors" sections and notes."""
    text = re.sub(r'^!!! \w+ "For contributors"\n(?:(?: {4}.*)?\n)*', "", text, flags=re.M | re.I)
    while m := CONTRIBUTORS.search(text):
        level = len(m.group(1))
        end = re.compile(rf"^#{{1,{level}}} ", re.M).search(text, m.end())
        text = text[: m.start()] + (text[end.start() :] if end else "")
    return text


def source_refs(text: str) -> list[str]:
    """The references to source files of a page's text outside its contributors' notes."""
    return SOURCE_REF.findall(outside_contributors(text))


def history_words(text: str) -> list[str]:
    return [m.group(0) for m in HISTORY.finditer(_prose(text))]


def test_hand_pages_quote_only_committed_results():
    """Every shader name and FLIP/RMSE figure of README.md, experiments/README.md and the
    hand-written docs pages is one a current committed result file holds, and each figure's
    caption names the shaders its panels show."""
    mod = _figures()
    pages = mod.hand_pages()
    assert REPO / "README.md" in pages and REPO / "docs" / "variants.md" in pages
    assert REPO / "docs" / "experiment-keys.md" not in pages  # generated from the schema
    problems = mod.problems()
    assert not problems, "\n".join(problems)


def test_a_figure_no_current_result_holds_is_caught():
    """A figure of a stale run (the variants study's original shader: 0.2399 and 0.1759,
    where make run scores 0.2369 and 0.1674) and a shader that no result knows fail."""
    mod = _figures()
    page = REPO / "docs" / "variants.md"
    text = page.read_text() + (
        "\n* default: the original shader scores FLIP 0.2399 with its own constants and 0.1759 "
        "fitted.\n\nOn this scene `water_refraction_nowhere` is best.\n"
    )
    problems = mod.page_problems(page, text)
    assert any("0.2399 is in no FLIP/RMSE" in p for p in problems), problems
    assert any("0.1759 is in no FLIP/RMSE" in p for p in problems), problems
    assert any("`water_refraction_nowhere` is in no committed" in p for p in problems), problems
    assert not mod.page_problems(page)


def test_a_stale_result_folder_is_found_and_its_report_says_so():
    """A folder whose original shader scores other than the newest run of its scene is stale;
    its generated report opens with the warning, and a paragraph quoting it with a link fails."""
    mod = _figures()
    stale = mod.stale_results()
    assert "variants" in stale and "tradeoff" not in stale and "default" not in stale
    report = (REPO / "docs" / "results" / "variants" / "report.md").read_text()
    assert "Not the current reference" in report.split("\n## ")[0]
    page = REPO / "docs" / "variants.md"
    text = "FLIP 0.1519 on deep_steps ([report](results/variants/report.md)).\n"
    assert any("quotes the stale results/variants" in p for p in mod.page_problems(page, text))


def test_a_caption_naming_a_shader_its_panels_do_not_show_is_caught():
    mod = _figures()
    page = REPO / "docs" / "index.md"
    text = (
        "![front](results/tradeoff/images_default.png)\n\n*The best within the original's "
        "fetches\n(`water_refraction_beer_walls` at the original's schedule).*\n"
    )
    problems = mod.caption_problems(page, text)
    assert problems and "`water_refraction_beer_walls`" in problems[0]
    fixed = text.replace("water_refraction_beer_walls", "water_refraction_beer_disc_walls_parallax")
    assert mod.caption_problems(page, fixed) == []


def test_quoted_passages_are_written_from_the_result_files():
    """A quoted passage is replaced by what the result files give, whatever it held."""
    mod = _figures()
    filled = mod.fill_quotes("x <!-- quote:make-run -->RMSE 9.9999<!-- /quote --> y")
    assert "9.9999" not in filled and filled.startswith("x <!-- quote:make-run -->RMSE")
    import json

    e = json.loads((REPO / "docs" / "results" / "default" / "constants.json").read_text())["error"]
    assert f"{e['flip']['fitted']:.4f}" in filled
    caption = mod.fill_quotes("<!-- quote:front-caption-docs --><!-- /quote -->")
    assert (
        "water_refraction_beer_disc_walls" in caption
        and mod.caption_problems(
            REPO / "docs" / "index.md",
            "![f](results/tradeoff/images_default.png)\n\n" + caption.split("-->")[1],
        )
        == []
    )
    with pytest.raises(KeyError):
        mod.fill_quotes("<!-- quote:no-such-quote --><!-- /quote -->")


def _manual_pages():
    return _figures().hand_pages()


@pytest.mark.parametrize("page", _manual_pages(), ids=lambda p: p.relative_to(REPO).as_posix())
def test_pages_read_as_a_manual(page):
    """No hand-written page tells the project's history: present tense, what was measured in
    the generated results pages."""
    found = history_words(page.read_text())
    assert not found, f"{page.relative_to(REPO)}: {found}"


def test_history_words_are_found():
    assert history_words("The screen is now at the fit resolution; it was slower.") == [
        "now",
        "was",
    ]
    assert history_words("Mended after the run; `was` in code and <!-- now --> are not.") == [
        "Mended"
    ]


@pytest.mark.parametrize("page", _manual_pages(), ids=lambda p: p.relative_to(REPO).as_posix())
def test_pages_keep_source_references_for_contributors(page):
    """A rule a user needs is on the page; references into the source sit in a "For
    contributors" section or note, at most a few elsewhere."""
    found = source_refs(page.read_text())
    assert len(found) <= MAX_SOURCE_REFS, f"{page.relative_to(REPO)}: {found}"


def test_source_references_are_counted_outside_contributors_notes():
    text = (
        "Run `scripts/setup.sh`; the rule is in `study/fit/solvers.py` "
        "(`study.fit.solvers.fit`, three.js aside).\n\n"
        "## For contributors\n\n`tests/test_a.py`, `bench_b.py`\n\n"
        "### Deeper\n\n`study/x.py`\n\n"
        "## Next\n\n`shaders_port/space.py`\n\n"
        '!!! note "For contributors"\n    `study/y.py`\n\nafter\n'
    )
    assert source_refs(text) == [
        "scripts/setup.sh",
        "study/fit/solvers.py",
        "study.fit.solvers.fit",
        "shaders_port/space.py",
    ]
    assert "after" in outside_contributors(text) and "Deeper" not in outside_contributors(text)
