"""Whole-grid operations of the evidence map (`core.evidence_map`), on the part that holds
something.

The map's grid is n x n cells (180 x 180 by default), and a pair's evidence, or the
confirmed cells, lie in a small part of it. A square dilation, a labelling of connected
regions and a shift of the grid are done here on the bounding box of the non-zero cells
(padded by the dilation's reach): the results are those of the whole grid, cell for cell
(test_evidence_map compares both), without the work on the empty rest.
"""
from __future__ import annotations

import cv2
import numpy as np
from .npfast import flat_nonzero


def nonzero_box(mask: np.ndarray, pad: int = 0, align: int = 1
                ) -> tuple[int, int, int, int] | None:
    """The bounding box of the non-zero cells of a 2-D ``mask``, grown by ``pad`` cells on
    each side and clipped to the grid: (y0, y1, x0, x1), rows ``y0:y1`` and columns
    ``x0:x1``; ``y0`` and ``x0`` rounded down to a multiple of ``align``. None when the
    mask is all zero."""
    # the non-zero cells' flat indices, in row-major order: the first and the last are
    # in the first and the last row that hold any, their columns' extremes are the
    # box's (the rows and columns that ``mask.any`` would find, without its two passes)
    return cells_box(flat_nonzero(mask), mask.shape, pad, align)


def cells_box(nz: np.ndarray, shape: tuple[int, int], pad: int = 0, align: int = 1
              ) -> tuple[int, int, int, int] | None:
    """`nonzero_box` of a 2-D mask of ``shape`` whose non-zero cells are the flat indices
    ``nz`` ((K,) int, ascending)."""
    if not nz.size:
        return None
    n1 = shape[1]
    cols = nz % n1
    row0, row1 = int(nz[0]) // n1, int(nz[-1]) // n1
    y0, x0 = max(row0 - pad, 0), max(int(cols.min()) - pad, 0)
    y0 -= y0 % align
    x0 -= x0 % align
    return (y0, min(row1 + pad + 1, shape[0]),
            x0, min(int(cols.max()) + pad + 1, shape[1]))


def dilate(mask: np.ndarray, radius: int, whole: bool = False) -> np.ndarray:
    """(n0, n1) uint8: ``cv2.dilate`` of the 2-D ``mask`` (bool or uint8) by a square of
    side ``2 radius + 1`` (1 where a non-zero cell lies within ``radius`` cells in x and
    in y), worked out on the box of the non-zero cells only (``whole``: on the whole
    grid; the same result)."""
    m8 = mask.astype(np.uint8)
    k = np.ones((2 * radius + 1, 2 * radius + 1), np.uint8)
    if whole:
        return cv2.dilate(m8, k)
    out = np.zeros_like(m8)
    box = nonzero_box(m8, radius)
    if box is not None:
        y0, y1, x0, x1 = box
        out[y0:y1, x0:x1] = cv2.dilate(m8[y0:y1, x0:x1], k)
    return out


def label_regions(mask: np.ndarray, join_cells: int, whole: bool = False,
                  cells: np.ndarray | None = None) -> list[np.ndarray]:
    """Flat cell indices (int64, ascending) of each region of the 2-D bool ``mask``:
    8-connected, gaps of ``join_cells`` cells bridged (the mask dilated by that many
    before the labelling; only the mask's own cells are returned), in the order of
    ``cv2.connectedComponents``' labels over the whole grid. Worked out on the box of the
    mask's cells (its corner on even rows and columns: the labelling scans 2 x 2 blocks,
    so its labels come in the same order as over the whole grid); ``whole``: on the
    whole grid. ``cells``: the mask's cells as flat indices ((K,) int, ascending), when
    known (the box found from them)."""
    n0, n1 = mask.shape
    if whole:
        box: tuple[int, int, int, int] | None = (0, n0, 0, n1)
    elif cells is not None:
        box = cells_box(cells, (n0, n1), join_cells, align=2)
    else:
        box = nonzero_box(mask, join_cells, align=2)
    if box is None:
        return []
    y0, y1, x0, x1 = box
    sub = mask[y0:y1, x0:x1]
    m8: np.ndarray = sub.astype(np.uint8)
    if join_cells > 0:
        k = 2 * join_cells + 1
        m8 = cv2.dilate(m8, np.ones((k, k), np.uint8))
    _, lab = cv2.connectedComponents(m8, connectivity=8)
    flat = np.where(sub, lab, 0).reshape(-1)
    local = flat_nonzero(flat)
    if not local.size:
        return []
    order = np.argsort(flat[local], kind='stable')
    labels = flat[local][order]
    w = x1 - x0
    cells = (local // w + y0) * n1 + (local % w + x0)
    cells = cells[order]
    starts = flat_nonzero(np.concatenate(([True], labels[1:] != labels[:-1])))
    return np.split(cells, starts[1:])


def shift(a: np.ndarray, dy: int, dx: int, fill) -> None:
    """Shift array ``a`` (first two axes [y, x]) in place so that new[i, j] = old[i + dy,
    j + dx] (the grid's origin moved by (dy, dx) cells), filling the
    cells shifted in with ``fill``."""
    n0, n1 = a.shape[0], a.shape[1]
    out = np.full_like(a, fill)
    ys = slice(max(dy, 0), n0 + min(dy, 0))
    yd = slice(max(-dy, 0), n0 + min(-dy, 0))
    xs = slice(max(dx, 0), n1 + min(dx, 0))
    xd = slice(max(-dx, 0), n1 + min(-dx, 0))
    if abs(dy) < n0 and abs(dx) < n1:
        out[yd, xd] = a[ys, xs]
    a[...] = out
