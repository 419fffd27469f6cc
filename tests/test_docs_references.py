"""Every page of docs/ points at things that exist: relative links (and their #anchors), and the
project paths it names (holoflow/..., stages/..., tests/..., docs/...). The pages describe how things
are; the history lives in CHANGELOG.md, so no page cites an issue or a stop number."""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = sorted((ROOT / "docs").glob("*.md")) + [ROOT / "README.md", ROOT / "CHANGELOG.md"]
#: files the docs name as examples of what a user would write (docs/extending.md)
EXAMPLES = {"stages/my_detail.py", "stages/my_stage.py", "stages/denoise.py"}
PATH = re.compile(r"(?<![\w/.-])((?:holoflow|stages|tests|docs)/[\w./-]*\w)")


def _anchor(heading: str) -> str:
    """GitHub's anchor of a Markdown heading: lower case, punctuation dropped, spaces to dashes."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def _anchors(page: Path) -> set[str]:
    return {_anchor(m) for m in re.findall(r"^#+ (.+)$", page.read_text(), flags=re.M)}


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_links_resolve(page):
    for target in re.findall(r"\]\(([^)\s]+)\)", page.read_text()):
        if re.match(r"[a-z]+:", target):
            continue
        path, _, anchor = target.partition("#")
        dest = (page.parent / path) if path else page
        assert dest.exists(), f"{page.name}: link {target}"
        if anchor and dest.suffix == ".md":
            assert anchor in _anchors(dest), f"{page.name}: no heading for #{anchor} in {dest.name}"


@pytest.mark.parametrize("page", [p for p in PAGES if p.name != "CHANGELOG.md"], ids=lambda p: p.name)
def test_named_paths_exist(page):
    for path in PATH.findall(page.read_text()):
        if path in EXAMPLES or path.endswith("__pycache__") or path.endswith("_"):
            continue
        assert (ROOT / path).exists(), f"{page.name}: {path}"


def test_anchor_of_a_heading():
    assert _anchor("First run: compiling the kernels") == "first-run-compiling-the-kernels"
    assert _anchor("`holoflow view`: look around") == "holoflow-view-look-around"


def test_docs_cite_no_issue_or_stop_numbers():
    found = [
        f"{p.name}:{n}"
        for p in (ROOT / "docs").glob("*.md")
        for n, line in enumerate(p.read_text().splitlines(), 1)
        if re.search(r"(stop|issue) [0-9]+", line, flags=re.I)
    ]
    assert not found, f"history belongs in CHANGELOG.md: {found}"
