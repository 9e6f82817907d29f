"""The pages a user reads (README, BENCHMARKS, CHANGELOG, docs/, the model and config READMEs) read as a guide and a
page of current figures, not as a work log: no work-log labels, no tools outside the repository, links that resolve,
every shipped model in the README's table, and a layout page that names the package as it is."""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def user_pages() -> list[Path]:
    pages = [ROOT / "README.md", ROOT / "BENCHMARKS.md", ROOT / "CHANGELOG.md"]
    pages += sorted((ROOT / "docs").rglob("*.md"))
    pages += sorted((ROOT / "models").glob("*/README.md"))
    pages += sorted((ROOT / "configs").rglob("README.md"))
    pages += sorted((ROOT / "roshan" / "data").rglob("README.md"))
    pages += sorted((ROOT / "benchmarks" / "maps").glob("README.md"))
    return [p for p in pages if p.is_file()]


# A work log's marks: its own issue and session numbers (another project's issue, "upstream issue 5777", is a
# citation), and tools that live outside the repository.
WORK_LOG = [
    (re.compile(r"(?<!upstream )\bissues? \d+", re.I), "an issue number"),
    (re.compile(r"\bsessions? \d+", re.I), "a session number"),
    (re.compile(r"\.\./shared|shared/tools|fresh-check|farm-bench|\.ci/run"), "a tool outside the repository"),
    (re.compile(r"\bthis session\b", re.I), "a work-log phrase"),
]


@pytest.mark.parametrize("page", user_pages(), ids=lambda p: str(p.relative_to(ROOT)))
def test_a_user_page_is_not_a_work_log(page):
    found = []
    for lineno, line in enumerate(page.read_text(encoding="utf-8").splitlines(), 1):
        found += [f"{page.relative_to(ROOT)}:{lineno}: {what}: {m.group(0)!r}"
                  for pattern, what in WORK_LOG for m in pattern.finditer(line)]
    assert not found, "\n".join(found)


@pytest.mark.parametrize("name", ["README.md", "BENCHMARKS.md"])
def test_headings_carry_no_dates_or_labels(name):
    headings = [ln for ln in (ROOT / name).read_text(encoding="utf-8").splitlines() if ln.startswith("#")]
    dated = [h for h in headings if re.search(r"\d{4}-\d{2}-\d{2}|\(issue|\bsession\b|\(first step\)", h)]
    assert not dated, dated


def test_the_readme_and_benchmarks_fit_their_length():
    assert len((ROOT / "README.md").read_text(encoding="utf-8").splitlines()) <= 400
    assert len((ROOT / "BENCHMARKS.md").read_text(encoding="utf-8").splitlines()) <= 700


def slug(heading: str) -> str:
    """GitHub's anchor for a Markdown heading."""
    text = re.sub(r"[`*_]", "", heading.strip().lstrip("#").strip()).lower()
    return re.sub(r"\s", "-", re.sub(r"[^\w\s-]", "", text))


def anchors(page: Path) -> set[str]:
    text = re.sub(r"```.*?```", "", page.read_text(encoding="utf-8"), flags=re.S)
    return {slug(ln) for ln in text.splitlines() if ln.startswith("#")}


LINK = re.compile(r"\]\((?P<target>[^)\s#]*)(?:#(?P<anchor>[^)\s]+))?\)")


@pytest.mark.parametrize("page", user_pages(), ids=lambda p: str(p.relative_to(ROOT)))
def test_every_link_resolves(page):
    broken = []
    for m in LINK.finditer(page.read_text(encoding="utf-8")):
        target, anchor = m.group("target"), m.group("anchor")
        if re.match(r"[a-z]+:", target):
            continue
        path = (page.parent / target).resolve() if target else page
        if not path.exists():
            broken.append(f"{target}: no such file")
        elif anchor and path.suffix == ".md" and anchor not in anchors(path):
            broken.append(f"{target}#{anchor}: no such heading")
    assert not broken, f"{page.relative_to(ROOT)}: " + "; ".join(broken)


def test_every_raw_result_benchmarks_names_exists():
    text = (ROOT / "BENCHMARKS.md").read_text(encoding="utf-8")
    paths = set(re.findall(r"benchmarks/(?:results|scripts|maps)/[\w./*-]*[\w/]", text))
    missing = [p for p in sorted(paths) if not any(ROOT.glob(p.rstrip("/")))]
    assert not missing, missing


def test_benchmarks_starts_with_a_summary_that_lists_every_section():
    text = (ROOT / "BENCHMARKS.md").read_text(encoding="utf-8")
    sections = [ln[3:] for ln in text.splitlines() if ln.startswith("## ")]
    assert sections[0] == "Summary" and "Training that reproduces on any CPU" in sections
    summary = text.split("## Summary", 1)[1].split("\n## ", 1)[0]
    linked = set(re.findall(r"\]\(#([\w-]+)\)", summary))
    assert {slug(s) for s in sections[1:]} <= linked | {"test-suite"}, "a section missing from the summary"


def test_every_shipped_model_has_a_readme_and_a_row_in_the_readme_table():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    table = readme.split("## What to try next", 1)[1].split("\n## ", 1)[0]
    rows = [ln for ln in table.splitlines() if ln.startswith("| [`models/")]
    named = [re.match(r"\| \[`(models/[\w-]+)`\]", ln).group(1) for ln in rows]
    folders = sorted(f"models/{p.name}" for p in (ROOT / "models").iterdir() if p.is_dir())
    assert sorted(named) == folders
    for folder in folders:
        assert (ROOT / folder / "README.md").is_file(), f"{folder} has no README"
    for row in rows:  # what it does, its figure, the command that gives it
        cells = [c.strip() for c in row.strip("|").split("|")]
        assert len(cells) == 4 and all(cells) and cells[3].startswith("`roshan "), row


def test_the_layout_page_names_the_package_as_it_is():
    """docs/layout.md names every subpackage and base module of roshan/, and every path it names exists."""
    text = (ROOT / "docs" / "layout.md").read_text(encoding="utf-8")
    package = ROOT / "roshan"
    subpackages = sorted(p.name for p in package.iterdir() if p.is_dir() and not p.name.startswith("__"))
    modules = sorted(p.name for p in package.glob("*.py") if not p.name.startswith("__"))
    missing = [f"{d}/" for d in subpackages if f"`roshan/{d}/`" not in text and f"`{d}/`" not in text]
    missing += [m for m in modules if f"`{m}`" not in text and f"`roshan/{m}`" not in text]
    assert not missing, f"docs/layout.md does not name {missing}"
    named = set(re.findall(r"`(?:roshan/)?((?:[a-z_]+/)+[a-z_]+\.py|[a-z_]+/)`", text))
    gone = [p for p in sorted(named) if (ROOT / p).exists() is False and not (package / p).exists()]
    assert not gone, f"docs/layout.md names paths that do not exist: {gone}"
