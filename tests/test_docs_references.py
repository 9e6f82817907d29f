"""Citations of the model description (docs/model/) name a page that exists and a section heading it has.

Code, configs, README.md, BENCHMARKS.md and the model READMEs cite the model as ``docs/model/<page>.md §N``
(several sections as ``§7 and §10.1``, ``§1, §2.3``, ranges as ``§3-4``; thesis.md's list of differences as
``docs/model/thesis.md §1, item 17``). The pages cite each other as ``[agents.md](agents.md) §7.1``. The
original's spec files (firespin.md, agents.md, learning.md, the spec README) are not in the repository, so a
bare citation of them is an error.
"""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs" / "model"

NUM = r"\d+(?:\.\d+)*"
SECTIONS = rf"(?P<secs>(?:(?:,\s*|\s+and\s+|\s+)§{NUM}(?:-{NUM})?)*)"
# docs/model/fire.md §2 and §10 / docs/model/thesis.md §1, item 17
CITATION = re.compile(rf"(?P<path>docs/[\w/.-]*?\w\.md)`?{SECTIONS}(?P<item>,\s*items?\s+\d+)?")
# inside docs/model: [agents.md](agents.md) §7.1
LINK = re.compile(rf"\]\((?P<path>[\w.-]+\.md)\){SECTIONS}")
SECTION = re.compile(rf"§(?P<a>{NUM})(?:-(?P<b>{NUM}))?")
HEADING = re.compile(rf"^#{{2,6}}\s+(?:\*\*)?(?P<n>{NUM})\.?\s", re.M)
# The original's spec files, cited without docs/model/ (or as "spec README", "shared/spec", "spec item N"); the
# text of a Markdown link, [agents.md](docs/model/agents.md), is not a citation (its target is checked).
BARE = re.compile(r"(?<![\w/.\[-])(?:shared/spec/)?(?:firespin|agents|learning)\.md"
                  r"|\bspec README\b|\bshared/spec\b|\bspec item \d+")

SELF = Path(__file__).resolve()


def scanned_files() -> list[Path]:
    """Where the model is cited: README.md, BENCHMARKS.md, CHANGELOG.md, docs/*.md, configs/, roshan/, tests/,
    models/*/README.md."""
    files = [ROOT / "README.md", ROOT / "BENCHMARKS.md", ROOT / "CHANGELOG.md",
             *sorted((ROOT / "models").glob("*/README.md")),
             *sorted(p for p in (ROOT / "docs").glob("*.md"))]
    for folder, patterns in (("configs", ("*.yaml", "*.yml", "*.md")), ("roshan", ("*.py", "*.md", "*.yaml")),
                             ("tests", ("*.py",))):
        for pattern in patterns:
            files += sorted(p for p in (ROOT / folder).rglob(pattern) if "__pycache__" not in p.parts)
    return [f for f in files if f.is_file() and f.resolve() != SELF]


def headings(page: Path) -> set[str]:
    return {m.group("n") for m in HEADING.finditer(page.read_text(encoding="utf-8"))}


def items_of_section_1(page: Path) -> set[str]:
    """The numbered items of a page's section 1 (thesis.md: the differences between the code versions)."""
    text = page.read_text(encoding="utf-8")
    start = re.search(r"^## 1\.", text, re.M)
    if start is None:
        return set()
    end = re.search(r"^## \d", text[start.end():], re.M)
    body = text[start.end(): start.end() + end.start() if end else len(text)]
    return set(re.findall(r"^(\d+)\. ", body, re.M))


def section_numbers(secs: str) -> list[str]:
    """``§3-4 and §8`` -> ['3', '4', '8']: both ends of a range must exist."""
    out = []
    for m in SECTION.finditer(secs):
        out.append(m.group("a"))
        if m.group("b"):
            out.append(m.group("b"))
    return out


def problems(text: str, where: str, base: Path = ROOT) -> list[str]:
    """Every broken citation in ``text``: a missing page, a missing section heading, a missing item of
    thesis.md §1, or a bare citation of the original's spec files. ``base`` resolves relative links."""
    found = []
    for lineno, line in enumerate(text.splitlines(), 1):
        at = f"{where}:{lineno}"
        for m in BARE.finditer(line):
            found.append(f"{at}: bare citation {m.group(0)!r}; cite docs/model/<page>.md §N")
        cites = [(ROOT / m.group("path"), m) for m in CITATION.finditer(line)]
        cites += [(base / m.group("path"), m) for m in LINK.finditer(line)]
        for page, m in cites:
            if not page.is_file():
                found.append(f"{at}: {m.group('path')} does not exist")
                continue
            have = headings(page)
            found += [f"{at}: {m.group('path')} has no section {n}" for n in section_numbers(m.group("secs"))
                      if n not in have]
            item = m.groupdict().get("item")
            if item:
                n = re.search(r"\d+", item).group(0)
                if n not in items_of_section_1(page):
                    found.append(f"{at}: {m.group('path')} §1 has no item {n}")
    return found


def test_model_pages_exist_with_numbered_sections():
    for name, last in (("fire", 14), ("agents", 15), ("learning", 15), ("thesis", 3)):
        have = headings(DOCS / f"{name}.md")
        assert {str(k) for k in range(1, last + 1)} <= have, name
    assert (DOCS / "README.md").is_file()
    assert {str(k) for k in range(1, 28)} <= items_of_section_1(DOCS / "thesis.md")


def test_every_citation_resolves():
    found = []
    for path in scanned_files():
        found += problems(path.read_text(encoding="utf-8"), str(path.relative_to(ROOT)), base=path.parent)
    assert not found, "\n".join(found)


def test_model_pages_cite_each_other_correctly():
    found = []
    for page in sorted(DOCS.glob("*.md")):
        text = page.read_text(encoding="utf-8")
        found += [p for p in problems(text, str(page.relative_to(ROOT)), base=DOCS) if "bare citation" not in p]
    assert not found, "\n".join(found)


def test_the_readme_points_at_the_model():
    assert "docs/model/" in (ROOT / "README.md").read_text(encoding="utf-8")


@pytest.mark.parametrize("old", [
    "- the FireSPIN model of `shared/spec/firespin.md`, batched over envs",
    '"""The FlyAgent task (agents.md 5-9)."""',
    "(learning.md 6: reward scaling by a running std without shift",
    "# The thesis's saved planner was trained over its SimpleFlyAgent (spec README, open ambiguities)",
    "its \"off\" row shared the encoder too (spec item 17)",
])
def test_the_old_spec_citations_are_reported(old):
    assert problems(old, "old"), old


@pytest.mark.parametrize("cite, ok", [
    ("docs/model/fire.md §11", True),
    ("docs/model/agents.md §7 and §10.1", True),
    ("docs/model/learning.md §6.2 step 1", True),
    ("docs/model/agents.md §3-4, §14", True),
    ("docs/model/thesis.md §1, item 17", True),
    ("`docs/model/fire.md`", True),
    ("docs/model/fire.md §15", False),
    ("docs/model/agents.md §7 and §10.9", False),
    ("docs/model/learning.md §6.2-6.7", False),
    ("docs/model/thesis.md §1, item 28", False),
    ("docs/model/firespin.md §11", False),
])
def test_citation_checker(cite, ok):
    assert (not problems(cite, "x")) == ok
