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


def test_deblur_print_config_shows_the_merged_config(capsys):
    import yaml

    from fusiongs.cli import main

    assert main(["deblur", "scene-not-read", "--config", "deblur_fast", "--print-config",
                 "optim.iterations=7"]) == 0
    doc = yaml.safe_load(capsys.readouterr().out)
    assert doc["optim"]["iterations"] == 7  # the override
    assert doc["densify"]["max_gaussians"] == 10000  # from the deblur_fast preset
    assert main(["deblur", "scene-not-read"]) == 2  # no -o and no --print-config
