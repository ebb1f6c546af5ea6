"""The repository states facts, not its development history.

No text file of the project (package, presets, tests, benchmarks, notebooks, README, CHANGELOG,
docs) may cite a past work period, a numbered tracker entry, or a path outside the repository such
as the folder of real recordings beside it: an installed package or a fresh clone has none of them.
"""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# Built from pieces so that this file does not match its own patterns.
_WORD = "sess" + "ion"
PATTERNS = [
    re.compile(r"\b" + _WORD + r"s?\b", re.IGNORECASE),
    re.compile(r"\b" + "iss" + r"ues? ?#?\d+", re.IGNORECASE),
    re.compile(r"\.\./" + "sha" + "red", re.IGNORECASE),
]

FILES = ["README.md", "CHANGELOG.md", "pyproject.toml"]
GLOBS = [
    "docs/**/*.md", "docs/**/*.ipynb",
    "benchmarks/**/*.py", "benchmarks/**/*.sh", "benchmarks/**/*.md",
    "fusiongs/**/*.py", "fusiongs/**/*.yaml",
    "notebooks/**/*.py",
    "tests/**/*.py",
]


def project_text_files() -> list[Path]:
    """The project's text files that exist (README, CHANGELOG and docs may be absent)."""
    paths = {ROOT / name for name in FILES}
    for pattern in GLOBS:
        paths.update(ROOT.glob(pattern))
    this = Path(__file__).resolve()
    return sorted(p for p in paths if p.is_file() and p.resolve() != this)


def history_mentions(path: Path) -> list[str]:
    """``file:line: text`` for every line of ``path`` that matches a pattern."""
    text = path.read_text(encoding="utf-8", errors="replace")
    rel = path.relative_to(ROOT).as_posix()
    return [f"{rel}:{n}: {line.strip()[:120]}" for n, line in enumerate(text.splitlines(), 1)
            if any(p.search(line) for p in PATTERNS)]


def test_patterns_match_history_and_not_api_names():
    word = "Sess" + "ion"
    hits = ["(RESULTS.md, " + word.lower() + " 49)", word + "s 12 and 58", "Iss" + "ue 14's target",
            "(iss" + "ue #15)", "../" + "shared/FORMAT.md"]
    for line in hits:
        assert any(p.search(line) for p in PATTERNS), line
    tissue = "t" + "iss" + "ue 3"
    for line in ["subprocess.Popen(cmd, start_new_" + word.lower() + "=True)", "the issuer", tissue]:
        assert not any(p.search(line) for p in PATTERNS), line


def test_no_development_history_in_project_files():
    files = project_text_files()
    assert any(p.name == "pyproject.toml" for p in files)
    found = [hit for path in files for hit in history_mentions(path)]
    assert not found, "development history in project files:\n" + "\n".join(found)
