"""Scene simulator: textured ray-cast worlds -> blurry frames, DVS events, trajectory, sharp truth.

The truth is not a Gaussian model (no inverse crime): photographs on planes and boxes, drawn by a
vectorised ray caster in linear light. ``simulate_scene(SimConfig(...))`` returns the ``Scene`` and
the sharp truth; ``write_simulated_scene`` writes the scene folder plus ``gt/<name>.png``.
``sweep_scene_config(seed, split)`` draws a scene and event sensor from a seeded sweep.
"""

from fusiongs.sim.dvs import DVSParams
from fusiongs.sim.presets import PRESETS, Preset, get_preset
from fusiongs.sim.simulate import SimConfig, SimResult, run_simulation, simulate_scene
from fusiongs.sim.sweep import SENSOR_RANGE, TEST_SEEDS, TUNING_SEEDS, draw_sensor, sweep_scene_config
from fusiongs.sim.write import write_simulated_scene

__all__ = ["DVSParams", "PRESETS", "Preset", "SENSOR_RANGE", "SimConfig", "SimResult", "TEST_SEEDS",
           "TUNING_SEEDS", "draw_sensor", "get_preset", "run_simulation", "simulate_scene",
           "sweep_scene_config", "write_simulated_scene"]
