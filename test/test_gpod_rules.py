"""GPOD's named rules (core/gpod/rules.py): the lists in `GpodConfig.rules`, their order,
and what a rule takes out of one frame's evidence or does to a nearest point."""
import numpy as np
import pytest

from asmonc_vision.core.config import override
from asmonc_vision.core.gpod import GpodConfig, rules
from asmonc_vision.core.gpod.settings import (DROP_RULE_NAMES, PIXEL_RULE_NAMES,
                                              PLACEMENT_RULE_NAMES, STRING_RULE_NAMES,
                                              RuleSettings)
from asmonc_vision.core.matching import Matches


def test_every_listed_rule_is_a_rule_and_every_rule_is_listed_by_default():
    assert tuple(rules.PIXEL_RULES) == PIXEL_RULE_NAMES == RuleSettings().pixels
    assert tuple(rules.STRING_RULES) == STRING_RULE_NAMES == RuleSettings().strings
    assert tuple(rules.DROP_RULES) == DROP_RULE_NAMES == RuleSettings().drops
    assert tuple(rules.PLACEMENT_RULES) == PLACEMENT_RULE_NAMES == RuleSettings().placement


def test_a_list_with_an_unknown_or_repeated_rule_is_refused():
    with pytest.raises(ValueError, match=r'GpodConfig\.rules\.pixels = \[.periodic.\]'):
        override(GpodConfig(), {'rules.pixels': ('periodic',)})
    with pytest.raises(ValueError, match=r'RuleSettings\.drops'):
        RuleSettings(drops=('ground_bend', 'ground_bend'))
    with pytest.raises(ValueError, match=r'RuleSettings\.strings'):
        RuleSettings(strings=('drop_region',))           # a rule of another list
    with pytest.raises(TypeError, match='list of rule names'):
        RuleSettings(pixels='string_pieces')
    assert RuleSettings(pixels=(), strings=(), drops=(), placement=()).pixels == ()


def test_rules_run_in_the_order_listed_and_only_those_listed():
    calls = []
    table = {name: (lambda c, ev, name=name: calls.append(name)) for name in 'abc'}
    rules.run_rules(GpodConfig(), ('c', 'a'), table, None)   # type: ignore[arg-type]
    assert calls == ['c', 'a']


def _evidence(d, rivals, pd, thr):
    """A frame's evidence with only what the pixel rules on rivals read: matches of
    disparities ``d`` with rivals (match, disparity, support ratio), every match both an
    obstacle and a drop pixel."""
    k = len(d)
    z = np.zeros(k, np.float32)
    r = np.asarray(rivals, np.float64).reshape(-1, 3)
    m = Matches(u_left=z + 50, u_right=z + 50 - d, v=np.arange(k, dtype=np.int32),
                d=np.asarray(d, np.float32), strength=z + 20, string_id=np.zeros(k, np.int32),
                left_index=np.arange(k, dtype=np.int32), right_index=np.arange(k, dtype=np.int32),
                support=z + 1, rival_match=r[:, 0].astype(np.int32),
                rival_d=r[:, 1].astype(np.float32), rival_ratio=r[:, 2].astype(np.float32))
    none = None
    return rules.FrameEvidence(
        m=m, el=none, er=none, cand=none, metric=none,  # type: ignore
        pd=np.full(k, pd), pts=np.zeros((k, 3)), h=np.zeros(k), excess=np.zeros(k),
        ex_mean=np.zeros(k), thr=np.full(k, thr), prev=np.full(k, -1),
        run=np.full(k, 5), usable=np.ones(k, bool), below=np.zeros(k, bool), slope=1.0,
        weight=np.ones(k), min_px=2.0, n_s=1, obst=np.ones(k, bool), drop=np.ones(k, bool))


def test_the_periodic_and_ambiguous_drop_rules_take_out_only_their_own_evidence():
    # match 0: two strong rivals a period either side, one on the ground (10 px): periodic;
    # match 1: one strong rival on the ground, nearer: no drop evidence, still an obstacle
    # pixel (a kerb's face has such a rival); match 2: no rival
    rivals = [(0, 10.2, 0.9), (0, 16.8, 1.1), (1, 10.1, 1.0)]
    c = GpodConfig()
    ev = _evidence([13.4, 4.6, 13.0], rivals, 10.0, 0.8)
    rules.run_rules(c, ('periodic_pattern',), rules.PIXEL_RULES, ev)
    assert ev.obst.tolist() == [False, True, True] and ev.drop.tolist() == [False, True, True]
    ev = _evidence([13.4, 4.6, 13.0], rivals, 10.0, 0.8)
    rules.run_rules(c, ('ambiguous_drop',), rules.PIXEL_RULES, ev)
    assert ev.obst.all() and ev.drop.tolist() == [True, False, True]
    ev = _evidence([13.4, 4.6, 13.0], rivals, 10.0, 0.8)
    rules.run_rules(c, (), rules.PIXEL_RULES, ev)                 # none listed: none run
    assert ev.obst.all() and ev.drop.all()


def test_a_placement_rule_moves_a_nearest_point_only_as_it_says():
    """`_nearer`: a placement rule's points replace those it sets, and, for the rules that
    may only reveal a nearer point (silhouettes, view_edge), only where nearer."""
    q = np.array([[2.0, 0.0], [3.0, 1.0], [4.0, 0.0]])
    new = np.array([[1.5, 0.0], [3.5, 1.0], [np.nan, np.nan]])
    np.testing.assert_array_equal(rules._nearer(q, new, True), [[1.5, 0.0], [3.0, 1.0],
                                                                [4.0, 0.0]])
    np.testing.assert_array_equal(rules._nearer(q, new, False), [[1.5, 0.0], [3.5, 1.0],
                                                                 [4.0, 0.0]])
    assert rules._nearer(q, np.full((3, 2), np.nan), False) is q

