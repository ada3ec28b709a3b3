"""No link of the README or the site points outside the repository, and every link lands.

A clone has only what is in it: a link to ``../shared`` (the design notes of the team) or
to the web is a link a reader may not be able to follow, and a web page can change under
the text that cites it. So README.md and docs/**/*.md link only to files of the
repository, by relative path, and each link's target exists (with its heading, when the
link names one inside docs/). MkDocs' strict build (a gate of .ci/run) checks the site's
own links too; this test also covers the README, which is not part of the site.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PAGES = [REPO / "README.md", *sorted((REPO / "docs").rglob("*.md"))]

LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
AUTOLINK = re.compile(r"<(https?://[^>]+)>|(?<![(\w])(https?://\S+)")
FENCE = re.compile(r"^```.*?^```[ \t]*$", re.MULTILINE | re.DOTALL)


def _prose(text: str) -> str:
    """The page without its fenced blocks and code spans (their text is code, not links)."""
    return re.sub(r"`[^`\n]*`", "", FENCE.sub("", text))


def _anchor(heading: str) -> str:
    """The id MkDocs' toc extension gives a heading (its default slugify)."""
    text = re.sub(r"[`*_]", "", heading).strip().lower()
    text = re.sub(r"[^\w\s-]", "", text)
    return re.sub(r"[-\s]+", "-", text).strip("-")


def _anchors(path: Path) -> set[str]:
    text = FENCE.sub("", path.read_text(encoding="utf-8"))
    return {_anchor(m.group(1)) for m in re.finditer(r"^#{1,6}\s+(.*?)\s*#*$", text, re.MULTILINE)}


def problems_of(page: Path, text: str) -> list[str]:
    """Every link of ``text`` (the page ``page``) that leaves the repository or lands nowhere."""
    prose = _prose(text)
    found = [f"a web address: {match.group(1) or match.group(2)}" for match in AUTOLINK.finditer(prose)]
    for match in LINK.finditer(prose):
        target = match.group(1)
        if re.match(r"[a-z][a-z0-9+.-]*:", target):
            found.append(f"a link out of the repository: {target}")
            continue
        path, _, anchor = target.partition("#")
        if path.startswith("/"):
            found.append(f"an absolute path: {target}")
            continue
        resolved = (page.parent / path).resolve() if path else page
        if not resolved.is_relative_to(REPO):
            found.append(f"a link out of the repository: {target}")
        elif not resolved.exists():
            found.append(f"a link to nothing: {target}")
        elif anchor and resolved.suffix == ".md" and anchor not in _anchors(resolved):
            found.append(f"a link to a heading that is not there: {target}")
    return found


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.relative_to(REPO).as_posix())
def test_links_stay_in_the_repository_and_land(page: Path) -> None:
    assert problems_of(page, page.read_text(encoding="utf-8")) == []


def test_the_check_catches_what_it_should() -> None:
    page = REPO / "docs" / "index.md"
    for bad in ["[x](../../shared/design/ARCHITECTURE.md)", "[x](https://example.org)", "see https://example.org",
                "[x](no-such-page.md)", "[x](language.md#no-such-heading)", "[x](/etc/passwd)"]:
        assert problems_of(page, bad), bad
    assert problems_of(page, "[x](language.md) and `https://in.code/span`") == []
