"""Online check and correction of a rectified pair's vertical misalignment.

A rectified stereo pair images every scene point on the same row in both cameras. A
real rig drifts from its calibration: a bump or a warm camera turns the right camera by a
fraction of a degree, and the rows part by a fraction of a pixel to a few pixels. Feature
matching on one row (PMF) then matches each slanted edge a little off along it: the
disparity error is dv / tan(edge angle), so the ground's disparity spread, the obstacle
threshold taken from it and the smallest obstacle that stands out all grow (on the
simulated paper rig, the edge pixels' median threshold: 0.73 -> 0.91 px for 0.5 px of
misalignment, 0.71 -> 1.43 px for 1.6 px; and the egomotion's stereo matching, whose row
tolerance is 1 px, finds nothing beyond it).

This module measures the misalignment from corners matched between the two images of
each pair (pyramidal Lucas-Kanade, checked forwards and backwards, on the right image
brought to the left's brightness: `matched_brightness`), fits the vertical
displacement of the right image over the left,

    dv(u) = p0 + p1 x,    x = (u - cx) / f,   u the column in the right image,

(p0: a vertical offset or the right camera turned about its x axis, about f times the
angle, pixels; p1: turned about its optical axis, -f times the angle) by iteratively
reweighted least squares, and tracks p = (p0, p1) with a Kalman
filter of a slowly drifting constant. When the tracked misalignment reaches
``apply_min_px`` at either side of the image, and is sure there (3 times its standard
deviation and the scene's bias, ``scene_bias_px``: about 0.3 px; on 180 simulated
well-rectified rigs the largest measured was 0.13 px), the right image is resampled
so that its rows match the left's again (bilinear; below that, the pair is left
untouched, so a well-rectified rig sees no change at all).

A measurement costs about 5 ms at 320x240 (two thirds of it the corners' second
Lucas-Kanade pass). Once the misalignment is known it is measured in one pair of
``every_frames``, and that measurement is done in steps of 1-2 ms over the
pairs that follow (`corner_displacement_steps`); the filter takes it in as of the pair it
measures, so the estimate is the same, a few pairs later, and no pair pays for a whole
measurement. Until then (the first pairs, a restart) every pair is measured at once.

Lucas-Kanade assumes that a point is as bright in both images. Two cameras differ in
gain and black level (the simulator's right camera: 1.05 and +4 grey levels; two
cameras with their own auto-exposure: a third or more); on the raw pair that bias
reached 0.6 px where the ground meets a wall, and at a gain of 0.7 or 1.5 no corner
was matched at all.

Frames and units: image pixels (u right, v down, pixel-centre origin), the rectified
camera's f, cx, cy; the right image's rows displaced by +dv means a scene point on row v
of the left image lies on row v + dv of the right image.
"""
from __future__ import annotations

from collections.abc import Generator
from dataclasses import dataclass

import cv2
import numpy as np

from asmonc_vision.core.config import check_fields, param
from .npfast import flat_nonzero

#: chi-squared (2 degrees of freedom) at 0.999: a measurement farther than this from the
#: tracked misalignment is an outlier, or the rig has changed (`VerticalAlignment.update`).
_GATE_CHI2 = 13.82
#: Outlier frames in a row after which the rig is taken to have changed (restart).
_RESTART_AFTER = 3
#: Pairs measured (since the start or a restart) before the misalignment can count as
#: known: one pair's covariance holds its corners' scatter, not the view's structure,
#: which moves its roll term by up to 1.5 of its standard deviations.
_SETTLE_AFTER = 5
#: Initial standard deviations of (p0, p1): pixels, pixels per unit x.
_P0_SD = (3.0, 10.0)
#: Lucas-Kanade termination: iterations, and the step in pixels.
_LK_CRITERIA = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01)


