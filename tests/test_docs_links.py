"""Relative links in README.md and docs/*.md point to files inside the repository.

A user who installs fusiongs has the repository and nothing beside it, so a link such as
``../elsewhere/FORMAT.md`` is broken for them. Links with a scheme (``https:``, ``mailto:``) are not
checked; a ``#fragment`` on a Markdown file must name one of its headings (GitHub's slugs).
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

_FENCE = re.compile(r"^\s*(```|~~~)")
_CODE_SPAN = re.compile(r"(`+)(?:(?!\1).)+?\1")
_INLINE = re.compile(r"!?\[[^\]]*\]\(\s*(<[^>]*>|[^)\s]+)[^)]*\)")
_REFERENCE = re.compile(r"^\s{0,3}\[[^\]]+\]:\s*(<[^>]*>|\S+)")
_SCHEME = re.compile(r"^[a-zA-Z][a-zA-Z0-9+.-]*:")


def doc_files(root: Path = ROOT) -> list[Path]:
    """README.md and every Markdown file under docs/."""
    return [root / "README.md", *sorted((root / "docs").glob("*.md"))]


def prose_lines(text: str) -> list[str]:
    """The lines outside fenced code blocks, with inline code spans removed."""
    out, fenced = [], False
    for line in text.splitlines():
        if _FENCE.match(line):
            fenced = not fenced
            continue
        if not fenced:
            out.append(_CODE_SPAN.sub("", line))
    return out


def links(path: Path) -> list[str]:
    """Link targets of a Markdown file (inline links, images and reference definitions)."""
    found = []
    for line in prose_lines(path.read_text(encoding="utf-8")):
        found += [m.group(1) for m in _INLINE.finditer(line)]
        m = _REFERENCE.match(line)
        if m:
            found.append(m.group(1))
    return [t[1:-1] if t.startswith("<") and t.endswith(">") else t for t in found]


def slug(heading: str) -> str:
    """GitHub's anchor for a heading text: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"`|\*|_(?=\W)|(?<=\W)_", "", heading.strip()).lower()
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    """Anchors of every heading of a Markdown file outside code blocks (a repeated heading gets
    -1, -2, ...). Code spans stay in the heading text: `frame_response` gives #frame_response."""
    seen: dict[str, int] = {}
    out = set()
    fenced = False
    for line in path.read_text(encoding="utf-8").splitlines():
        if _FENCE.match(line):
            fenced = not fenced
            continue
        m = None if fenced else re.match(r"^\s{0,3}#{1,6}\s+(.*?)\s*#*\s*$", line)
        if not m:
            continue
        base = slug(m.group(1))
        n = seen.get(base, 0)
        seen[base] = n + 1
        out.add(base if n == 0 else f"{base}-{n}")
    return out


def broken_links(path: Path, root: Path = ROOT) -> list[str]:
    """One message per link of ``path`` that leaves ``root``, names no existing file, or names a
    heading its Markdown target does not have."""
    problems = []
    root = root.resolve()
    for target in links(path):
        if _SCHEME.match(target):
            continue  # https:, mailto:, ... (not checked offline)
        file_part, _, fragment = target.partition("#")
        file_part = file_part.split("?", 1)[0]
        dest = (path.parent / file_part).resolve() if file_part else path.resolve()
        if not dest.is_relative_to(root):
            problems.append(f"{path.name}: {target!r} points outside the repository")
            continue
        if not dest.exists():
            problems.append(f"{path.name}: {target!r} names no file ({dest.relative_to(root)})")
            continue
        if fragment and dest.suffix.lower() == ".md" and fragment not in anchors(dest):
            problems.append(f"{path.name}: {target!r}: no heading #{fragment} in "
                            f"{dest.relative_to(root)}")
    return problems


@pytest.mark.parametrize("path", doc_files(), ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_point_to_files_in_the_repository(path):
    assert path.is_file()
    assert broken_links(path) == []


def test_docs_exist_and_readme_links_them():
    targets = links(ROOT / "README.md")
    assert "docs/scene-format.md" in targets
    assert "docs/method.md" in targets


def test_checker_flags_links_outside_missing_and_bad_anchors(tmp_path):
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "a.md").write_text("# Title\n\n## The `b` part\n", encoding="utf-8")
    readme = tmp_path / "README.md"
    readme.write_text(
        "See [fmt](../elsewhere/FORMAT.md), [gone](docs/missing.md), [ok](docs/a.md#the-b-part),\n"
        "[bad anchor](docs/a.md#nope), [web](https://example.org/x.md), ![img](docs/a.md)\n"
        "[ref]: ../outside.txt\n"
        "```\n[in code](nowhere.md)\n```\n"
        "and `[span](nowhere.md)` in inline code.\n",
        encoding="utf-8")
    problems = broken_links(readme, tmp_path)
    assert len(problems) == 4, problems
    assert sum("outside the repository" in p for p in problems) == 2
    assert any("docs/missing.md" in p and "names no file" in p for p in problems)
    assert any("#nope" in p for p in problems)
