"""The docs' cross-references hold: every relative link in README.md, DESIGN.md, docs/ and
benchmarks/README.md names a file that exists and, with a #fragment, a heading of that file
(GitHub's anchor: lower case, punctuation dropped, spaces to hyphens). Bad input tried: a link
to a missing file and to a missing heading (the rule itself, last test)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [
    ROOT / "README.md",
    ROOT / "DESIGN.md",
    ROOT / "benchmarks" / "README.md",
    *sorted((ROOT / "docs").glob("*.md")),
]
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")
HEADING = re.compile(r"^#{1,6} +(.+?) *#*$", re.MULTILINE)
FENCE = re.compile(r"^```.*?^```", re.MULTILINE | re.DOTALL)


def anchor(heading: str) -> str:
    """GitHub's anchor of a heading."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def anchors(page: Path) -> set[str]:
    return {anchor(h) for h in HEADING.findall(FENCE.sub("", page.read_text()))}


def broken(page: Path, root: Path = ROOT) -> list[str]:
    wrong = []
    for target in LINK.findall(FENCE.sub("", page.read_text())):
        if re.match(r"[a-z]+:", target):  # a URL (https:, mailto:): not ours to check
            continue
        path, _, fragment = target.partition("#")
        file = (page.parent / path).resolve() if path else page
        if not file.exists():
            wrong.append(f"{page.relative_to(root)}: {target}: no such file")
        elif fragment and file.suffix == ".md" and fragment not in anchors(file):
            wrong.append(f"{page.relative_to(root)}: {target}: no such heading")
    return wrong


@pytest.mark.parametrize("page", PAGES, ids=[str(p.relative_to(ROOT)) for p in PAGES])
def test_every_link_names_a_file_and_heading_that_exist(page):
    assert not broken(page), "\n".join(broken(page))


def test_the_rule_itself(tmp_path):
    (tmp_path / "other.md").write_text("# The air–ground link (`drivers/xbee`)\n")
    page = tmp_path / "page.md"
    page.write_text(
        "[ok](other.md#the-airground-link-driversxbee) [gone](missing.md) "
        "[no heading](other.md#nowhere) [web](https://example.com/#x)\n"
    )
    assert broken(page, tmp_path) == [
        "page.md: missing.md: no such file",
        "page.md: other.md#nowhere: no such heading",
    ]
