"""The paper's synthetic motion experiment (Molton et al. 1998, Section 4.2, Tables 2, 3).

"A set of points in space were chosen and their positions in the image of a left and
right camera were calculated. The points were then rotated (by up to 20°) and
translated (a significant distance) rigidly, and new image positions found. A random
amount of noise was added to the point image position ... chosen from a uniform
distribution between plus and minus a maximum pixel noise value." 500 tests per level.

Here (``TrialSettings``): the paper's rig (f = 300 px, B = 0.35 m, 320x240, principal
point at the image centre); ``n_points`` points drawn uniformly over the left image
with depths uniform in ``depth_range``, kept only if all four images (previous and
current, left and right) see them; the camera moves by a rotation of uniform angle up
to ``max_rotation_deg`` about a uniformly random axis and a translation of uniform
length in ``translation_range`` in a uniformly random direction (equivalently the
points move rigidly by the inverse); every pixel coordinate of every image gets
independent uniform noise in [-a, a]. Outliers (``outlier_fraction``): that share of
the points gets a wrong match, half of them a wrong temporal match (the current left
and right positions of another random point) and half a wrong stereo match at time 0
(the previous right position moved along the row to a random disparity).

Errors of an estimate ``T_p_c`` against the truth: |Δx|, |Δy|, |Δz| of the
translation in the previous left optical frame (x right, y down, z forward), mm; and
the error rotation ``log(R_est R_true^T)`` about the optical axes: pitch about x
(lateral), yaw about y (vertical), roll about z (optical axis), degrees.

The paper's Tables 2 and 3 are ``PAPER_TABLES`` (their x, y, z are presumably mm).
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from asmonc_vision.core.camera import StereoCamera
from asmonc_vision.core.motion.estimators import (Correspondences, RansacSettings,
                                                  estimate_motion)
from asmonc_vision.core.motion.geometry import (invert, project, rotation_error_components,
                                                so3_exp)

#: Molton et al. 1998, mean error at each maximum pixel noise: x, y, z, roll, pitch, yaw
#: (x, y, z in mm as we read them; angles in degrees).
PAPER_TABLES = {
    'three_point': {  # Table 2, three point method
        0.1: (7.0, 7.5, 7.9, 0.05, 0.14, 0.13),
        0.5: (35, 37, 39, 0.26, 0.72, 0.68),
        1.0: (71, 74, 79, 0.52, 1.43, 1.36),
        2.0: (148, 153, 157, 1.06, 2.94, 2.80),
    },
    'essential': {  # Table 3, essential matrix method
        0.1: (9.95, 9.03, 12.14, 0.11, 0.17, 0.18),
        0.5: (45, 43, 60, 0.46, 0.82, 0.84),
        1.0: (84, 81, 118, 0.92, 1.48, 1.60),
        2.0: (163, 149, 241, 1.78, 2.42, 2.59),
    },
}


@dataclass(frozen=True)
class TrialSettings:
    """The synthetic scene and motion (defaults: the paper's rig; see module docstring)."""

    f: float = 300.0
    width: int = 320
    height: int = 240
    baseline: float = 0.35
    n_points: int = 100
    depth_range: tuple = (1.5, 8.0)
    max_rotation_deg: float = 20.0
    translation_range: tuple = (0.05, 0.5)
    margin_px: float = 2.0

    def camera(self) -> StereoCamera:
        return StereoCamera(f=self.f, cx=(self.width - 1) / 2.0, cy=(self.height - 1) / 2.0,
                            baseline=self.baseline, width=self.width, height=self.height)


@dataclass
class Trial:
    """One synthetic trial: correspondences and the true egomotion T_p_c."""

    corr: Correspondences
    R: np.ndarray
    t: np.ndarray
    outliers: np.ndarray


def _visible(uv, s: TrialSettings):
    m = s.margin_px
    return ((uv[:, 0] >= m) & (uv[:, 0] <= s.width - 1 - m)
            & (uv[:, 1] >= m) & (uv[:, 1] <= s.height - 1 - m))


def make_trial(rng, s: TrialSettings, noise_px: float, outlier_fraction: float = 0.0) -> Trial:
    """Draw one trial (see the module docstring). ``rng``: seed or Generator."""
    rng = np.random.default_rng(rng)
    cam = s.camera()
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    angle = np.radians(rng.uniform(0.0, s.max_rotation_deg))
    r_pc = so3_exp(axis * angle)
    d = rng.normal(size=3)
    t_pc = d / np.linalg.norm(d) * rng.uniform(*s.translation_range)
    r_cp, t_cp = invert(r_pc, t_pc)
    pts: np.ndarray = np.zeros((0, 3))
    for _ in range(100):
        k = 4 * s.n_points
        u = rng.uniform(0, s.width - 1, k)
        v = rng.uniform(0, s.height - 1, k)
        z = rng.uniform(*s.depth_range, k)
        x0 = np.stack([(u - cam.cx) * z / cam.f, (v - cam.cy) * z / cam.f, z], axis=1)
        x1 = x0 @ r_cp.T + t_cp
        ok = (x1[:, 2] > 0.3)
        with np.errstate(invalid='ignore', divide='ignore'):
            for pp, off in ((x0, cam.baseline), (x1, 0.0), (x1, cam.baseline)):
                ok &= _visible(project(pp, cam.f, cam.cx, cam.cy, off), s)
        pts = np.vstack([pts, x0[ok]])
        if len(pts) >= s.n_points:
            break
    pts = pts[:s.n_points]
    n = len(pts)
    x1 = pts @ r_cp.T + t_cp
    obs = [project(p, cam.f, cam.cx, cam.cy, off)
           for p in (pts, x1) for off in (0.0, cam.baseline)]
    obs = [o + rng.uniform(-noise_px, noise_px, size=o.shape) for o in obs]
    out = np.zeros(n, bool)
    n_out = int(round(outlier_fraction * n))
    if n_out:
        which = rng.choice(n, n_out, replace=False)
        out[which] = True
        temporal, stereo = which[: (n_out + 1) // 2], which[(n_out + 1) // 2:]
        for i in temporal:                      # the current match is another point
            u, v = rng.uniform(0, s.width - 1), rng.uniform(0, s.height - 1)
            dd = cam.fb / rng.uniform(*s.depth_range)
            obs[2][i] = (u, v)
            obs[3][i] = (u - dd, v)
        for i in stereo:                        # the previous right match is wrong
            dd = cam.fb / rng.uniform(*s.depth_range)
            obs[1][i, 0] = obs[0][i, 0] - dd
    return Trial(Correspondences(*obs), r_pc, t_pc, out)


def motion_errors(r_est, t_est, r_true, t_true) -> np.ndarray:
    """(6,) |dx|, |dy|, |dz| mm and |roll|, |pitch|, |yaw| deg (see module docstring)."""
    dt = np.abs(np.asarray(t_est) - np.asarray(t_true)) * 1e3
    w = np.degrees(np.abs(rotation_error_components(r_est, r_true)))
    return np.array([dt[0], dt[1], dt[2], w[2], w[0], w[1]])


def default_ransac(noise_px: float) -> RansacSettings:
    """The RANSAC settings of the experiment at a noise level: the inlier bound is
    max(1, 4 a) px (the time-0 stereo depth error adds to the image noise after a
    large motion), the Huber bound half of it."""
    thr = max(1.0, 4.0 * noise_px)
    return RansacSettings(threshold_px=thr, huber_px=thr / 2.0, max_iterations=500,
                          min_inliers=8)


@dataclass
class LevelResult:
    """Mean errors of one method at one noise level over the trials it solved.

    Attributes:
        mean: (6,) x, y, z mm, roll, pitch, yaw deg. median: (6,) the same, medians.
        failures: trials without an estimate. ms: mean CPU time of a solve (this
            thread), milliseconds.
    """

    method: str
    noise_px: float
    outlier_fraction: float
    trials: int
    mean: np.ndarray
    median: np.ndarray
    failures: int
    ms: float


def run_level(methods, noise_px: float, trials: int, outlier_fraction: float = 0.0,
              settings: TrialSettings = TrialSettings(), seed: int = 0,
              ransac: RansacSettings | None = None, progress=None) -> dict[str, LevelResult]:
    """Run every method on the same ``trials`` trials at one noise level.

    Trial i uses the generator seeded ``[seed, round(1000 a), i]`` (independent of the
    outlier fraction, so with and without outliers see the same scenes and motions);
    the methods' own RANSAC draws are seeded ``[seed, i, 7]``.
    """
    cam = settings.camera()
    st = ransac or default_ransac(noise_px)
    errs: dict[str, list] = {m: [] for m in methods}
    fails = {m: 0 for m in methods}
    secs = {m: 0.0 for m in methods}
    for i in range(trials):
        tr = make_trial([seed, int(round(noise_px * 1000)), i], settings, noise_px,
                        outlier_fraction)
        for m in methods:
            t0 = time.thread_time()
            est = estimate_motion(m, tr.corr, cam, st, rng=[seed, i, 7])
            secs[m] += time.thread_time() - t0
            if not est.ok:
                fails[m] += 1
                continue
            errs[m].append(motion_errors(est.R, est.t, tr.R, tr.t))
        if progress is not None:
            progress(i + 1, trials)
    out = {}
    for m in methods:
        e = np.array(errs[m]) if errs[m] else np.full((1, 6), np.nan)
        out[m] = LevelResult(m, noise_px, outlier_fraction, trials, e.mean(axis=0),
                             np.median(e, axis=0), fails[m], secs[m] / max(trials, 1) * 1e3)
    return out


def run_minimal_level(noise_px: float, trials: int, settings: TrialSettings = TrialSettings(),
                      seed: int = 0) -> dict[str, LevelResult]:
    """The paper's two methods on *minimal* point sets, without RANSAC or least squares:
    Grunert's P3P on 3 points (``three_point``) and the seven-point F with the scale from
    the same 7 stereo points (``essential``). Where a minimal problem has several
    solutions the one nearest the truth is taken (an oracle: optimistic). This is the
    regime the paper's Tables 2 and 3 fall in (docs/motion.md).
    """
    from asmonc_vision.core.motion.geometry import bearings, triangulate
    from asmonc_vision.core.motion.refine import scale_from_stereo
    from asmonc_vision.core.motion.solvers import (choose_by_cheirality,
                                                   essential_from_fundamental,
                                                   fundamental_7pt, p3p_grunert)
    import dataclasses

    cam = settings.camera()
    k = np.array([[cam.f, 0.0, cam.cx], [0.0, cam.f, cam.cy], [0.0, 0.0, 1.0]])
    out = {}
    for method, n in (('three_point', 3), ('essential', 7)):
        s = dataclasses.replace(settings, n_points=n)
        errs, fails, secs = [], 0, 0.0
        for i in range(trials):
            tr = make_trial([seed, int(round(noise_px * 1000)), i, n], s, noise_px)
            c = tr.corr
            t0 = time.thread_time()
            pts = triangulate(c.prev_left, c.prev_right, cam.f, cam.cx, cam.cy, cam.baseline)
            cands = []
            if method == 'three_point':
                r, t, v = p3p_grunert(bearings(c.curr_left, cam.f, cam.cx, cam.cy)[None], pts[None])
                cands = [invert(r[0, j], t[0, j]) for j in range(4) if v[0, j]]
            else:
                f, v = fundamental_7pt(c.prev_left[None], c.curr_left[None])
                m0 = np.column_stack([(c.prev_left - [cam.cx, cam.cy]) / cam.f, np.ones(n)])
                m1 = np.column_stack([(c.curr_left - [cam.cx, cam.cy]) / cam.f, np.ones(n)])
                for j in range(3):
                    if not v[0, j]:
                        continue
                    r, tu, _ = choose_by_cheirality(essential_from_fundamental(f[0, j], k), m0, m1)
                    sc = scale_from_stereo(r, tu, pts, c.curr_left, cam)
                    cands.append(invert(r, sc * tu))
            secs += time.thread_time() - t0
            if not cands:
                fails += 1
                continue
            ce = [motion_errors(r, t, tr.R, tr.t) for r, t in cands]
            errs.append(min(ce, key=lambda x: float(np.sum(x[:3]) / 10 + np.sum(x[3:]))))
        e = np.array(errs) if errs else np.full((1, 6), np.nan)
        out[method] = LevelResult(method, noise_px, 0.0, trials, e.mean(axis=0),
                                  np.median(e, axis=0), fails, secs / max(trials, 1) * 1e3)
    return out


# --- corner localisation --------------------------------------------------------------

#: synthetic corner kinds: a step-edge wedge, a step-edge saddle (four tiles of two
#: shades), two crossing grout lines, a grout line ending on another (T)
CORNER_KINDS = ('L', 'X_step', 'X_line', 'T_line')
#: detector variants measured: Shi–Tomasi at integer pixels, with cv2.cornerSubPix
#: (11x11), with our vectorised ``subpix_refine`` (11x11, the default), and Wang–Brady
#: (quadratic fit) without and with its smoothing-displacement correction
CORNER_DETECTORS = ('shi_tomasi_integer', 'shi_tomasi_cv', 'shi_tomasi', 'wang_brady_uncorrected',
                    'wang_brady')


def render_corner(kind: str, rng, size: int = 48, supersample: int = 8, blur_sigma: float = 0.5,
                  noise_sigma: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """A synthetic corner at a random sub-pixel position, as the simulator's camera
    sees it: area-sampled (``supersample`` x ``supersample`` per pixel), Gaussian blur,
    Gaussian noise, rounded to uint8.

    Args:
        kind: one of CORNER_KINDS.
    Returns:
        (image (size, size) uint8, true corners (K, 2) (u, v) pixels: the vertex first,
        then, for line junctions, the corners where the lines' edges meet, which are
        physical corners as good as the vertex for matching).
    """
    import cv2

    rng = np.random.default_rng(rng)
    c = (size - 1) / 2.0 + rng.uniform(-0.5, 0.5, 2)
    ss = supersample
    g = (np.arange(size * ss) + 0.5) / ss - 0.5
    uu, vv = np.meshgrid(g - c[0], g - c[1])
    th0 = rng.uniform(0, 2 * np.pi)
    bg, fg = rng.uniform(130, 170), rng.uniform(70, 110)
    ang = np.arctan2(vv, uu)

    def in_wedge(a0, width):
        return np.mod(ang - a0, 2 * np.pi) < width

    def line_dist(a):
        return np.abs(-np.sin(a) * uu + np.cos(a) * vv)

    if kind == 'L':
        img = np.where(in_wedge(th0, np.radians(rng.uniform(60, 120))), fg, bg)
    elif kind == 'X_step':
        a1 = np.radians(rng.uniform(60, 120))
        img = np.where(in_wedge(th0, a1) | in_wedge(th0 + np.pi, a1), fg, bg)
    elif kind in ('X_line', 'T_line'):
        width = rng.uniform(1.5, 2.5)
        a1 = th0 + np.radians(rng.uniform(60, 120))
        on = line_dist(th0) < width / 2
        along = np.cos(a1) * uu + np.sin(a1) * vv
        second = line_dist(a1) < width / 2
        if kind == 'T_line':
            second &= along > 0
        img = np.where(on | second, fg, bg)
        normals = np.array([[-np.sin(th0), np.cos(th0)], [-np.sin(a1), np.cos(a1)]])
        extra = []
        for s1 in (-1, 1):
            for s2 in (-1, 1):
                p = np.linalg.solve(normals, [s1 * width / 2, s2 * width / 2])
                if kind == 'X_line' or p @ [np.cos(a1), np.sin(a1)] > 0:
                    extra.append(c + p)
        c = np.vstack([c[None], np.array(extra)])
    else:
        raise ValueError(f"unknown corner kind '{kind}'; expected one of {CORNER_KINDS}")
    img = img.reshape(size, ss, size, ss).mean(axis=(1, 3))
    if blur_sigma > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur_sigma)
    img = img + rng.normal(0, noise_sigma, img.shape)
    return np.clip(np.round(img), 0, 255).astype(np.uint8), np.atleast_2d(c)


def corner_localisation(detector: str, kind: str, trials: int = 300, seed: int = 0,
                        gate_px: float = 3.0) -> dict:
    """Localisation error of a corner detector on synthetic corners.

    The detection nearest to a true corner within ``gate_px`` counts (its error is to
    that corner); for a line junction the true corners are where the centre lines cross
    and where the lines' edges meet (see ``render_corner``).

    Returns:
        {'detected': fraction, 'mean': mean error px, 'rms': px, 'median': px,
         'p90': px, 'bias': |mean error vector| px}.
    """
    from asmonc_vision.core.motion.features import shi_tomasi_corners, wang_brady_corners

    errs = []
    for i in range(trials):
        img, c = render_corner(kind, [seed, CORNER_KINDS.index(kind), i])
        if detector == 'shi_tomasi_integer':
            pts = shi_tomasi_corners(img, max_corners=10, border=4, subpix_half_window=0)
        elif detector == 'shi_tomasi':
            pts = shi_tomasi_corners(img, max_corners=10, border=4)
        elif detector == 'shi_tomasi_cv':
            import cv2
            pts = shi_tomasi_corners(img, max_corners=10, border=4, subpix_half_window=0)
            if len(pts):
                crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 40, 0.001)
                pts = cv2.cornerSubPix(img, pts.astype(np.float32).reshape(-1, 1, 2), (5, 5),
                                       (-1, -1), crit).reshape(-1, 2).astype(float)
        elif detector == 'wang_brady':
            pts = wang_brady_corners(img, max_corners=10, border=4)
        elif detector == 'wang_brady_uncorrected':
            pts = wang_brady_corners(img, max_corners=10, border=4, displacement_correction=0.0)
        else:
            raise ValueError(f"unknown detector '{detector}'; expected one of {CORNER_DETECTORS}")
        if len(pts) == 0:
            continue
        d = (pts[:, None, :] - c[None, :, :]).reshape(-1, 2)
        j = int(np.argmin(np.sum(d * d, axis=1)))
        if np.hypot(*d[j]) <= gate_px:
            errs.append(d[j])
    e = np.array(errs).reshape(-1, 2)
    n = np.hypot(e[:, 0], e[:, 1])
    if not len(n):
        return {'detected': 0.0, 'mean': np.nan, 'rms': np.nan, 'median': np.nan,
                'p90': np.nan, 'bias': np.nan}
    return {'detected': len(n) / trials, 'mean': float(n.mean()),
            'rms': float(np.sqrt(np.mean(n * n))), 'median': float(np.median(n)),
            'p90': float(np.percentile(n, 90)), 'bias': float(np.hypot(*e.mean(axis=0)))}


__all__ = ['run_minimal_level', 'CORNER_KINDS', 'CORNER_DETECTORS', 'render_corner',
           'corner_localisation',
           'PAPER_TABLES', 'TrialSettings', 'Trial', 'make_trial', 'motion_errors',
           'default_ransac', 'LevelResult', 'run_level']
