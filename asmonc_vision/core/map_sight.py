"""Sight lines of one stereo pair over the evidence map (`core.evidence_map`).

Two questions the map asks of each pair, answered here from the pair's matched points
alone:

* *seen through* (`seen_through`): did the pair see the ground behind a raised cell
  along sight lines that pass below the cell's top? A real thing hides the ground
  behind it; a mismatch floating above the ground (a repetitive pattern matched a
  period off) does not.
* *in plain view* (`in_both_images`, `passed_unhidden`): would the pair have seen a
  confirmed cell, were it still there? Its point lies inside both images, the pair
  matched something at its bearing beyond it, and nothing nearer at its bearing hides
  it.

Frames (REP 103): points on the ground are the pair's ground frame G (x ahead, y left,
m, origin below the left camera); points in 3-D are the left optical frame (x right,
y down, z forward, m).
"""
from __future__ import annotations

import numpy as np

from asmonc_vision.core import map_kernels
from asmonc_vision.core.camera import StereoCamera
from asmonc_vision.core.map_evidence import GROUND, RAISED
from asmonc_vision.core.map_settings import EvidenceMapConfig
from .npfast import linspace

#: bearings from -90 to 90 degrees in 1 degree bins (`passed_unhidden`)
BINS = 180


def seen_through(p: np.ndarray, top: np.ndarray, ground_xy: np.ndarray, cam_height: float,
                 n_own: np.ndarray, config: EvidenceMapConfig, use_kernel: bool = True
                 ) -> np.ndarray:
    """(M,) bool: the raised cells that this pair's ground matches saw through.

    The sight line from the camera (``cam_height`` m above the wearer's foot) to a
    ground point at range R passes over the ground at range r at
    ``h_ray = cam_height (1 - r / R)``. A sight line passing within ``ray_lateral_m`` of
    a cell's evidence point, lower than its top, went through where the thing was said
    to stand. A real thing hides the ground behind it; its silhouette edge (where its
    evidence is) is passed on its outer side only, and a thin post hides the sight
    lines through its middle. A mismatch floating above the ground is seen through on
    both sides: at least ``ray_min_pixels`` sight lines on each side in a pair, more in
    all than the cell's own raised pixels. The sight lines stop ``ray_stop_m`` short of
    their ground point and count from 0.3 m out.

    Args:
        p: (M, 2) float64 the cells' evidence points (their mean matched point), G, m.
        top: (M,) float64 the height below which a sight line passes through each cell
            (its height estimate less a margin), m.
        ground_xy: (N, 2) float64 the pair's ground matches, G, m (at most
            ``ray_max_points`` of them are used, evenly picked).
        cam_height: the camera's height above the ground plane, m.
        n_own: (M,) int the pair's own raised pixels in each cell.
        config: the map's settings (``ray_*``).
        use_kernel: use the compiled counts (`map_kernels.nb_rays`) when present; the
            numpy path gives the same counts.
    """
    c = config
    if ground_xy.shape[0] > c.ray_max_points:
        pick = linspace(0, ground_xy.shape[0] - 1, c.ray_max_points).astype(np.int64)
        ground_xy = ground_xy[pick]
    R = np.hypot(ground_xy[:, 0], ground_xy[:, 1])                 # (n,)
    gh = ground_xy / np.maximum(R, 1e-6)[:, None]                   # sight line directions
    if map_kernels.nb_rays is not None and use_kernel and gh.dtype == np.float64:
        # the same counts, compiled (`map_kernels.rays_kernel`)
        left, right = map_kernels.nb_rays(p, top.astype(np.float64), gh, R,
                                          float(cam_height), float(c.ray_lateral_m),
                                          float(c.ray_stop_m))
    else:
        # (m, n): each evidence point against each sight line
        along = p[:, 0:1] * gh[None, :, 0] + p[:, 1:2] * gh[None, :, 1]
        lateral = gh[None, :, 0] * p[:, 1:2] - gh[None, :, 1] * p[:, 0:1]
        h_ray = cam_height * (1.0 - along / R[None, :])
        through = ((np.abs(lateral) <= c.ray_lateral_m) & (along > 0.3)
                   & (along < R[None, :] - c.ray_stop_m) & (h_ray < top[:, None]))
        left = np.count_nonzero(through & (lateral > 0), axis=1)
        right = np.count_nonzero(through & (lateral <= 0), axis=1)
    return (np.minimum(left, right) >= c.ray_min_pixels) & (left + right > n_own)


def in_both_images(p: np.ndarray, cam: StereoCamera, margin_px: float) -> np.ndarray:
    """(M,) bool: points ``p`` (M, 3) of the left optical frame (m) that project
    ``margin_px`` or more inside both images (and lie more than 0.1 m ahead)."""
    z = np.maximum(p[:, 2], 1e-3)
    u, v = cam.project_left(np.column_stack([p[:, 0], p[:, 1], z]))
    return ((p[:, 2] > 0.1) & (u - cam.f * cam.baseline / z >= margin_px)
            & (u <= cam.width - 1 - margin_px) & (v >= margin_px)
            & (v <= cam.height - 1 - margin_px))


def bearing_bin(xy: np.ndarray) -> np.ndarray:
    """(N,) int64: the 1 degree bearing bin (0 .. BINS - 1) of ground points (N, 2)."""
    b = np.degrees(np.arctan2(xy[:, 1], xy[:, 0])) + 90.0
    # (ndarray.clip of the int64 bins, without its integer-bounds checks)
    return np.minimum(np.maximum(b.astype(np.int64), 0), BINS - 1)


def passed_unhidden(g: np.ndarray, ev_xy: np.ndarray, ev_kind: np.ndarray, cell_m: float
                    ) -> tuple[np.ndarray, np.ndarray]:
    """For cells at ``g`` (M, 2) (G, m): ``(passed, unhidden)``, (M,) bool each.

    ``passed``: the pair matched ground or a thing (``ev_kind`` GROUND or RAISED, at
    ``ev_xy`` (N, 2), G, m) at the cell's bearing at least ``cell_m`` beyond it (the
    sight line passed over it); ``unhidden``: it matched no raised point more than
    ``cell_m`` nearer at that bearing (nothing in front hides it). Bearings in 1 degree
    bins, each widened by one bin either side."""
    r, b = np.hypot(g[:, 0], g[:, 1]), bearing_bin(g)
    seen = (ev_kind == GROUND) | (ev_kind == RAISED)
    xy_seen = ev_xy[seen]
    er, eb = np.hypot(xy_seen[:, 0], xy_seen[:, 1]), bearing_bin(xy_seen)
    far = np.full(BINS + 2, -np.inf)
    np.maximum.at(far, eb + 1, er)
    near = np.full(BINS + 2, np.inf)
    raised = ev_kind[seen] == RAISED
    np.minimum.at(near, eb[raised] + 1, er[raised])
    far = np.maximum(np.maximum(far[:-2], far[1:-1]), far[2:])
    near = np.minimum(np.minimum(near[:-2], near[1:-1]), near[2:])
    return far[b] >= r + cell_m, near[b] >= r - cell_m
