"""Tall things that move (`core.moving_reports.TallReports`): which detector reports pass
the evidence map unconfirmed. No ROS."""
import math

import numpy as np
import pytest

from asmonc_vision.core.map_settings import EvidenceMapConfig
from asmonc_vision.core.moving_reports import MAX_GAP_S, ChainedReports, TallReports

DT = 0.1


def tall(**kw):
    c = dict(pass_height_m=1.0, pass_frames=2, moving_min_height_m=0.6, moving_frames=3,
             moving_gate_m=0.3, moving_max_speed_mps=4.0, moving_max_range_m=4.5)
    c.update(kw)
    return TallReports(**c)


def feed(t, seq):
    """Each item: list of (height, range, bearing_deg); returns one bool array per pair."""
    out = []
    for i, reps in enumerate(seq):
        h = np.array([r[0] for r in reps], float)
        rg = np.array([r[1] for r in reps], float)
        b = np.radians([r[2] for r in reps]) if reps else np.zeros(0)
        out.append(t.passing(i * DT, h, rg, b))
    return out


def test_a_passer_by_coming_towards_the_wearer_passes_from_the_third_pair():
    # legs 0.8 m up, 4.4 m ahead, closing at 2.5 m/s (0.25 m a pair), swaying 5 cm
    seq = [[(0.8, 4.4 - 0.25 * i, 3.0 * (-1) ** i)] for i in range(6)]
    got = [bool(p[0]) for p in feed(tall(), seq)]
    assert got == [False, False, True, True, True, True]


def test_a_passer_by_first_seen_far_off_passes_in_time_with_the_map_defaults():
    """people_towards 1022's passer-by, found from 5.4 m on and closing at 2.5 m/s: with
    the map's settings its legs pass from 4.4 m (0.76 s before 2.5 m), counted from 5 m."""
    t = TallReports.from_config(EvidenceMapConfig())
    seq = [[(0.8, 5.4 - 0.25 * i, 2.0 * (-1) ** i)] for i in range(8)]
    got = [bool(p[0]) for p in feed(t, seq)]
    assert got.index(True) == 4 and all(got[4:])


def test_reports_that_jump_about_never_pass():
    # 0.8 m "things" 1.2 m or more from the one of the pair before: no walker moves so
    rng = np.random.default_rng(3)
    seq = [[(0.8, 2.0 + 1.2 * (i % 2) + rng.uniform(0, 0.2), 40.0 * (i % 3 - 1))]
           for i in range(8)]
    assert not any(p.any() for p in feed(tall(), seq))


@pytest.mark.parametrize('height,rng_m', [(0.5, 3.0), (0.8, 5.0), (-0.8, 3.0),
                                          (math.nan, 3.0)])
def test_low_far_drop_or_unknown_reports_never_chain(height, rng_m):
    seq = [[(height, rng_m, 0.0)] for _ in range(6)]
    assert not any(p.any() for p in feed(tall(), seq))


def test_a_report_as_tall_as_pass_height_passes_in_its_second_pair_however_far():
    got = feed(tall(), [[(1.2, 7.0, 0.0)], [(0.3, 2.0, 0.0), (1.0, 6.9, 3.0)],
                        [(1.9, 1.6, 10.0)]])
    assert got[0].tolist() == [False]
    assert got[1].tolist() == [False, True]
    assert got[2].tolist() == [False]          # one pair's ghost, far from the last
    got = feed(tall(pass_frames=1), [[(1.2, 7.0, 0.0)]])
    assert got[0].tolist() == [True]


def test_a_gap_in_time_breaks_the_chain():
    t = tall()
    h, b = np.array([0.8]), np.zeros(1)
    assert not t.passing(0.0, h, np.array([3.0]), b).any()
    assert not t.passing(0.1, h, np.array([2.9]), b).any()
    assert not t.passing(0.2 + MAX_GAP_S, h, np.array([2.8]), b).any()  # a new chain
    assert not t.passing(0.3 + MAX_GAP_S, h, np.array([2.7]), b).any()
    assert t.passing(0.4 + MAX_GAP_S, h, np.array([2.6]), b).all()


def test_a_chain_follows_the_nearest_of_several_and_reset_forgets():
    t = tall()
    seq = [[(0.8, 3.0, 0.0), (0.7, 3.0, 60.0)], [(0.8, 2.8, 0.0)], [(0.8, 2.6, 0.0)]]
    got = feed(t, seq)
    assert got[2].tolist() == [True]
    t.reset()
    assert not t.passing(0.3, np.array([0.8]), np.array([2.4]), np.zeros(1)).any()


