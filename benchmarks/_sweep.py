"""Shared pieces of the sweep benchmarks: a simulated scene's config, its sensor twins, the HPF floor."""

from __future__ import annotations

import json
from pathlib import Path

from fusiongs.io.truth import read_sim_facts

# ``--smoke`` of the benchmarks (CI's benchmarks/smoke.sh): SimConfig fields that make a scene tiny
# and cheap (48x36, 0.4 s, 5 frames; exposures up to 0.08 s still fit). Nothing is reported from it.
SMOKE_SCENE = {"width": 48, "height": 36, "duration": 0.4, "frames": 5, "novel": 1, "dvs_rate_hz": 500.0,
               "blur_samples": 6, "supersample": 1}


def smoke_config(cfg):
    """``cfg`` (a :class:`SimConfig`) shrunk by :data:`SMOKE_SCENE`, validated."""
    import dataclasses

    return dataclasses.replace(cfg, **SMOKE_SCENE).validate()


def sim_config(scene: Path):
    """The :class:`SimConfig` a simulated scene was written with (from ``gt/sim.json``)."""
    from fusiongs.sim.dvs import DVSParams
    from fusiongs.sim.simulate import SimConfig

    cfg = dict(json.loads((scene / "gt" / "sim.json").read_text())["config"])
    cfg["dvs"] = DVSParams(**cfg["dvs"])
    return SimConfig(**cfg)


def parse_sensor(sensor: str) -> dict[str, float]:
    """``"name=value,..."`` -> ``{name: value}`` for fields of :class:`fusiongs.sim.dvs.DVSParams`;
    raises ValueError naming the bad item."""
    import dataclasses

    from fusiongs.sim.dvs import DVSParams

    fields = {f.name for f in dataclasses.fields(DVSParams)}
    changes = {}
    for item in sensor.split(","):
        name, _, value = item.partition("=")
        if name not in fields:
            raise ValueError(f"--sensor: {name!r} is not a DVSParams field ({', '.join(sorted(fields))})")
        try:
            changes[name] = float(value)
        except ValueError:
            raise ValueError(f"--sensor: {name}: expected a number, got {value!r}") from None
    return changes


def resimulate(scene: Path, out: Path, sensor: str) -> Path:
    """Write ``scene`` again to ``out`` with some ``DVSParams`` fields changed (``sensor``:
    ``name=value,...``, e.g. ``refractory_s=0,ba_rate_hz=0``): the same seed, scene, camera path
    and thresholds, another sensor model, with its own ``gt/sim.json``. Returns ``out``."""
    import dataclasses

    from fusiongs.sim.simulate import run_simulation
    from fusiongs.sim.write import write_simulated_scene

    cfg = sim_config(scene)
    changes = parse_sensor(sensor)
    cfg = dataclasses.replace(cfg, dvs=dataclasses.replace(cfg.dvs, **changes))
    res = run_simulation(cfg)
    sweep = (read_sim_facts(scene) or {}).get("sweep")
    stats = res.stats | ({"sweep": sweep} if sweep else {})  # the twin's own facts, its sweep draw kept
    write_simulated_scene(res.scene, res.gt, out, stats=stats, overwrite=True)
    print(json.dumps({"resimulated": str(out), "events": len(res.scene.events), **changes}))
    return out


def hpf_floor(scene_path: Path, theta0: float = 0.22, tau: float = 0.05) -> dict[str, float]:
    """Affine-fit PSNR / SSIM of the HPF intensity image (the event-only anchor) at the held-out
    instants (:func:`fusiongs.eval.event_floor.leaky_integrator_floor`)."""
    from fusiongs.eval.event_floor import leaky_integrator_floor

    return leaky_integrator_floor(scene_path, theta0, tau)
