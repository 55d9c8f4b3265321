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
