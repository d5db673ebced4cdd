"""The figures the hand-written pages quote, checked against the committed result files.

The hand-written pages are ``README.md``, ``experiments/README.md`` and every ``docs/*.md`` that
``scripts/build_docs.py`` does not generate. In them:

* every shader name (``water_refraction...``, ``water_reflection...``, ``water_baseline...``)
  is one the committed result files under ``docs/results/`` hold;
* every FLIP or RMSE figure (a decimal of three or more places in a clause of a paragraph,
  list item or table row that says FLIP or RMSE) is a FLIP or RMSE value of a committed result
  file, at the precision quoted: of the result folders the paragraph links to, where it links
  to some, else of those the page links to, else of any current result folder;
* no figure comes from a stale result folder: one whose original shader, fitted on a scene,
  scores other than the newest committed run of that scene (:func:`stale_results`); its
  generated report says so at its top;
* the caption of a side-by-side figure (``images_<scene>.png``: its alt text and the paragraph
  under it) names only the shaders its panels show (``images_<scene>.json``).

Quoted passages between ``<!-- quote:NAME -->`` and ``<!-- /quote -->`` are written by
:func:`fill_quotes` from the result files (``QUOTES``); ``build_docs.py`` writes them and its
``--check`` fails when one differs.
"""

from __future__ import annotations

import json
import re
from functools import lru_cache
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "docs" / "results"

SHADER = re.compile(r"\bwater_(?:refraction|reflection|baseline)(?:_[a-z0-9_]*[a-z0-9])?\b")
# a figure: 0.xxx with three or more places, not a ratio (0.44x) nor a percentage
FIGURE = re.compile(r"(?<![\w.])0\.\d{3,}(?![\d.]*\s?(?:x\b|%))")
METRIC = re.compile(r"\b(?:FLIP|RMSE)\b")
RESULT_LINK = re.compile(r"results/([a-z0-9_/-]+?)/[A-Za-z0-9_.-]+\.(?:md|png|json)")
# the docs/*.md that build_docs.py writes from the code (not hand-written)
GENERATED_TOPIC_PAGES = ("experiment-keys.md", "file-formats.md", "engine-inputs.md")
QUOTE = re.compile(r"<!-- quote:([a-z0-9-]+) -->.*?<!-- /quote -->", re.S)

# the committed runs that are the newest of their scene: a scene's original shader, fitted at
# its schedule, scores here what any other result folder must score for that scene
CURRENT = ("default", "tradeoff", "scenes", "views/tradeoff")


def _walk(obj, path: tuple, figures: set, names: set) -> None:
    if isinstance(obj, dict):
        for k, v in obj.items():
            names.update(SHADER.findall(str(k)))
            _walk(v, (*path, str(k).lower()), figures, names)
    elif isinstance(obj, list):
        for v in obj:
            _walk(v, path, figures, names)
    elif isinstance(obj, str):
        names.update(SHADER.findall(obj))
    elif isinstance(obj, float) and any("flip" in p or "rmse" in p for p in path):
        figures.add(obj)


@lru_cache(maxsize=1)
def result_pool() -> dict[str, dict[str, set]]:
    """Per result folder (relative to ``docs/results``): the FLIP and RMSE values its JSON and
    Parquet files hold (``figures``) and the shader names they mention (``names``)."""
    import pyarrow.parquet as pq

    pool: dict[str, dict[str, set]] = {}
    files = sorted([*RESULTS.rglob("*.json"), *RESULTS.rglob("*.parquet")])
    for f in files:
        folder = f.parent.relative_to(RESULTS).as_posix()
        entry = pool.setdefault(folder, {"figures": set(), "names": set()})
        if f.suffix == ".json":
            _walk(json.loads(f.read_text()), (), entry["figures"], entry["names"])
            continue
        table = pq.read_table(f)
        for col in table.column_names:
            values = table.column(col).to_pylist()
            if "flip" in col.lower() or "rmse" in col.lower():
                entry["figures"].update(v for v in values if isinstance(v, float))
            for v in values:
                if isinstance(v, str):
                    entry["names"].update(SHADER.findall(v))
    return pool


def _seed_flips(folder: str) -> dict[str, float]:
    """Scene -> FLIP of the original shader fitted at its own schedule, in a result folder."""
    if folder == "default":
        c = json.loads((RESULTS / "default" / "constants.json").read_text())
        return {"default": c["error"]["flip"]["fitted"]}
    summary = RESULTS / folder / "summary.json"
    if not summary.is_file():
        return {}
    scenes = json.loads(summary.read_text()).get("scenes") or {}
    return {s: v["seed"]["flip"] for s, v in scenes.items() if (v.get("seed") or {}).get("flip")}


