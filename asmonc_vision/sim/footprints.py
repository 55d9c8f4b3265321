"""The obstacles' footprints on the ground, for scoring (docs/evaluation.md: "footprint").

``world_footprints(world)`` lists, per obstacle of a `World`, its outline on the ground
in world x, y (metres, z up): a box's (post, door, wall) rectangle, a cylinder's
(bollard, round post) circle as a 24-gon, a terrace's (kerb up, step down) polygon;
its height (a terrace's rise: negative for a drop); and when it exists. The bag writer
stores the list in the bag's metadata (``asmonc_vision.sim`` custom data, key
``footprints``), so that recorded runs can be scored against the true footprints.
"""
from __future__ import annotations

import math

import numpy as np

from asmonc_vision.sim.world import Cylinder, Terrace, World

#: corners of a cylinder's footprint polygon
CYLINDER_CORNERS = 24


def _seconds(x: float) -> float | None:
    return None if not math.isfinite(x) else float(x)


def world_footprints(world: World) -> list[dict]:
    """Footprints of every obstacle of ``world``, JSON-ready.

    Returns:
        one dict per obstacle, by id: ``id``, ``kind``, ``height`` (m; negative for a
        drop), ``polygon`` ([[x, y], ...] world metres, convex), ``appear_s`` and
        ``vanish_s`` (seconds of simulation time, None = always), ``ground_region``
        (True for a terrace: raised or lowered ground the wearer may stand on).
    """
    out = []
    for ob in world.obstacles:
        if isinstance(ob, Terrace):
            poly, height = np.asarray(ob.polygon, float), float(ob.rise)
        elif isinstance(ob, Cylinder):
            poly, height = ob.top_polygon(CYLINDER_CORNERS)[:, :2], float(ob.height)
        else:
            poly, height = np.asarray(ob.top_polygon(), float)[:, :2], float(ob.height)
        out.append({'id': int(ob.id), 'kind': ob.kind, 'height': round(height, 4),
                    'polygon': [[round(float(x), 4), round(float(y), 4)] for x, y in poly],
                    'appear_s': _seconds(ob.appear), 'vanish_s': _seconds(ob.vanish),
                    'ground_region': isinstance(ob, Terrace)})
    return out
