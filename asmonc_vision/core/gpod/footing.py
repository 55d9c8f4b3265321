"""Where obstacle strings meet the ground: the per-frame geometry (`_FrameContext`: the
plane's ground coordinates, image projections, contact-edge and outline evidence) and
the walk of each string down to its foot (`string_feet`).
"""
from __future__ import annotations

from typing import cast

import cv2
import numpy as np

from ..camera import (MetricPlane, StereoCamera, columns, ground_axes, plane_disparity,
                      sub_rows, sub_scaled)
from . import kernels_geometry as kg
from ..npfast import flat_nonzero

#: An obstacle string's foot is where its matched run, followed down the image from its
#: lowest obstacle pixel, comes within this many noise sigmas of the ground plane.
_FOOT_SIGMAS = 1.0
#: Least uncertainty of a foot's image row, rows (the row is found to a pixel).
_FOOT_MIN_ROWS = 0.5
#: The lone-face search (`faces.lone_face_points`) follows each direction from the foot
#: in steps of _LONE_STEP_M metres up to _LONE_MAX_M: the steps.
_LONE_STEP_M = 0.02
_LONE_MAX_M = 0.7
_LONE_STEPS = np.arange(1, int(round(_LONE_MAX_M / _LONE_STEP_M)) + 1) * _LONE_STEP_M


def _clip_int(x, lo: int, hi: int) -> int:
    """``int(np.clip(x, lo, hi))`` of a float (NaN: ValueError, as int(NaN)), without
    np.clip's overhead on a scalar."""
    return int(min(max(float(x), lo), hi))


