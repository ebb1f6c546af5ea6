"""Typed YAML configs: unknown keys, types, overrides, round trip."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import pytest

from fusiongs.configs.load import config_from_dict, load_config, save_config, to_yaml
from fusiongs.errors import ConfigError


@dataclass
class Loss:
    kind: Literal["mse", "band", "pvc"] = "band"
    beta: float = 0.5
    weights: tuple[float, float, float] = (0.4, 0.2, 0.4)


@dataclass
class Threshold:
    grid: tuple[int, int] | None = None
    init: float = 0.25


@dataclass
class Cfg:
    steps: int = 100
    name: str = "run"
    verbose: bool = False
    out: Path = Path("out")
    loss: Loss = field(default_factory=Loss)
    threshold: Threshold | None = None
    tags: list[str] = field(default_factory=list)
    extra: dict[str, int] = field(default_factory=dict)


def _write(tmp_path, text):
    p = tmp_path / "cfg.yaml"
    p.write_text(text)
    return p


def test_defaults_without_file():
    assert load_config(Cfg) == Cfg()


def test_file_values_and_nested_merge_keep_defaults(tmp_path):
    p = _write(tmp_path, "steps: 7\nloss:\n  beta: 0\n")
    cfg = load_config(Cfg, p)
    assert cfg.steps == 7 and cfg.loss.beta == 0.0 and isinstance(cfg.loss.beta, float)
    assert cfg.loss.kind == "band"


def test_unknown_key_error_names_file_key_and_valid_keys(tmp_path):
    p = _write(tmp_path, "loss:\n  betta: 0.1\n")
    with pytest.raises(ConfigError) as e:
        load_config(Cfg, p)
    msg = str(e.value)
    assert str(p) in msg and "loss.betta" in msg and "kind, beta, weights" in msg


def test_wrong_type_is_named(tmp_path):
    p = _write(tmp_path, "steps: ten\n")
    with pytest.raises(ConfigError, match=r"cfg.yaml: steps: expected an integer, got 'ten'"):
        load_config(Cfg, p)
    with pytest.raises(ConfigError, match="verbose: expected true or false"):
        config_from_dict(Cfg, {"verbose": 1})
    with pytest.raises(ConfigError, match="steps: expected an integer"):
        config_from_dict(Cfg, {"steps": True})


def test_literal_and_tuple_length_checked():
    with pytest.raises(ConfigError, match=r"loss.kind: expected one of 'mse', 'band', 'pvc'"):
        config_from_dict(Cfg, {"loss": {"kind": "l2"}})
    with pytest.raises(ConfigError, match=r"loss.weights: expected a list of 3 items"):
        config_from_dict(Cfg, {"loss": {"weights": [1, 2]}})
    with pytest.raises(ConfigError, match=r"loss.weights\[1\]: expected a number"):
        config_from_dict(Cfg, {"loss": {"weights": [1, "x", 2]}})


def test_float_accepts_int_and_exponent_string():
    cfg = config_from_dict(Cfg, {"loss": {"beta": "1e-3"}})
    assert cfg.loss.beta == 1e-3


def test_override_nested_key_and_optional_dataclass(tmp_path):
    p = _write(tmp_path, "steps: 7\n")
    cfg = load_config(Cfg, p, ["loss.kind=mse", "steps=9", "threshold.grid=[6, 8]", "tags=[a, b]"])
    assert cfg.loss.kind == "mse" and cfg.steps == 9
    assert cfg.threshold == Threshold(grid=(6, 8)) and cfg.tags == ["a", "b"]


def test_override_errors_name_the_override():
    with pytest.raises(ConfigError, match=r"override 'loss.kindd=mse': loss.kindd: expected one of the keys"):
        load_config(Cfg, None, ["loss.kindd=mse"])
    with pytest.raises(ConfigError, match=r"override 'steps=1.5': steps: expected an integer"):
        load_config(Cfg, None, ["steps=1.5"])
    with pytest.raises(ConfigError, match="dotted.key=value"):
        load_config(Cfg, None, ["steps"])


def test_bad_yaml_and_non_mapping_file(tmp_path):
    with pytest.raises(ConfigError, match="valid YAML"):
        load_config(Cfg, _write(tmp_path, "steps: [1\n"))
    with pytest.raises(ConfigError, match="mapping"):
        load_config(Cfg, _write(tmp_path, "- 1\n- 2\n"))
    with pytest.raises(ConfigError, match="readable"):
        load_config(Cfg, tmp_path / "missing.yaml")


def test_missing_required_value_is_named():
    @dataclass
    class Req:
        scene: str
        steps: int = 1

    with pytest.raises(ConfigError, match="scene: expected a value"):
        config_from_dict(Req, {})
    assert config_from_dict(Req, {"scene": "a"}).scene == "a"


def test_round_trip_dump_then_load_is_equal(tmp_path):
    cfg = load_config(Cfg, None, ["threshold.grid=[6,8]", "loss.beta=0.125", "out=/x/y", "extra={a: 1}",
                                  "tags=[t]", "verbose=true"])
    path = save_config(cfg, tmp_path / "sub" / "resolved.yaml")
    assert load_config(Cfg, path) == cfg
    assert "loss:" in to_yaml(cfg)
    assert [p.name for p in path.parent.iterdir()] == ["resolved.yaml"]  # no temp file left