@lru_cache(maxsize=1)
def stale_results(tolerance: float = 1e-3) -> dict[str, str]:
    """Result folder -> why it is stale: the original shader, fitted on one of its scenes,
    scores other than in the newest committed run of that scene (``CURRENT``): the reference
    or the shader changed since the folder's run."""
    current: dict[str, tuple[str, float]] = {}
    for folder in CURRENT:
        for scene, flip in _seed_flips(folder).items():
            current.setdefault(scene, (folder, flip))
    stale = {}
    for summary in sorted(RESULTS.rglob("summary.json")):
        folder = summary.parent.relative_to(RESULTS).as_posix()
        if folder in CURRENT:
            continue
        for scene, flip in _seed_flips(folder).items():
            if scene in current and abs(flip - current[scene][1]) > tolerance:
                where, now = current[scene]
                stale[folder] = (
                    f"the original shader fitted on `{scene}` scores FLIP {flip:.4f} here and "
                    f"{now:.4f} in docs/results/{where}: this run's reference or shader is not "
                    "the current one"
                )
                break
    return stale


def hand_pages() -> list[Path]:
    """The pages written by hand: README.md, experiments/README.md and the docs/*.md that
    build_docs.py does not generate."""
    docs = [p for p in sorted((REPO / "docs").glob("*.md")) if p.name not in GENERATED_TOPIC_PAGES]
    return [REPO / "README.md", REPO / "experiments" / "README.md", *docs]


def blocks(text: str) -> list[str]:
    """A page's paragraphs, list items and table rows (code blocks left out)."""
    text = re.sub(r"```.*?```", "", text, flags=re.S)
    out: list[str] = []
    for para in re.split(r"\n\s*\n", text):
        lines = para.split("\n")
        if all(line.lstrip().startswith("|") for line in lines if line.strip()):
            out += [line for line in lines if line.strip()]
            continue
        item: list[str] = []
        for line in lines:
            if re.match(r"\s*(?:[*-]|\d+\.)\s", line) and item:
                out.append("\n".join(item))
                item = []
            item.append(line)
        out.append("\n".join(item))
    return out


def _quoted(value: str, pool: set) -> bool:
    places = len(value.split(".")[1])
    return any(f"{v:.{places}f}" == value for v in pool)


def page_problems(path: Path, text: str | None = None) -> list[str]:
    """What a hand-written page (``text``: its text, else the file's) quotes that no current
    committed result file holds."""
    pool, stale = result_pool(), stale_results()
    current = {f: e for f, e in pool.items() if f not in stale}
    known = set().union(*(e["names"] for e in pool.values()))
    everything = set().union(*(e["figures"] for e in current.values()))
    rel = path.relative_to(REPO).as_posix()
    text = path.read_text() if text is None else text
    on_page = {m for m in RESULT_LINK.findall(text) if m in current}
    page_pool = set().union(*(current[f]["figures"] for f in on_page)) if on_page else everything
    problems = []
    for block in blocks(text):
        where = " ".join(block.split())[:90]
        for name in sorted(set(SHADER.findall(block)) - known):
            problems.append(f"{rel}: `{name}` is in no committed result file ({where} ...)")
        links = {m for m in RESULT_LINK.findall(block) if m in pool}
        for folder in sorted(links & stale.keys()):
            if FIGURE.search(block) and METRIC.search(block):
                problems.append(f"{rel}: quotes the stale results/{folder}: {stale[folder]}")
        linked = set().union(*(current[f]["figures"] for f in links if f in current))
        clauses = re.split(r"(?<=[.;:])\s", block)
        for value in [v for c in clauses if METRIC.search(c) for v in FIGURE.findall(c)]:
            if not _quoted(value, linked or page_pool):
                shown = sorted(links or on_page)
                source = f"results/{{{', '.join(shown)}}}" if shown else "any current result"
                problems.append(f"{rel}: {value} is in no FLIP/RMSE of {source} ({where} ...)")
    problems += caption_problems(path, text)
    return problems


# a side-by-side figure, its alt text and the italic paragraph under it
IMAGE = re.compile(
    r"!\[([^\]]*)\]\(([^)]*images_[a-z0-9_-]+)\.png\)\n*((?:\*[^\n]*(?:\n[^\n]+)*)?)"
)