def test_off_switches():
    seq = [[(0.8, 3.0, 0.0), (1.5, 3.0, 30.0)] for _ in range(5)]
    got = feed(tall(moving_min_height_m=0.0, pass_height_m=0.0), seq)
    assert not any(p.any() for p in got)
    got = feed(tall(moving_frames=1), [[(0.8, 3.0, 0.0)]])
    assert got[0].all()
    with pytest.raises(ValueError, match='pass_frames'):
        EvidenceMapConfig(pass_frames=0)


def test_built_from_the_map_settings():
    c = EvidenceMapConfig()
    t = TallReports.from_config(c)
    assert (t.pass_height_m, t.pass_frames, t.moving_min_height_m, t.moving_frames,
            t.moving_gate_m, t.moving_max_speed_mps, t.moving_max_range_m) == (
        c.pass_height_m, c.pass_frames, c.moving_min_height_m, c.moving_frames,
        c.moving_gate_m, c.moving_max_speed_mps, c.moving_max_range_m)
    with pytest.raises(ValueError, match='moving_frames'):
        EvidenceMapConfig(moving_frames=0)


def test_while_the_map_is_down_a_report_goes_out_once_chained_over_unmapped_frames():
    """A box the wearer walks up to (closing 0.12 m a pair) goes out from its third pair,
    a drop at once (`unmapped_drop_frames` 1); a raised ghost of one pair (a mismatch 3.3
    m ahead, beside where a drop was) never; unknown ground ahead at once; a time gap
    breaks the chain; 1 pair = every report."""
    c = ChainedReports.from_config(EvidenceMapConfig())
    assert (c.frames, c.drop_frames) == (3, 1)
    seq = [[(0.12, 4.0 - 0.12 * i, 5.0), (-0.15, 3.0 - 0.12 * i, -20.0)] for i in range(5)]
    seq[2] = seq[2] + [(0.3, 2.8, -20.0), (math.nan, 4.4, 0.0)]
    got = feed(c, seq)
    assert [p[:2].tolist() for p in got] == [[False, True]] * 2 + [[True, True]] * 3
    assert got[2][2:].tolist() == [False, True]   # a raised ghost does not chain on drops
    c.reset()
    h, r, b = np.array([0.12]), np.array([4.0]), np.zeros(1)
    assert [bool(c.passing(t, h, r, b)[0]) for t in (0.0, 0.1, 0.2)] == [False, False, True]
    assert not c.passing(0.2 + MAX_GAP_S + 0.1, h, r, b)[0]
    assert ChainedReports(1, 1, 0.3, 4.0).passing(0.0, h, r, b).all()
    assert not ChainedReports(3, 2, 0.3, 4.0).passing(0.0, -h, r, b).any()


def test_while_the_map_is_down_a_narrow_drop_is_chained_as_a_raised_report():
    """kerb_ramp 900017 (chest rig): a 35 cm deep patch 0.55 m wide, 4.5 m ahead, in the
    one pair whose plane rose 9 cm, went out as a drop while the map was down; a step
    down across the path is reported wide (step_down 1011: 3.9 m) and goes out at once."""
    c = ChainedReports.from_config(EvidenceMapConfig())
    assert c.drop_min_width_m == EvidenceMapConfig().unmapped_drop_min_width_m == 1.0
    h, r, b = np.array([-0.35, -0.21]), np.array([4.5, 3.6]), np.array([0.1, -0.1])
    w = np.array([0.55, 3.87])
    assert c.passing(0.0, h, r, b, w).tolist() == [False, True]
    # the narrow one goes out once it ends a chain of unmapped_frames (3) pairs
    assert c.passing(0.1, h, r - 0.12, b, w).tolist() == [False, True]
    assert c.passing(0.2, h, r - 0.24, b, w).tolist() == [True, True]
    # without widths every drop is wide; 0 m: every drop at once
    c.reset()
    assert c.passing(0.0, h, r, b).all()
    c0 = ChainedReports(3, 1, 0.3, 4.0, 0.0)
    assert c0.passing(0.0, h, r, b, w).all()
    # raised reports are not changed by it
    c.reset()
    assert not c.passing(0.0, -h, r, b, w).any()
