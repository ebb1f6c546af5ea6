"""Atomic writes: the target is whole or untouched; a killed writer's temporary is recognisable and
cleared away by the next run."""

from __future__ import annotations

import pytest

from fusiongs.atomic import atomic_path, is_temporary, remove_temporaries, write_text


@pytest.mark.parametrize("name", ["checkpoint.pt", "history.jsonl", "report.png", "README"])
def test_the_writers_temporaries_are_recognised_and_targets_are_not(tmp_path, name):
    with atomic_path(tmp_path / name) as tmp:
        tmp.write_text("x")
        assert is_temporary(tmp) and tmp.parent == tmp_path
    assert not is_temporary(tmp_path / name)
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]


def test_a_failed_write_leaves_the_target_as_it_was(tmp_path):
    write_text(tmp_path / "a.json", "{}")
    with pytest.raises(RuntimeError), atomic_path(tmp_path / "a.json") as tmp:
        tmp.write_text('{"half')
        raise RuntimeError("killed")
    assert (tmp_path / "a.json").read_text() == "{}"
    assert [p.name for p in tmp_path.iterdir()] == ["a.json"]


def test_remove_temporaries_clears_leftovers_only(tmp_path):
    leftovers = [tmp_path / ".checkpoint.ab12_xyz.tmp.pt",
                 tmp_path / "renders" / ".novel_000.q1w2e3r4.tmp.png"]
    kept = [tmp_path / "checkpoint.pt", tmp_path / ".hidden", tmp_path / "notes.tmp",
            tmp_path / ".x.short.tmp.pt", tmp_path / "a" / "b" / ".deep.ab12_xyz.tmp.png"]
    for p in leftovers + kept:
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text("half")
    assert sorted(remove_temporaries(tmp_path)) == sorted(leftovers)  # depth 1: not a/b/
    assert not any(p.exists() for p in leftovers) and all(p.exists() for p in kept)
    assert remove_temporaries(tmp_path / "missing") == []
