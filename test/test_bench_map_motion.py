"""The map's motion in the offline runs: late (as the graph has it) or the pair's own."""
from __future__ import annotations

from pathlib import Path

import pytest

from asmonc_vision.eval import bench
from asmonc_vision.io.frames import load_frames

BAG = Path(__file__).resolve().parents[1] / 'bags' / 'walk_obstacles'


@pytest.mark.parametrize('lag, waits, measured_all', [(2, False, False), (0, True, True)])
def test_map_motion_is_late_or_the_pairs_own(monkeypatch, lag, waits, measured_all):
    made, orig = [], bench.make_method

    def make(*a, **k):
        made.append(orig(*a, **k))
        return made[-1]

    monkeypatch.setattr(bench, 'make_method', make)
    frames = load_frames(BAG, 12)
    runs = bench.run_method(frames, 'gpod', map_enabled=True, egomotion=True,
                            motion_lag=lag, map_waits=waits)
    assert len(runs) == 12
    pred = made[0].motion_predictor
    assert pred is not None and pred.predictions >= 8
    # waiting, every pair after the first is placed by its own measured pose; two pairs
    # late, none is
    assert (pred.measured == pred.predictions) is measured_all
    assert (pred.measured == 0) is not measured_all


def test_the_surface_is_carried_by_the_maps_motion_asked_once_a_pair(monkeypatch):
    """The ground surface (`core.surface_tracking`) takes the map's predicted motion:
    the predictor is asked once per pair (it keeps the pose it gave), and the detector's
    tracker gets a motion for the pairs after the first."""
    from asmonc_vision.core import surface_tracking
    made, orig = [], bench.make_method
    given, updates = [], surface_tracking.SurfaceTracker.update

    def make(*a, **k):
        made.append(orig(*a, **k))
        return made[-1]

    def update(self, surface, motion, min_bend_m):
        given.append(motion)
        return updates(self, surface, motion, min_bend_m)

    monkeypatch.setattr(bench, 'make_method', make)
    monkeypatch.setattr(surface_tracking.SurfaceTracker, 'update', update)
    frames = load_frames(BAG, 12)
    bench.run_method(frames, 'gpod', map_enabled=True, egomotion=True, motion_lag=1)
    pred = made[0].motion_predictor
    calls = []
    monkeypatch.setattr(pred, 'predict', lambda *a, **k: calls.append(a) or None)
    assert len(given) >= 8 and sum(m is not None for m in given) >= 6
    # a fresh pair through Perception: predict is called exactly once
    made[0].process(frames[-1].left, frames[-1].right, frames[-1].cam,
                    stamp_ns=frames[-1].stamp_ns + 100_000_000)
    assert len(calls) == 1