@dataclass(frozen=True)
class AlignmentConfig:
    """Settings of the vertical-misalignment check (validated on construction)."""

    enabled: bool = param(True, 'Measure the vertical misalignment of the rectified pair '
                          'and, where it matters, resample the right image to remove it')
    every_frames: int = param(10, 'Once the misalignment is known (`settled`: its standard '
                              'deviation under settled_sd_px at both image sides, and '
                              'since not above twice that), measure it in one '
                              'pair of this many (before that, in every pair)',
                              range=(1, 1000))
    settled_sd_px: float = param(0.1, 'The misalignment counts as known when its standard '
                                 'deviation at both image sides is below this, pixels',
                                 range=(0.001, 10.0))
    apply_min_px: float = param(0.2, 'Resample the right image when the misalignment '
                                'reaches this at an image side and is sure there '
                                '(scene_bias_px); it stops at half of this, pixels',
                                range=(0.01, 100.0))
    max_corners: int = param(150, 'Corners sought in the left image per measurement',
                             range=(10, 5000))
    min_matches: int = param(20, 'Fewest corners matched both ways for a measurement',
                             range=(4, 5000))
    max_px: float = param(5.0, 'Largest vertical displacement of a corner match, pixels '
                          '(larger ones are mismatches)', range=(0.1, 100.0))
    drift_px: float = param(0.01, 'Random-walk drift of the misalignment, pixels per '
                            'square root of a frame', range=(0.0, 10.0))
    match_error_px: float = param(0.25, 'Largest forward-backward error of a corner match, '
                                  'pixels', range=(0.01, 10.0))
    spread: bool = param(True, 'Once the misalignment is known, spread each measurement '
                         'over the pairs after the one it measures (steps of 1-2 '
                         'ms at 320x240: the corners, the first pass, then the '
                         'second pass chunk_corners at a time) instead of doing it all in '
                         'one pair, when every_frames leaves the room; the filter takes it '
                         'in as of the pair it measures')
    chunk_corners: int = param(50, 'Corners followed in one step of a spread '
                               'measurement\'s second pass', range=(1, 5000))
    scene_bias_px: float = param(0.1, 'Error of the measurement that frames do not '
                                 'average away, pixels: the scene\'s structure biases it, '
                                 'the same in every frame of a still view (at most 0.13 px on '
                                 '180 simulated well-rectified rigs). The misalignment must '
                                 'stand 3 times its standard deviation and this above zero to '
                                 'be corrected', range=(0.0, 10.0))

    def __post_init__(self) -> None:
        check_fields(self)
        if self.min_matches > self.max_corners:
            raise ValueError(f'AlignmentConfig.min_matches = {self.min_matches} must not '
                             f'exceed max_corners = {self.max_corners}')


@dataclass(frozen=True)
class AlignmentMeasurement:
    """One pair's measured misalignment.

    Attributes:
        p: (2,) float64 (p0 px, p1 px): dv = p0 + p1 x (module docstring).
        cov: (2, 2) float64 its covariance.
        residual_px: robust spread of the matches about the fit, pixels.
        matches: corners used.
    """

    p: np.ndarray
    cov: np.ndarray
    residual_px: float
    matches: int


def _lk_both_ways(left: np.ndarray, right: np.ndarray, p: np.ndarray,
                  guess: np.ndarray | None, level: int, match_error_px: float,
                  max_px: float) -> tuple[np.ndarray, np.ndarray]:
    """Pyramidal Lucas-Kanade from left to right and back: ((N, 2) displacement right -
    left, (N,) bool kept) for the (N, 1, 2) float32 points p (``guess``: their initial
    positions in the right image, or None)."""
    flags = cv2.OPTFLOW_USE_INITIAL_FLOW if guess is not None else 0
    q, st, _ = cv2.calcOpticalFlowPyrLK(left, right, p,
                                        None if guess is None else guess.copy(),  # type: ignore[arg-type]
                                        winSize=(15, 15), maxLevel=level,
                                        criteria=_LK_CRITERIA, flags=flags)
    pb, st2, _ = cv2.calcOpticalFlowPyrLK(right, left, q, p.copy(), winSize=(15, 15),
                                          maxLevel=level, criteria=_LK_CRITERIA,
                                          flags=cv2.OPTFLOW_USE_INITIAL_FLOW)
    p2 = p.reshape(-1, 2).astype(np.float64)
    disp = q.reshape(-1, 2).astype(np.float64) - p2
    ok = ((st.ravel() == 1) & (st2.ravel() == 1)
          & (np.linalg.norm(pb.reshape(-1, 2) - p2, axis=1) <= match_error_px)
          & (disp[:, 0] <= 0.5) & (np.abs(disp[:, 1]) <= max_px))
    return disp, ok


