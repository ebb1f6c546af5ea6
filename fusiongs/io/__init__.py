"""Scene folders (docs/scene-format.md, version 1): ``Scene``, ``load_scene`` and ``save_scene``."""

from fusiongs.io.scene import RenderRequest, Scene
from fusiongs.io.scene_io import load_scene, read_scene_spec, save_scene

__all__ = ["RenderRequest", "Scene", "load_scene", "read_scene_spec", "save_scene"]
