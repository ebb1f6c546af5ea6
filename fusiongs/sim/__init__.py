"""Scene simulator: textured ray-cast worlds -> blurry frames, DVS events, trajectory, sharp truth.

The truth is not a Gaussian model (no inverse crime): photographs on planes and boxes, drawn by a
vectorised ray caster in linear light. ``simulate_scene(SimConfig(...))`` returns the ``Scene`` and
the sharp truth; ``write_simulated_scene`` writes the scene folder plus ``gt/<name>.png``.
"""

from fusiongs.sim.dvs import DVSParams
from fusiongs.sim.presets import PRESETS, Preset, get_preset
from fusiongs.sim.simulate import SimConfig, SimResult, run_simulation, simulate_scene
from fusiongs.sim.write import write_simulated_scene

__all__ = ["DVSParams", "PRESETS", "Preset", "SimConfig", "SimResult", "get_preset", "run_simulation",
           "simulate_scene", "write_simulated_scene"]