def caption_problems(path: Path, text: str | None = None) -> list[str]:
    """A side-by-side figure's alt text and caption name only the shaders its panels show."""
    problems = []
    rel = path.relative_to(REPO).as_posix()
    for alt, target, caption in IMAGE.findall(path.read_text() if text is None else text):
        data = (path.parent / f"{target}.json").resolve()
        if not data.is_file():
            continue
        panels = json.loads(data.read_text())["panels"]
        shown = {n for p in panels for n in SHADER.findall(p["title"])}
        shown |= {"water_refraction"}  # the original shader is its first panels' subject
        for name in sorted(set(SHADER.findall(alt + caption)) - shown):
            problems.append(
                f"{rel}: the caption of {Path(target).name}.png names `{name}`, which none of "
                f"its panels shows ({', '.join(sorted(shown))})"
            )
    return problems


def problems() -> list[str]:
    return [p for page in hand_pages() for p in page_problems(page)]


# ---- quoted passages written from the result files ------------------------------------------


def _json(rel: str) -> dict:
    return json.loads((RESULTS / rel).read_text())


def _named(label: str) -> str:
    """A configuration's label, ``shader (a, b, c)``, with the shader's name as code."""
    name, _, schedule = label.partition(" ")
    return f"`{name}` {schedule}".strip()


def _front_caption(prefix: str) -> str:
    """The caption of the default scene's side-by-side, from its panels."""
    panels = _json("tradeoff/images_default.json")["panels"]
    titles = [p["title"] for p in panels]
    flips = [p.get("flip") for p in panels]
    best = _named(titles[3].split(": ", 1)[1])
    if len(panels) > 4:
        rec = _named(titles[4].split(": ", 1)[1])
        last = f"the recommendation ({rec}, {flips[4]:.4f})"
    else:  # the recommendation is the best within the original's fetches: one panel
        last = "it is also the recommendation"
    return (
        f"*The default scene, from [`study tradeoff`]({prefix}tradeoff.md): the reference; the "
        f"original shader with its documented constants (FLIP {flips[1]:.4f}); the same shader "
        f"fitted ({flips[2]:.4f}); the best shader within the original's texture fetches "
        f"({best}, {flips[3]:.4f}); {last}. Below each, its error on the water pixels.*"
    )


def _make_run() -> str:
    e = _json("default/constants.json")["error"]
    return (
        f"RMSE {e['rmse']['default']:.4f} -> {e['rmse']['fitted']:.4f}, FLIP "
        f"{e['flip']['default']:.4f} -> {e['flip']['fitted']:.4f}"
    )


def _recommended() -> str:
    s = _json("tradeoff/summary.json")["scenes"]["default"]
    rec, seed = s["recommended"], s["seed"]
    return (
        f"`{rec['variant']}` at {_times(rec['scale'])} the original's schedule: FLIP "
        f"{rec['flip']:.4f} at {rec['fetches_mean']:.1f} fetches against the fitted original's "
        f"{seed['flip']:.4f} at {seed['fetches_mean']:.1f}"
    )


def _times(scale: float) -> str:
    return {0.5: "half", 1.0: "the same as", 2.0: "twice"}.get(scale, f"{scale:g} times")


def _glint_split() -> str:
    """What separates the sun's disc from the reference's glitter, term by term."""
    from docs_error_budget import glint_split

    return glint_split(_json("error-budget/water_refraction_beer_disc_walls.json")["highlights"])[0]


QUOTES = {
    "glint-split": _glint_split,
    "front-caption-readme": lambda: _front_caption("docs/"),
    "front-caption-docs": lambda: _front_caption(""),
    "make-run": _make_run,
    "recommended": _recommended,
}


def fill_quotes(text: str) -> str:
    """``text`` with every quoted passage written from the result files."""

    def fill(m: re.Match) -> str:
        name = m.group(1)
        if name not in QUOTES:
            raise KeyError(f"no quote named {name!r} (scripts/docs_figures.py QUOTES)")
        return f"<!-- quote:{name} -->{QUOTES[name]()}<!-- /quote -->"

    return QUOTE.sub(fill, text)


def quoted_pages() -> dict[Path, str]:
    """Every hand-written page that holds a quoted passage -> its text with them filled."""
    out = {}
    for page in hand_pages():
        text = page.read_text()
        if QUOTE.search(text):
            out[page] = fill_quotes(text)
    return out
