"""The results of matching: candidate pairs, their support links, accepted matches."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Candidates:
    """Candidate matches, grouped by left edge (sorted by left index, then right index).

    Attributes:
        left: (M,) int64 (intp) index into the left EdgeMap.
        right: (M,) int64 (intp) index into the right EdgeMap.
        d: (M,) float64 sub-pixel disparity, pixels.
    """

    left: np.ndarray
    right: np.ndarray
    d: np.ndarray

    def __len__(self) -> int:
        return int(self.left.shape[0])


@dataclass(frozen=True)
class SupportLinks:
    """PMF neighbourhood: one link per (candidate, neighbouring left edge).

    Link q says: candidate ``cand[q]`` is supported by one neighbouring left edge, with
    the weight of the best *alive* one of the link's supporters. Supporter p belongs
    to link ``pair_link[p]`` (the supporters of a link are contiguous, from
    ``start[q]``): candidate ``pair_cand[p]`` = (``pair_edge[p]``, ``pair_right[p]``)
    of the neighbouring edge, whose cyclopean position is within the support radius of
    the supported candidate's and which satisfies the disparity-gradient limit with it;
    ``weight[p]`` is ``1 / cyclopean separation``. Links without supporters are not
    stored. The first ``num_single`` links have one supporter each (link q is supporter
    q); links are in no particular order of candidate.

    Attributes:
        num_candidates: M.
        cand: (Q,) int64 supported candidate.
        start: (Q,) int64 index of the link's first supporter (ascending).
        pair_link: (P,) int64 link of each supporter (ascending).
        pair_cand: (P,) int64 supporting candidate (index into the Candidates).
        pair_edge: (P,) int64 its left edge (index into the left EdgeMap).
        pair_right: (P,) int64 its right edge (index into the right EdgeMap).
        weight: (P,) float64 ``1 / distance`` between the two candidates' cyclopean
            positions, 1/pixels.
        num_single: how many of the links, first, have a single supporter (0: unknown).
    """

    num_candidates: int
    cand: np.ndarray
    start: np.ndarray
    pair_link: np.ndarray
    pair_cand: np.ndarray
    pair_edge: np.ndarray
    pair_right: np.ndarray
    weight: np.ndarray
    num_single: int = 0

    def __len__(self) -> int:
        return int(self.cand.shape[0])


@dataclass(frozen=True)
class Matches:
    """Accepted edge matches of one stereo pair.

    Attributes:
        u_left: (K,) float32 sub-pixel column in the left image, pixels.
        u_right: (K,) float32 sub-pixel column in the right image, pixels.
        v: (K,) int32 row (the same in both rectified images).
        d: (K,) float32 disparity ``u_left - u_right``, pixels.
        strength: (K,) float32 mean edge strength of the two edges, grey levels / pixel.
        string_id: (K,) int32 edge-string id of the left edge (see EdgeMap).
        left_index: (K,) int32 index into the left EdgeMap.
        right_index: (K,) int32 index into the right EdgeMap.
        support: (K,) float32 final PMF support.
        precision: (K,) float32 ``1 / sqrt(1/cL^2 + 1/cR^2)`` of the left and right edges'
            curvatures c (``EdgeMap.curvature``): the disparity's noise is about
            ``0.7 * gradient noise / precision`` pixels. None if unknown.
        rival_match, rival_d, rival_ratio: the rivals of the matches (`match_rivals`),
            one entry each: (R,) int32 the match it rivals (ascending), (R,) float32 its
            disparity, pixels, and (R,) float32 its first-round PMF support over the
            match's. None if unknown.
    """

    u_left: np.ndarray
    u_right: np.ndarray
    v: np.ndarray
    d: np.ndarray
    strength: np.ndarray
    string_id: np.ndarray
    left_index: np.ndarray
    right_index: np.ndarray
    support: np.ndarray
    precision: np.ndarray | None = None
    rival_match: np.ndarray | None = None
    rival_d: np.ndarray | None = None
    rival_ratio: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.v.shape[0])

    @property
    def u(self) -> np.ndarray:
        """(K,) float64 cyclopean column ``(u_left + u_right) / 2``, pixels."""
        return 0.5 * (self.u_left.astype(np.float64) + self.u_right)
