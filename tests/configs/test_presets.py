"""Shipped YAML presets: package data, resolved by name or path (``--config deblur_fast``)."""

from __future__ import annotations

from pathlib import Path

import pytest

import fusiongs
from fusiongs.configs import config_dir, preset_names, resolve_config_path
from fusiongs.configs.load import load_config
from fusiongs.errors import InputError
from fusiongs.train.settings import DeblurConfig
from tests.conftest import REPO_ROOT

PRESETS = ["deblur", "deblur_fast", "deblur_quality", "event_only"]


def test_presets_are_package_data():
    assert config_dir() == Path(fusiongs.__file__).resolve().parent / "configs"
    assert preset_names() == PRESETS
    assert all((config_dir() / f"{n}.yaml").is_file() and not (config_dir() / f"{n}.yaml").is_symlink()
               for n in PRESETS)


@pytest.mark.parametrize("name", PRESETS)
@pytest.mark.parametrize("suffix", ["", ".yaml", ".yml"])
def test_a_bare_preset_name_resolves_with_or_without_suffix(name, suffix, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # anywhere, not only in the repository
    path = resolve_config_path(name + suffix)
    assert path == config_dir() / f"{name}.yaml"
    load_config(DeblurConfig, path)  # every preset is a valid config


def test_an_existing_path_wins_over_a_preset(tmp_path, monkeypatch):
    (tmp_path / "deblur_fast.yaml").write_text("optim:\n  iterations: 7\n")
    monkeypatch.chdir(tmp_path)
    assert resolve_config_path("deblur_fast.yaml") == Path("deblur_fast.yaml")
    assert resolve_config_path(tmp_path / "deblur_fast.yaml") == tmp_path / "deblur_fast.yaml"
    assert resolve_config_path("deblur_fast") == config_dir() / "deblur_fast.yaml"


@pytest.mark.parametrize("value", ["deblur_slow", "nowhere/deblur_fast.yaml", "deblur_fast.json", ""])
def test_unknown_names_and_missing_paths_list_the_presets(value):
    with pytest.raises(InputError, match=r"--config: config: expected an existing YAML file or a preset "
                       r"name \(deblur, deblur_fast, deblur_quality, event_only\)"):
        resolve_config_path(value)


@pytest.mark.parametrize("name", PRESETS)
def test_repository_configs_folder_links_to_the_package_presets(name):
    linked = REPO_ROOT / "configs" / f"{name}.yaml"
    assert linked.is_file() and linked.samefile(config_dir() / f"{name}.yaml")


@pytest.mark.parametrize("name", PRESETS)
def test_presets_have_no_repeated_keys(name):
    """PyYAML keeps the last of two equal keys silently; a preset must say each key once."""
    import yaml

    class Strict(yaml.SafeLoader):
        pass

    def mapping(loader, node):
        keys = [loader.construct_object(k) for k, _ in node.value]
        repeated = {k for k in keys if keys.count(k) > 1}
        assert not repeated, f"{name}.yaml repeats {sorted(repeated)}"
        return loader.construct_mapping(node)

    Strict.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, mapping)
    path = Path(config_dir()) / f"{name}.yaml"
    assert isinstance(yaml.load(path.read_text(), Loader=Strict), dict)
