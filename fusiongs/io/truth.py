"""What a simulated scene knows about itself: ``SCENE/gt/sim.json`` (true sensor thresholds)."""

from __future__ import annotations

import json
from pathlib import Path

from fusiongs.events.thresholds import SensorThresholds


def read_sim_facts(scene_path: str | Path) -> dict | None:
    """``gt/sim.json`` of a scene folder (or of the folder of a ``scene.json``), None when absent
    or unreadable (a scene without simulator truth)."""
    p = Path(scene_path)
    root = p.parent if p.name == "scene.json" else p
    try:
        doc = json.loads((root / "gt" / "sim.json").read_text())
    except (OSError, ValueError):
        return None
    return doc if isinstance(doc, dict) else None


def true_thresholds(scene_path: str | Path, cfa: str | None) -> SensorThresholds | None:
    """The simulator's nominal ON / OFF thresholds (the same for every channel), or None."""
    facts = read_sim_facts(scene_path)
    if facts is None:
        return None
    try:
        tp, tn = float(facts["theta_on"]), float(facts["theta_off"])
    except (KeyError, TypeError, ValueError):
        return None
    if not (tp > 0 and tn > 0):
        return None
    return SensorThresholds.uniform(tp, tn, cfa, method="simulator truth")