class _FrameContext:
    """What describing one frame's obstacles needs: the matches' smoothed excess, noise
    and run links, the plane, the visible ground and the left image (internal).

    Ground coordinates (``xy``): metres on the ground plane from the point below the left
    camera, x along the walking direction (the optical axis projected on the plane), y to
    the left, as range and bearing (`core.camera.ground_range_bearing`) measure them.
    """

    def __init__(self, cam: StereoCamera, metric: MetricPlane, abc: np.ndarray, u, v, pd,
                 excess_mean, sigma, prev, ground_points, left, u_left, usable,
                 nxt: np.ndarray | None = None) -> None:
        self.cam, self.metric, self.abc = cam, metric, abc
        self._nxt = nxt
        self.u, self.v, self.pd = u, v, pd
        # the matches' left-image columns and whether each is reliably matched in range
        self.u_left, self.usable = u_left, usable
        self.excess_mean, self.sigma, self.prev = excess_mean, sigma, prev
        self.origin, self.fwd, self.lft = ground_axes(metric)
        self._ground_points = ground_points
        # Placement-only silhouette candidates (`silhouette_owners`): the lowest
        # candidate pixel of each and the height of its top, metres.
        self.weak_start = np.zeros(0, np.int64)
        self.weak_top = np.zeros(0)
        self._ground_xy: np.ndarray | None = None
        self._left = left

    @property
    def nxt(self) -> np.ndarray:
        """(K,) int64 the match one row down in the same matched run of each match (-1
        at a run's bottom): the inverse of ``prev``."""
        if self._nxt is None:
            k = self.prev.shape[0]
            nxt = np.full(k, -1, np.int64)
            has = self.prev >= 0
            nxt[self.prev[has]] = flat_nonzero(has)
            self._nxt = nxt
        return self._nxt

    def to_xy(self, points: np.ndarray) -> np.ndarray:
        """(N, 2) ground coordinates of the feet (projections on the plane) of (N, 3)
        points of the left optical frame."""
        n = self.metric.normal_up
        g = sub_rows(sub_scaled(points, self.metric.signed_height(points), n), self.origin)
        return columns(g @ self.fwd, g @ self.lft)

    def to_image(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Left-image (u, v) of ground points (N, 2)."""
        p = (self.origin[None, :] + xy[:, :1] * self.fwd[None, :]
             + xy[:, 1:2] * self.lft[None, :])
        p[:, 2] = np.maximum(p[:, 2], 1e-6)
        return self.cam.project_left(p)

    @property
    def ground_xy(self) -> np.ndarray:
        """(G, 2) ground coordinates of the frame's ground features (visible ground)."""
        if self._ground_xy is None:
            self._ground_xy = self.to_xy(self._ground_points)
        return self._ground_xy

    def outline_evidence(self, foot: np.ndarray, height: float, phi: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The image's evidence for a face of ``height`` (m) starting at the ground point
        ``foot`` (2,) in each direction ``phi`` (D,) on the ground (radians from the
        ground's x axis towards y).

        Returns:
            points: (D, S, 2) ground coordinates of the samples (`_LONE_STEPS` metres
                from the foot), metres;
            evidence: (D, S) the weaker of the image gradients across the contact line
                (the samples) and across the top outline (the samples raised by
                ``height``), grey levels per pixel (the largest within one pixel across
                the line; 0 outside the image);
            separation: (D, S) the distance between the two lines across their
                direction, pixels;
            shift: (D, S) the distance between each sample and its raised copy in the
                image, pixels (the separation is its part across the line).
        """
        img_h, img_w = self._left.shape
        n_d = phi.shape[0]
        cos_d, sin_d = np.cos(phi), np.sin(phi)
        ok = False
        if kg.nb_outline_patch is not None:
            # The same samples and patch, compiled.
            points, x0, x1, y0, y1, ok = kg.nb_outline_patch(
                np.ascontiguousarray(foot, np.float64), cos_d, sin_d, _LONE_STEPS,
                self.origin, self.fwd, self.lft, self.metric.normal_up, float(height),
                float(self.cam.f), float(self.cam.cx), float(self.cam.cy), img_w, img_h)
        if not ok:
            dirs = np.empty((n_d, 2))
            dirs[:, 0] = cos_d
            dirs[:, 1] = sin_d
            points = foot[None, None, :] + _LONE_STEPS[None, :, None] * dirs[:, None, :]
            # The gradient on the patch that holds every sample (the lines' ends and the
            # foot bound them, raised or not), two pixels wider than the samples one
            # pixel across the lines reach: the full image's values there.
            ends = np.empty((n_d + 1, 2))
            ends[0] = foot
            ends[1:] = points[:, -1]
            e3 = np.empty((2 * n_d + 2, 3))
            e3[:n_d + 1] = (self.origin[None, :] + ends[:, :1] * self.fwd
                            + ends[:, 1:] * self.lft)
            e3[n_d + 1:] = e3[:n_d + 1] + height * self.metric.normal_up
            e3[:, 2] = np.maximum(e3[:, 2], 1e-6)
            ue, ve = self.cam.project_left(e3)
            x0 = _clip_int(np.floor(ue.min()) - 3, 0, img_w - 1)
            x1 = _clip_int(np.ceil(ue.max()) + 4, x0 + 1, img_w)
            y0 = _clip_int(np.floor(ve.min()) - 3, 0, img_h - 1)
            y1 = _clip_int(np.ceil(ve.max()) + 4, y0 + 1, img_h)
        patch = self._left[y0:y1, x0:x1].astype(np.float32)
        gx = cv2.Sobel(patch, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
        gy = cv2.Sobel(patch, cv2.CV_32F, 0, 1, ksize=3, scale=0.125)
        if kg.nb_outline is not None:
            ev, sep, shift = kg.nb_outline(points, self.origin, self.fwd, self.lft,
                                         self.metric.normal_up, float(height),
                                         float(self.cam.f), float(self.cam.cx),
                                         float(self.cam.cy), gx, gy, x0, y0, img_w, img_h)
            return points, ev, sep, shift
        p3 = (self.origin[None, None, :] + points[..., :1] * self.fwd
              + points[..., 1:] * self.lft)
        lines = []
        for lift in (0.0, height):
            q = (p3 + lift * self.metric.normal_up).reshape(-1, 3)
            q[:, 2] = np.maximum(q[:, 2], 1e-6)
            u, v = self.cam.project_left(q)
            u, v = u.reshape(points.shape[:2]), v.reshape(points.shape[:2])
            # a line on the ground (or parallel to it) is a line in the image: one
            # normal per direction, from its ends
            du, dv = u[:, -1:] - u[:, :1], v[:, -1:] - v[:, :1]
            length = np.maximum(np.hypot(du, dv), 1e-9)
            nu, nv = -dv / length, du / length
            best = np.zeros(u.shape)
            for off in (-1.0, 0.0, 1.0):
                ui = np.clip(np.rint(u + off * nu), 0, img_w - 1).astype(np.int64) - x0
                vi = np.clip(np.rint(v + off * nv), 0, img_h - 1).astype(np.int64) - y0
                best = np.maximum(best, np.abs(gx[vi, ui] * nu + gy[vi, ui] * nv))
            inside = (u >= 0) & (u <= img_w - 1) & (v >= 0) & (v <= img_h - 1)
            lines.append((np.where(inside, best, 0.0), u, v, nu, nv))
        (g_c, uc, vc, nuc, nvc), (g_t, ut, vt, _, _) = lines
        separation = np.abs((ut - uc) * nuc + (vt - vc) * nvc)
        return points, np.minimum(g_c, g_t), separation, np.hypot(ut - uc, vt - vc)

    def contact_edge_score(self, a: np.ndarray, n: np.ndarray, b: np.ndarray) -> np.ndarray:
        """How well the left image's intensity edges follow the ground polylines
        a -> n[k] -> b (a, b (2,), n (M, 2) ground points): the mean over each polyline of
        the image gradient across it (the largest within one pixel), grey levels per
        pixel, (M,). An obstacle standing on the ground meets it along such an edge (its
        silhouette edges show that it contrasts with the ground)."""
        return self.contact_edge_scores(a[None], n[None], b[None],
                                        np.ones((1, n.shape[0]), bool))[0]

    def contact_edge_scores(self, a: np.ndarray, n: np.ndarray, b: np.ndarray,
                            ok: np.ndarray) -> np.ndarray:
        """`contact_edge_score` of several searches at once: a, b (T, 2), n (T, M, 2);
        only the candidates ``ok`` (T, M) are scored (-inf elsewhere), (T, M).

        Each search samples the image gradient in the frame of its own patch (the
        bounding box of its points and candidates, 3-4 pixels wider), as one search alone
        would; the gradient is computed once on the union of the patches (a sample lies
        at least two pixels inside its patch, or on the image border: the same values).
        """
        t_n, m = ok.shape
        img_h, img_w = self._left.shape
        if kg.nb_contact is not None and kg.nb_contact_bounds is not None:
            # One projection of all the points (elementwise: the same pixels), the
            # patches' bounds compiled (the same arithmetic).
            uu, vv = self.to_image(np.concatenate((a, b, n.reshape(-1, 2))))
            ua, ub, un = uu[:t_n], uu[t_n:2 * t_n], uu[2 * t_n:].reshape(t_n, m)
            va, vb, vn = vv[:t_n], vv[t_n:2 * t_n], vv[2 * t_n:].reshape(t_n, m)
            okc = np.ascontiguousarray(ok)
            x0, x1, y0, y1 = kg.nb_contact_bounds(ua, va, ub, vb, un, vn, okc, img_w, img_h)
            gx0, gx1, gy0, gy1 = int(x0.min()), int(x1.max()), int(y0.min()), int(y1.max())
            patch = self._left[gy0:gy1, gx0:gx1].astype(np.float32)
            gx = cv2.Sobel(patch, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
            gy = cv2.Sobel(patch, cv2.CV_32F, 0, 1, ksize=3, scale=0.125)
            return kg.nb_contact(ua, va, ub, vb, un, vn, okc, x0, x1, y0, y1, gx0, gy0, gx, gy)
        ua, va = self.to_image(a)
        ub, vb = self.to_image(b)
        un, vn = self.to_image(n.reshape(-1, 2))
        un, vn = un.reshape(t_n, m), vn.reshape(t_n, m)
        inf = np.inf
        u_lo = np.minimum(np.minimum(ua, ub), np.where(ok, un, inf).min(axis=1))
        u_hi = np.maximum(np.maximum(ua, ub), np.where(ok, un, -inf).max(axis=1))
        v_lo = np.minimum(np.minimum(va, vb), np.where(ok, vn, inf).min(axis=1))
        v_hi = np.maximum(np.maximum(va, vb), np.where(ok, vn, -inf).max(axis=1))
        x0 = np.clip(np.floor(u_lo).astype(np.int64) - 3, 0, img_w - 1)
        x1 = np.minimum(np.maximum(np.ceil(u_hi).astype(np.int64) + 4, x0 + 1), img_w)
        y0 = np.clip(np.floor(v_lo).astype(np.int64) - 3, 0, img_h - 1)
        y1 = np.minimum(np.maximum(np.ceil(v_hi).astype(np.int64) + 4, y0 + 1), img_h)
        gx0, gx1, gy0, gy1 = int(x0.min()), int(x1.max()), int(y0.min()), int(y1.max())
        patch = self._left[gy0:gy1, gx0:gx1].astype(np.float32)
        gx = cv2.Sobel(patch, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
        gy = cv2.Sobel(patch, cv2.CV_32F, 0, 1, ksize=3, scale=0.125)
        if kg.nb_contact is not None:
            return kg.nb_contact(ua, va, ub, vb, np.ascontiguousarray(un),
                               np.ascontiguousarray(vn), np.ascontiguousarray(ok), x0, x1,
                               y0, y1, gx0, gy0, gx, gy)
        # Segments (T, 2, M): a -> n and b -> n, in each search's patch coordinates.
        fx, fy = x0.astype(np.float64)[:, None, None], y0.astype(np.float64)[:, None, None]
        u0 = np.stack([ua, ub], axis=1)[:, :, None] - fx
        v0 = np.stack([va, vb], axis=1)[:, :, None] - fy
        u1 = un[:, None, :] - fx
        v1 = vn[:, None, :] - fy
        du, dv = u1 - u0, v1 - v0
        length = np.hypot(du, dv)
        nu = (-dv / np.maximum(length, 1e-9))[..., None]
        nv = (du / np.maximum(length, 1e-9))[..., None]
        t = (np.arange(16) + 0.5) / 16.0
        uu = u0[..., None] + t * du[..., None]
        vv = v0[..., None] + t * dv[..., None]
        # Clipping to each patch, then the offset into the union patch (flat index).
        pw = gx.shape[1]
        w_max = (x1 - x0 - 1)[:, None, None, None]
        h_max = (y1 - y0 - 1)[:, None, None, None]
        ox = (x0 - gx0)[:, None, None, None]
        oy = (y0 - gy0)[:, None, None, None]
        gxf, gyf = gx.ravel(), gy.ravel()
        best = None
        for off in (-1.0, 0.0, 1.0):
            ui = np.rint(uu + off * nu).astype(np.int64)
            vi = np.rint(vv + off * nv).astype(np.int64)
            np.maximum(ui, 0, out=ui)
            np.minimum(ui, w_max, out=ui)
            np.maximum(vi, 0, out=vi)
            np.minimum(vi, h_max, out=vi)
            flat = (vi + oy) * pw + (ui + ox)
            val = np.abs(gxf[flat] * nu + gyf[flat] * nv)
            best = val if best is None else np.maximum(best, val)
        total = cast(np.ndarray, best).mean(axis=-1) * length   # (the loop set best)
        score = (total[:, 0] + total[:, 1]) / np.maximum(length[:, 0] + length[:, 1], 1e-9)
        return np.where(ok, score, -inf)


def string_feet(ctx: _FrameContext, start: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The ground foot of edge strings, from their lowest obstacle pixels ``start``.

    Each string's matched run is followed down the image (one row at a time, only while
    the disparity stays consistent, :func:`run_links`) from its start until its smoothed
    disparity excess is within ``_FOOT_SIGMAS`` noise sigmas of the plane: there the edge
    meets the ground (an edge standing on the ground loses |b| px of excess per row).
    The foot is the projection on the plane of that pixel's point (its disparity the
    plane's plus the remaining excess; on the plane when the run ended on it). Its range
    uncertainty: the range spanned by one image row there, times the row's uncertainty
    (noise sigma / |b|, at least ``_FOOT_MIN_ROWS``).

    Returns:
        ((S, 2) ground coordinates of the feet, (S,) range sigma, metres).
    """
    nxt = ctx.nxt
    cur = np.asarray(start, np.int64)
    exm, sig = ctx.excess_mean, ctx.sigma
    if kg.nb_walk_down is not None:
        cur = kg.nb_walk_down(cur, nxt, exm, sig, _FOOT_SIGMAS, int(ctx.cam.height))
    else:
        for _ in range(int(ctx.cam.height)):
            n = nxt[cur]
            go = (n >= 0) & (exm[cur] > _FOOT_SIGMAS * sig[cur])
            if not go.any():
                break
            cur = np.where(go, n, cur)
    u, v = ctx.u[cur], ctx.v[cur]
    p = ctx.cam.triangulate(u, v, ctx.pd[cur] + np.maximum(exm[cur], 0.0))
    xy = ctx.to_xy(p)
    slope = max(abs(float(ctx.abc[1])), 1e-3)

    def ground_range(dv: float) -> np.ndarray:
        d = np.maximum(plane_disparity(ctx.abc, u, v + dv), 1e-3)
        g = ctx.to_xy(ctx.cam.triangulate(u, v + dv, d))
        return np.hypot(g[:, 0], g[:, 1])

    rows = np.maximum(sig[cur] / slope, _FOOT_MIN_ROWS)
    return xy, np.abs(ground_range(0.5) - ground_range(-0.5)) * rows


def ground_coords(p: np.ndarray, hh: np.ndarray, metric: MetricPlane, axes: bool = False):
    """The feet of points ``p`` (K, 3) (heights ``hh`` (K,) above the plane) on the ground:
    (K, 2) (forward, left) from the point below the camera, metres; with ``axes`` also
    the forward and left unit vectors (3,)."""
    n_up = metric.normal_up
    feet = p - hh[:, None] * n_up[None, :]
    origin, fwd, lft = ground_axes(metric)
    g = feet - origin[None, :]
    g2 = columns(g @ fwd, g @ lft)
    return (g2, fwd, lft) if axes else g2
