"""Row-wise stereo matching of vertical edges with PMF (Pollard, Mayhew & Frisby 1985).

After Pollard, Mayhew & Frisby (PMF, 1985), as used by GPOD (Molton et al. 1998, Sec. 2.1):

1. Candidates (:func:`candidate_matches`): every left edge is paired with the right edges
   of the same row whose disparity ``d = u_left - u_right`` lies in ``[d_min, d_max]``,
   of the same polarity, with compatible strength (ratio of the weaker to the stronger at
   least ``min_strength_ratio``) and orientation (gradient directions within
   ``max_orientation_diff_deg``).
2. Support (:func:`support_links`, :func:`pmf_support`), as published: a candidate
   c = (e, r) is supported by the candidates c' of the *other* left edges whose
   cyclopean positions ``((u_left + u_right) / 2, v)`` lie within ``support_radius`` of
   c's (the cyclopean image) and that satisfy the disparity-gradient limit with it,
   ``|d' - d| <= limit * |cyclopean separation|`` (limit 1 in PMF); each contributes
   ``1 / separation``, and each neighbouring left edge contributes at most once, with its
   best such match. (Candidates sharing an edge with c have a disparity gradient of 2
   and never support it.)
3. Selection (:func:`select_matches`), PMF's iterative winner-take-all with uniqueness:
   a candidate is accepted when its support is above ``min_support`` and strictly the
   largest among the live candidates of both its left and its right edge; the
   competitors of accepted matches (other candidates of their left or right edge) are
   removed, and the support is recomputed from what is left -- a neighbouring edge that
   has been matched supports only through its accepted match -- for ``iterations``
   rounds.

4. Rivals (:func:`match_rivals`): for each accepted match, the other candidates of its
   left and right edge, with their first-round support (every candidate alive) over the
   match's: a uniqueness ratio, by which the user may call a match ambiguous (a
   periodic pattern supports candidates a period apart alike).

Disparities are sub-pixel, from the sub-pixel edge positions in both images.

The pair, grouping, selection and rival loops run compiled by numba when it is installed
(:func:`warm_up`), with the numpy paths' tests and order of summation: identical results.
"""
from asmonc_vision.core.matching.candidates import (candidate_matches, disc_offsets,
                                                   disparity_gradient_interval)
from asmonc_vision.core.matching.kernels import warm_up
from asmonc_vision.core.matching.selection import (match_edges, match_rivals, pmf_match,
                                                   select_matches)
from asmonc_vision.core.matching.support import pmf_support, support_links
from asmonc_vision.core.matching.types import Candidates, Matches, SupportLinks

__all__ = ['Candidates', 'SupportLinks', 'Matches', 'candidate_matches', 'disc_offsets',
           'disparity_gradient_interval', 'support_links', 'pmf_support', 'select_matches',
           'pmf_match', 'match_edges', 'match_rivals', 'warm_up']