def matched_brightness(left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """The right image with the left's brightness: gain and offset such that its mean and
    standard deviation are the left's (two cameras with their own exposure, gain or
    black level; Lucas-Kanade assumes the same brightness in both images).

    Args:
        left, right: (H, W) uint8 grey images of one pair (both see nearly the same scene,
            so their statistics would agree but for the cameras' responses).
    Returns:
        (H, W) uint8 right image, gain * right + offset, rounded and clipped to 0..255
        (each grey level's value computed once, in a 256-entry table); the right image
        itself when either image is uniform.
    """
    go = brightness_gain_offset(left, right)
    if go is None:
        return right
    gain, offset = go
    if right.dtype != np.uint8:
        return np.clip(np.rint(right * gain + offset), 0, 255).astype(np.uint8)
    table = np.clip(np.rint(np.arange(256, dtype=np.uint8) * gain + offset), 0, 255)
    return cv2.LUT(right, table.astype(np.uint8))


def brightness_gain_offset(left: np.ndarray, right: np.ndarray) -> tuple[float, float] | None:
    """The gain and offset that give the right image the left's mean and standard
    deviation of grey level (`matched_brightness`).

    Args:
        left, right: (H, W) uint8 grey images of one pair.
    Returns:
        (gain, offset): ``gain * right + offset`` is on the left camera's scale (gain
        dimensionless, offset grey levels); None when either image is uniform (standard
        deviation below 1e-3 grey levels).
    """
    mu_l, sdev_l = cv2.meanStdDev(left)
    mu_r, sdev_r = cv2.meanStdDev(right)
    sd_l, sd_r = float(sdev_l[0, 0]), float(sdev_r[0, 0])
    if sd_l < 1e-3 or sd_r < 1e-3:
        return None
    gain = sd_l / sd_r
    return gain, float(mu_l[0, 0]) - gain * float(mu_r[0, 0])


def corner_displacements(left: np.ndarray, right: np.ndarray, max_corners: int = 150,
                         max_px: float = 5.0, match_error_px: float = 0.25
                         ) -> tuple[np.ndarray, np.ndarray]:
    """Corners of the left image and their displacement into the right image.

    Two passes: a third of the corners are followed over a 5-level pyramid, a robust
    plane du = a u + b v + c (the ground's disparity, which most of them see) is fitted to
    their horizontal displacement, and then every corner is followed from that plane's
    prediction over 3 levels (the ground's large near disparities and its repetitive
    texture defeat a search from zero). A corner keeps the second pass's displacement,
    or the first's where only that one held. (All of `corner_displacement_steps` at once.)

    Args:
        left, right: (H, W) uint8 grey images of one (rectified) pair.
        max_corners: corners sought (Shi-Tomasi).
        max_px: the largest |vertical displacement| kept, pixels.
        match_error_px: the largest forward-backward error kept, pixels.
    Returns:
        (points (N, 2) float64 left (u, v), displacement (N, 2) float64 right - left
        (du, dv)), pixels; only matches found both ways, with a non-negative disparity
        (du <= 0.5).
    """
    steps = corner_displacement_steps(left, right, max_corners, max_px, match_error_px,
                                      chunk=max_corners)
    while True:
        try:
            next(steps)
        except StopIteration as done:
            return done.value


def corner_displacement_steps(left: np.ndarray, right: np.ndarray, max_corners: int,
                              max_px: float, match_error_px: float, chunk: int,
                              min_corners: int = 1
                              ) -> Generator[None, None, tuple[np.ndarray, np.ndarray]]:
    """`corner_displacements` in steps of 1-2 ms at 320x240: it yields after
    the corners, after the first pass, and after each ``chunk`` corners of the second
    pass, and returns its result. Lucas-Kanade follows every point on its own, so the
    result is the same bit for bit however the points are chunked. The images are
    copied: the caller may reuse its arrays between steps. With fewer than
    ``min_corners`` corners it returns no matches at once (a caller that needs that many
    matches has no use for fewer)."""
    empty = (np.zeros((0, 2)), np.zeros((0, 2)))
    left = left.copy()
    p = cv2.goodFeaturesToTrack(left, max_corners, 0.01, 5, blockSize=5)
    if p is None or len(p) < max(min_corners, 1):
        return empty
    right = matched_brightness(left, right.copy())
    yield
    pts = p.reshape(-1, 2).astype(np.float64)
    first = np.arange(0, len(p), 3)
    disp = np.zeros((len(p), 2))
    ok = np.zeros(len(p), bool)
    disp[first], ok[first] = _lk_both_ways(left, right, p[first], None, 4, match_error_px,
                                           max_px)
    coef = _ground_disparity_plane(pts[ok], disp[ok, 0])
    if coef is None:
        return pts[ok], disp[ok]
    pred = np.column_stack([pts, np.ones(len(pts))]) @ coef
    guess = np.column_stack([pts[:, 0] + pred, pts[:, 1]]).astype(np.float32)
    guess = guess.reshape(-1, 1, 2)
    for i in range(0, len(p), chunk):
        yield
        d2, ok2 = _lk_both_ways(left, right, p[i:i + chunk], guess[i:i + chunk], 2,
                                match_error_px, max_px)
        sel = flat_nonzero(ok2) + i
        disp[sel], ok[i:i + chunk] = d2[ok2], ok[i:i + chunk] | ok2
    return pts[ok], disp[ok]


def _ground_disparity_plane(pts: np.ndarray, du: np.ndarray) -> np.ndarray | None:
    """The plane du = a u + b v + c fitted to the first pass's matches (least squares
    trimmed to 3 robust sigmas): (3,) float64 (a, b, c), or None with fewer than 6
    matches or when the trimming keeps fewer than 3."""
    if du.shape[0] < 6:
        return None
    a = np.column_stack([pts, np.ones(du.shape[0])])
    keep = np.ones(du.shape[0], bool)
    for _ in range(5):
        coef = np.linalg.lstsq(a[keep], du[keep], rcond=None)[0]
        r = du - a @ coef
        s = max(1.4826 * float(np.median(np.abs(r[keep]))), 0.3)
        keep = np.abs(r) <= 3.0 * s
        if keep.sum() < 3:
            return None
    return coef


def fit_misalignment(points: np.ndarray, dv: np.ndarray, f: float, cx: float
                     ) -> AlignmentMeasurement | None:
    """Fit dv = p0 + p1 x to corner matches (Huber-weighted least squares).

    Args:
        points: (N, 2) float64 right-image (u, v), pixels (the right camera's rotation
            acts about its own centre).
        dv: (N,) float64 vertical displacement right - left, pixels.
        f, cx: the rectified camera's focal length and principal point's column, pixels.
    Returns:
        The AlignmentMeasurement, or None with fewer than 4 points or a degenerate spread.
    """
    n = dv.shape[0]
    if n < 4:
        return None
    x = (points[:, 0] - cx) / f
    a = np.column_stack([np.ones(n), x])
    w = np.ones(n)
    coef = np.zeros(2)
    s = 1.0
    for _ in range(6):
        sw = np.sqrt(w)
        coef, _, rank, _ = np.linalg.lstsq(a * sw[:, None], dv * sw, rcond=None)
        if rank < 2:
            return None
        r = dv - a @ coef
        s = max(1.4826 * float(np.median(np.abs(r))), 0.01)
        w = np.minimum(1.0, 1.5 * s / np.maximum(np.abs(r), 1e-12))   # Huber, k = 1.5 s
    ata = (a * w[:, None]).T @ a
    try:
        cov = s * s * np.linalg.inv(ata)
    except np.linalg.LinAlgError:
        return None
    # Neighbouring corners share image noise and texture: count the errors as if the
    # matches were a quarter as many (independent ones would make the fit overconfident).
    cov *= 4.0
    return AlignmentMeasurement(p=coef, cov=cov, residual_px=s, matches=n)


class VerticalAlignment:
    """Kalman filter of a stereo rig's vertical misalignment, and its correction.

    State x = (p0, p1) (pixels; `fit_misalignment`), a constant drifting as a random
    walk: F = I, Q = drift_px² I per frame. Measurements z = one pair's fit, H = I,
    R = its covariance. Not thread-safe; one instance per image stream.
    """

    def __init__(self, config: AlignmentConfig | None = None) -> None:
        self.config = config if config is not None else AlignmentConfig()
        self.reset()

    def reset(self) -> None:
        """Forget the misalignment (a new camera)."""
        self.x: np.ndarray = np.zeros(2)
        self.P = np.diag(np.square(_P0_SD))
        self.measurements = 0
        self.applied = False
        self._outliers = 0
        self._since = 0
        self._run = 0           # pairs measured since the start or the last restart
        self._settled = False
        self._maps: tuple | None = None
        self._map_x = np.zeros(2)
        self._shape: tuple[int, int] | None = None
        self._cam: tuple[float, float, float] | None = None
        #: a spread measurement under way (`update`): its steps, the filter's P as of
        #: the pair it measures, and the frames predicted since
        self._job: Generator[None, None, tuple[np.ndarray, np.ndarray]] | None = None
        self._job_P: np.ndarray | None = None
        self._job_frames = 0

    # ----------------------------------------------------------------- estimate
    def _sides_x(self) -> np.ndarray:
        """(2, 2) rows (1, x) of the image's first and last columns."""
        assert self._cam is not None and self._shape is not None   # set by update()
        f, cx, _ = self._cam
        w = self._shape[1]
        return np.array([[1.0, -cx / f], [1.0, (w - 1.0 - cx) / f]])

    def sides_px(self) -> tuple[np.ndarray, np.ndarray]:
        """The tracked misalignment dv at the image's left and right edges and its
        standard deviation there: ((2,), (2,)) pixels (zeros before the first pair)."""
        if self._shape is None:
            return np.zeros(2), np.zeros(2)
        a = self._sides_x()
        return a @ self.x, np.sqrt(np.einsum('ij,jk,ik->i', a, self.P, a))

    def dv_at(self, u: np.ndarray) -> np.ndarray:
        """The tracked misalignment at right-image columns u ((N,) pixels): (N,) pixels
        (a scene point on row v of the left image is on row v + dv of the right one)."""
        if self._cam is None:
            return np.zeros(np.shape(u))
        f, cx, _ = self._cam
        return self.x[0] + self.x[1] * (np.asarray(u, np.float64) - cx) / f

    @property
    def max_px(self) -> float:
        """The largest |dv| of the tracked misalignment over the image, pixels."""
        return float(np.max(np.abs(self.sides_px()[0])))

    def settled(self) -> bool:
        """Whether the misalignment is known: measured in at least ``_SETTLE_AFTER`` pairs,
        its standard deviation fell below ``settled_sd_px`` at both image sides and has
        not risen above twice that since."""
        if self._run < _SETTLE_AFTER:
            self._settled = False
            return False
        sd = self.sides_px()[1]
        limit = self.config.settled_sd_px * (2.0 if self._settled else 1.0)
        self._settled = bool(np.all(sd < limit))
        return self._settled

    def update(self, left: np.ndarray, right: np.ndarray, f: float, cx: float, cy: float
               ) -> AlignmentMeasurement | None:
        """Predict one frame on, and measure this pair when it is due.

        Once the misalignment is known (`settled`) and ``spread`` is set, a due pair's
        measurement is done in steps, one a call, the first in this one; the call that
        finishes it takes it in as it would have been in the pair it measures (the
        update on that pair's prediction, then the frames' predictions since), so the
        estimate is the same, those few pairs later.

        Args:
            left, right: (H, W) uint8 rectified grey images (the raw right image).
            f, cx, cy: the rectified camera, pixels.
        Returns:
            The pair's measurement when one was finished and used, else None (not due,
            not finished, too few matches, or gated out as an outlier).
        """
        c = self.config
        shape = (int(left.shape[0]), int(left.shape[1]))
        cam = (float(f), float(cx), float(cy))
        if self._shape != shape or self._cam != cam:
            self.reset()
            self._shape, self._cam = shape, cam
        # predict: x = F x (F = I), P = F P F' + Q
        self.P = self.P + (c.drift_px ** 2) * np.eye(2)
        self._since += 1
        if self._job is not None:
            return self._step()
        if self.settled() and self._since < c.every_frames:
            return None
        self._since = 0
        if c.spread and self._settled and c.every_frames > self._spread_frames():
            steps = corner_displacement_steps(left, right, c.max_corners, c.max_px,
                                              c.match_error_px, c.chunk_corners)
            self._job, self._job_P, self._job_frames = steps, self.P, 0
            return self._step()
        # at once: a pair with fewer corners than min_matches is not followed (it could
        # give no more matches than corners)
        steps = corner_displacement_steps(left, right, c.max_corners, c.max_px,
                                          c.match_error_px, c.chunk_corners, c.min_matches)
        while True:
            try:
                next(steps)
            except StopIteration as done:
                return self._measured(*done.value)

    def _spread_frames(self) -> int:
        """Pairs after the measured one that a spread measurement takes to finish: one
        for the first pass, one a chunk of the second (its corners in the first)."""
        return 1 + -(-self.config.max_corners // self.config.chunk_corners)

    def _step(self) -> AlignmentMeasurement | None:
        """One step of the spread measurement; when it finishes, its update as of the
        pair it measures and the predictions of the frames since (`update`)."""
        assert self._job is not None and self._job_P is not None
        try:
            next(self._job)
        except StopIteration as done:
            self._job = None
            self.P, frames = self._job_P, self._job_frames
            m = self._measured(*done.value)
            for _ in range(frames):
                self.P = self.P + (self.config.drift_px ** 2) * np.eye(2)
            return m
        self._job_frames += 1
        return None

    def _measured(self, pts: np.ndarray, disp: np.ndarray) -> AlignmentMeasurement | None:
        """Fit one pair's corner matches and take the fit into the filter (gated; a
        restart after ``_RESTART_AFTER`` outliers in a row): the measurement when used."""
        c = self.config
        assert self._cam is not None                                   # set by update()
        f, cx, _ = self._cam
        if pts.shape[0] < c.min_matches:
            return None
        m = fit_misalignment(pts + disp, disp[:, 1], f, cx)
        if m is None:
            return None
        z, R = m.p, m.cov
        y = z - self.x                                   # y = z - H x
        S = self.P + R                                   # S = H P H' + R
        nis = float(y @ np.linalg.solve(S, y))
        if self.measurements > 0 and nis > _GATE_CHI2:
            self._outliers += 1
            if self._outliers < _RESTART_AFTER:
                return None
            # the rig has changed: start again from this pair
            self.x, self.P = z.copy(), R.copy()
            self._settled = False
            self._outliers = 0
            self.measurements += 1
            self._run = 1
            return m
        self._outliers = 0
        K = np.linalg.solve(S.T, self.P.T).T             # K = P H' S^-1
        self.x = self.x + K @ y                          # x = x + K y
        ikh = np.eye(2) - K
        self.P = ikh @ self.P @ ikh.T + K @ R @ K.T      # P = (I-KH) P (I-KH)' + K R K'
        self.measurements += 1
        self._run += 1
        return m

    # --------------------------------------------------------------- correction
    def wanted(self) -> bool:
        """Whether the right image should be resampled now: once the misalignment is
        known (`settled`, or to a quarter of its size) and sure at either side
        (``apply_min_px``, ``scene_bias_px``); it stops below half of ``apply_min_px`` or
        when no longer sure."""
        if self.measurements == 0:
            return False
        dv, sd = self.sides_px()
        if not (self.applied or self.settled() or np.all(sd < 0.25 * np.max(np.abs(dv)))):
            return False                 # not yet known well enough to resample by
        sure = np.abs(dv) > 3.0 * np.hypot(sd, self.config.scene_bias_px)
        limit = self.config.apply_min_px * (0.5 if self.applied else 1.0)
        self.applied = bool(np.any(sure & (np.abs(dv) >= limit)))
        return self.applied

    def correct(self, right: np.ndarray) -> np.ndarray:
        """The right image resampled onto the left's rows with the tracked misalignment.

        Args:
            right: (H, W) uint8, the raw right image of the shape last given to `update`.
        Returns:
            (H, W) uint8: right'(u, v) = right(u, v + dv(u)) (bilinear, edges
            replicated).
        """
        assert self._shape is not None                             # set by update()
        h, w = self._shape
        if self._maps is None or np.max(np.abs(self._sides_x() @ (self.x - self._map_x))) > 0.02:
            uu, vv = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
            self._maps = (uu.astype(np.float32), (vv + self.dv_at(uu)).astype(np.float32))
            self._map_x = self.x.copy()
        return cv2.remap(right, self._maps[0], self._maps[1], cv2.INTER_LINEAR,
                         borderMode=cv2.BORDER_REPLICATE)

    def process(self, left: np.ndarray, right: np.ndarray, f: float, cx: float, cy: float
                ) -> np.ndarray:
        """`update`, then the right image to match against: corrected when `wanted`,
        else ``right`` itself (the same array)."""
        if not self.config.enabled:
            return right
        self.update(left, right, f, cx, cy)
        return self.correct(right) if self.wanted() else right
