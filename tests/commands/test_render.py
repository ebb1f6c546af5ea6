"""``fusiongs render``: instants outside the recording are refused, not clamped."""

from __future__ import annotations

import pytest

from fusiongs.commands.render import check_instants
from fusiongs.errors import InputError


def test_instants_inside_the_range_pass():
    check_instants([0.0, 0.05, 0.12], 0.0, 0.12)


@pytest.mark.parametrize("bad", [-0.01, 0.1201, 7.5, float("nan"), float("inf")])
def test_instants_outside_the_range_name_the_flag_value_and_range(bad):
    with pytest.raises(InputError) as e:
        check_instants([0.05, bad], 0.0, 0.12)
    msg = str(e.value)
    assert "--t" in msg and f"{bad:g}" in msg and "[0, 0.12] s" in msg


def test_every_verb_spells_the_output_option_the_same():
    from fusiongs.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "verb")
    for verb, p in sub.choices.items():
        opts = {s for a in p._actions for s in a.option_strings}
        if "-o" in opts:
            assert "--output" in opts, verb
