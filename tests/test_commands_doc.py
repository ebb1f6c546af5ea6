"""docs/commands.md and docs/configuration.md are what docs/gen_commands.py prints today.

Both pages are generated from the code (the argument parsers, the deblur settings and the presets),
so a changed option or help text must be followed by regenerating them.
"""

from __future__ import annotations

from pathlib import Path

from tests.conftest import docs_script

ROOT = Path(__file__).resolve().parents[1]


def load_generator():
    """docs/gen_commands.py as a module."""
    return docs_script("gen_commands")


def test_commands_md_is_generated_from_the_parsers():
    expected = load_generator().commands_markdown()
    actual = (ROOT / "docs" / "commands.md").read_text(encoding="utf-8")
    assert actual == expected, "docs/commands.md is stale: run python docs/gen_commands.py > docs/commands.md"


def test_configuration_md_is_generated_from_the_settings():
    expected = load_generator().configuration_markdown()
    actual = (ROOT / "docs" / "configuration.md").read_text(encoding="utf-8")
    assert actual == expected, ("docs/configuration.md is stale: run "
                                "python docs/gen_commands.py --config > docs/configuration.md")


def test_every_verb_has_a_section():
    from fusiongs.cli import VERBS

    text = load_generator().commands_markdown()
    for verb in VERBS:
        assert f"\n## fusiongs {verb}\n" in text
