"""The README and the manual in docs/: every relative link and image resolves, anchors included."""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
FENCE = re.compile(r"^```.*?^```", re.S | re.M)


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation but - and _ dropped, spaces to -."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def anchors(page: Path) -> set[str]:
    text = FENCE.sub("", page.read_text())
    return {slug(h) for h in re.findall(r"^#+ (.+)$", text, re.M)}


def links(page: Path) -> list[str]:
    return LINK.findall(FENCE.sub("", page.read_text()))


def broken(page: Path) -> list[str]:
    """The relative links of ``page`` whose file or anchor does not exist."""
    bad = []
    for target in links(page):
        if re.match(r"[a-z]+:", target):  # https:, mailto:
            continue
        path, _, anchor = target.partition("#")
        file = (page.parent / path).resolve() if path else page
        if not file.exists():
            bad.append(target)
        elif anchor and (file.suffix != ".md" or anchor not in anchors(file)):
            bad.append(target)
    return bad


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_every_relative_link_and_image_resolves(page):
    assert broken(page) == []


def test_the_checker_finds_a_broken_link_image_and_anchor(tmp_path):
    (tmp_path / "a.md").write_text("# Title here\n\n[ok](#title-here) [gone](b.md) ![pic](img/x.png) "
                                   "[bad anchor](#nope) [web](https://example.org)\n```\n[in code](c.md)\n```\n")
    assert broken(tmp_path / "a.md") == ["b.md", "img/x.png", "#nope"]


def test_the_readme_is_a_front_door():
    readme = (ROOT / "README.md").read_text()
    assert len(readme.splitlines()) <= 250
    shown = [t for t in links(ROOT / "README.md") if t.endswith((".png", ".gif"))]
    assert "docs/img/walker.gif" in shown and "docs/img/walker_frames.png" in shown and "docs/img/walker_gait.png" in shown
    for page in PAGES[1:]:  # every page of the manual is linked from the README or the index
        name = page.relative_to(ROOT).as_posix()
        assert name in readme or page.name in (ROOT / "docs" / "index.md").read_text(), name
