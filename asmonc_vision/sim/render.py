"""Vectorised ray casting of rectified stereo pairs, with per-pixel ground truth.

Rays are cast through a grid of ``supersample x supersample`` samples per pixel (sample
centres at ``(k + 0.5) / s - 0.5`` pixels from the pixel centre), shaded (albedo of the
hit surface, pre-filtered by the sample footprint, times Lambert lighting), averaged per
pixel, then passed through the camera model: vignetting, Gaussian optical blur, gain and
offset (different for the right camera), Gaussian noise, rounding to mono8.

Optional camera realism (``RigSettings``, off by default): motion blur (the mean of
several renders over the exposure time), a slow auto-exposure gain drift per camera
(``exposure_gains``) and a rectification residual applied to the rendered right image.
The ground truth is always that of the frame time through the unshifted left camera.

Ground truth comes from one extra ray through each left pixel *centre*: depth z along
the left optical axis (the ray direction has optical z = 1, so the ray parameter *is*
the depth) and the id of the surface hit.
"""
from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Callable

import cv2
import numpy as np

from asmonc_vision.sim.geometry import CameraPose, RigPose, camera_poses
from asmonc_vision.sim.rig import RigSettings
from asmonc_vision.sim.world import Hits, Terrace, World

#: Code of a surface hit: primitive index * FACES + face; primitive 0 is the base ground.
FACES = 64
SKY = -1
#: Direction towards the sun (world, unit) and the ambient share of the lighting.
SUN = np.array([0.35, 0.45, 0.82]) / np.linalg.norm([0.35, 0.45, 0.82])
AMBIENT = 0.45


@dataclass
class CastResult:
    """The first surface along each ray of a grid.

    Attributes:
        t: (h, w) ray parameter = depth along the optical axis, metres (inf = sky);
            float64 for the pixel-centre grid, float32 for the sample grid.
        code: (h, w) int32 primitive * FACES + face, or -1 (sky).
        rays: (rx, ry, rz), each (h, w), dtype as t: world ray directions (optical z
            component 1).
        prims: list of the primitives; index 0 is None (the base ground), then the
            obstacles active at that time.
        regions: per primitive, (v0, v1, u0, u1) grid index bounds where it may appear.
    """

    t: np.ndarray
    code: np.ndarray
    rays: np.ndarray
    prims: list
    regions: list


@dataclass
class StereoImages:
    """One rendered stereo pair with the left image's ground truth.

    Attributes:
        left, right: (H, W) uint8 mono8 images.
        depth: (H, W) float64 depth z (m) of each left pixel centre, left optical frame;
            inf where the ray sees the sky.
        labels: (H, W) int32: 0 ground, k > 0 obstacle id, -1 sky.
        faces: (H, W) int32 face index of the surface hit (0 = top of a terrace), -1 sky.
        left_pose, right_pose: the optical frames in the world.
    """

    left: np.ndarray
    right: np.ndarray
    depth: np.ndarray
    labels: np.ndarray
    faces: np.ndarray
    left_pose: CameraPose
    right_pose: CameraPose


def _grid_dirs(rig: RigSettings, ss: int) -> tuple[np.ndarray, np.ndarray]:
    """Camera-frame ray directions ((u-cx)/f, (v-cy)/f, 1) of the sample grid: the
    x and y components, each (H*ss * W*ss,) float64 in row-major order."""
    u = (np.arange(rig.width * ss) + 0.5) / ss - 0.5
    v = (np.arange(rig.height * ss) + 0.5) / ss - 0.5
    uu, vv = np.meshgrid((u - rig.cx) / rig.focal, (v - rig.cy) / rig.focal)
    return uu.ravel(), vv.ravel()


class StereoRenderer:
    """Renders stereo pairs of a ``World`` for a ``RigSettings``.

    Args:
        rig: camera and image formation settings.
        threads: worker threads for ``render`` (left, right and ground truth are cast
            concurrently; numpy and OpenCV release the GIL). 1 = sequential. The output
            does not depend on it.
    """

    def __init__(self, rig: RigSettings, threads: int = 2) -> None:
        self.rig = rig
        self._pool = ThreadPoolExecutor(max_workers=threads) if threads > 1 else None
        self.ss = int(rig.supersample)
        # float32 for the shaded sample grid (speed); float64 for the ground truth
        self._sample_dirs = tuple(a.astype(np.float32) for a in _grid_dirs(rig, self.ss))
        self._centre_dirs = _grid_dirs(rig, 1)
        h, w = rig.height, rig.width
        v, u = np.mgrid[0:h, 0:w]
        r2 = ((u - rig.cx) ** 2 + (v - rig.cy) ** 2) / (rig.cx ** 2 + rig.cy ** 2 + 1e-9)
        self._vignette = (1.0 - rig.vignetting * np.clip(r2, 0, 1.5)).astype(np.float32)

    # ------------------------------------------------------------------ casting

    def _cull(self, corners, cam: CameraPose, h: int, w: int, ss: int):
        """Grid index bounds (v0, v1, u0, u1) containing the projection of the convex
        hull of world points ``corners`` (M, 3), clipped to the near plane; None when
        it is behind the camera or outside the image."""
        near = 1e-3
        pc = cam.to_optical(corners)
        z = pc[:, 2]
        front = z >= near
        if not front.any():
            return None
        pts = [pc[front]]
        back = ~front
        if back.any():
            pf, pb = pc[front], pc[back]
            zf, zb = pf[:, 2][:, None], pb[:, 2][None, :]
            a = (zf - near) / (zf - zb)                       # (F, B) in (0, 1]
            cut = pf[:, None, :] + a[..., None] * (pb[None, :, :] - pf[:, None, :])
            pts.append(cut.reshape(-1, 3))
        p = np.vstack(pts)
        zz = np.maximum(p[:, 2], near)
        u = self.rig.focal * p[:, 0] / zz + self.rig.cx
        v = self.rig.focal * p[:, 1] / zz + self.rig.cy
        u0 = max(int(math.floor((u.min() + 0.5) * ss - 0.5)) - 1, 0)
        u1 = min(int(math.ceil((u.max() + 0.5) * ss - 0.5)) + 2, w)
        v0 = max(int(math.floor((v.min() + 0.5) * ss - 0.5)) - 1, 0)
        v1 = min(int(math.ceil((v.max() + 0.5) * ss - 0.5)) + 2, h)
        if u0 >= u1 or v0 >= v1:
            return None
        return (v0, v1, u0, u1)

    def cast(self, world: World, t: float, cam: CameraPose, centre: bool = False
             ) -> CastResult:
        """Cast the sample grid (``centre=False``) or the pixel-centre grid.

        Args:
            world: the scene; obstacles active at time ``t`` (s) are used.
            t: seconds.
            cam: the optical frame the rays start from.
            centre: True for one float64 ray per pixel centre (ground truth), False for
                the float32 supersampling grid.
        Returns:
            CastResult.
        """
        ss = 1 if centre else self.ss
        h, w = self.rig.height * ss, self.rig.width * ss
        d = self._centre_dirs if centre else self._sample_dirs
        o = np.asarray(cam.centre, float)
        rot = [[float(v) for v in row] for row in cam.rotation]
        rays = tuple((d[0] * rot[k][0] + d[1] * rot[k][1] + rot[k][2]).reshape(h, w)
                     for k in range(3))
        rx, ry, rz = rays
        if world.profile is None:
            n, off = world.ground.plane
            nx, ny, nz = (float(v) for v in n)
            with np.errstate(divide='ignore', invalid='ignore'):
                t_best = (float(off - o @ n)) / (rx * nx + ry * ny + rz * nz)
            t_best[~(t_best > 1e-6)] = np.inf
            code = np.where(np.isfinite(t_best), 0, SKY).astype(np.int32)
        else:   # the profile's planar pieces; the face index is the piece
            t_best, piece = world.profile.intersect(world.ground.gradient, world.ground.z0,
                                                    o, rx, ry, rz)
            code = np.where(np.isfinite(t_best), piece, SKY).astype(np.int32)
        prims: list = [None]
        regions: list = [(0, h, 0, w)]
        active = world.active(t)
        for ob in active:
            if isinstance(ob, Terrace):
                region = self._cull(ob.bounds_with(world.ground), cam, h, w, ss)
            else:
                region = self._cull(ob.bounds(), cam, h, w, ss)
            if region is None:
                continue
            v0, v1, u0, u1 = region
            sub = (slice(v0, v1), slice(u0, u1))
            srx, sry, srz = (a[sub].ravel() for a in rays)
            tb = t_best[sub]
            cb = code[sub]
            if isinstance(ob, Terrace):
                # the base plane inside the polygon is not there (raised or sunk)
                inside = ob.contains(float(o[0]) + tb * rx[sub],
                                     float(o[1]) + tb * ry[sub]) & (cb >= 0) & (cb < FACES)
                tb[inside] = np.inf
                cb[inside] = SKY
                edges = [i for i in range(len(ob.polygon)) if self._cull(
                    ob.edge_corners(world.ground, i), cam, h, w, ss) is not None]
                tt, ff = ob.intersect_with(world.ground, o, srx, sry, srz, edges)
            else:
                tt, ff = ob.intersect(o, srx, sry, srz)
            idx = len(prims)
            prims.append(ob)
            regions.append(region)
            tt = tt.reshape(tb.shape)
            better = tt < tb
            tb[better] = tt[better]
            cb[better] = idx * FACES + ff.reshape(tb.shape)[better]
        return CastResult(t=t_best, code=code, rays=rays, prims=prims, regions=regions)

    # ------------------------------------------------------------------ shading

    def radiance(self, world: World, t: float, cam: CameraPose) -> np.ndarray:
        """Scene radiance seen by one camera, averaged over each pixel's samples.

        Args:
            world: the scene at time ``t`` (s); cam: the camera's optical frame.
        Returns:
            (H, W) float32, grey levels (before the camera model).
        """
        res = self.cast(world, t, cam, centre=False)
        h, w = res.t.shape
        f32 = np.float32
        rx, ry, rz = (a.ravel() for a in res.rays)
        o = np.asarray(cam.centre, float)
        code = res.code.ravel()
        out = np.empty(code.shape, f32)
        sky = np.flatnonzero(code == SKY)
        if sky.size:   # brighter upwards
            sx, sy, sz = rx[sky], ry[sky], rz[sky]
            elev = sz / np.sqrt(sx * sx + sy * sy + sz * sz)
            out[sky] = 190.0 + 40.0 * np.clip(elev * (1 / 0.35), 0.0, 1.0)
        tflat = res.t.ravel()
        step = 1.0 / (self.rig.focal * self.ss)
        r_u = (cam.rotation[:, 0] * step).astype(f32)
        r_v = (cam.rotation[:, 1] * step).astype(f32)
        for idx, (ob, region) in enumerate(zip(res.prims, res.regions)):
            v0, v1, u0, u1 = region
            if idx == 0:
                sel = np.flatnonzero((code >= 0) & (code < FACES))
            else:
                sub = res.code[v0:v1, u0:u1]
                rows, cols = np.nonzero((sub >= idx * FACES) & (sub < (idx + 1) * FACES))
                sel = (rows + v0) * w + (cols + u0)
            if sel.size == 0:
                continue
            tt = tflat[sel]
            sx, sy, sz = rx[sel], ry[sel], rz[sel]
            px, py, pz = (float(o[0]) + tt * sx, float(o[1]) + tt * sy,
                          float(o[2]) + tt * sz)
            face = code[sel] % FACES
            if ob is None and world.profile is not None:
                n = world.profile.normals(world.ground.gradient)[face].astype(f32)
                nx, ny, nz = n[:, 0], n[:, 1], n[:, 2]
            elif ob is None:
                nx, ny, nz = (f32(c) for c in world.ground.plane[0])
            else:
                nx, ny, nz = (np.asarray(c, f32) for c in ob.normal(world, px, py, pz, face))
            tt, sx, sy, sz = (a.astype(f32, copy=False) for a in (tt, sx, sy, sz))
            rn = nx * sx + ny * sy + nz * sz
            rn[np.abs(rn) < 1e-9] = f32(1e-9)
            inv = tt / rn
            ku = (nx * r_u[0] + ny * r_u[1] + nz * r_u[2]) * inv
            kv = (nx * r_v[0] + ny * r_v[1] + nz * r_v[2]) * inv
            hits = Hits(px, py, pz,
                        tt * r_u[0] - ku * sx, tt * r_u[1] - ku * sy, tt * r_u[2] - ku * sz,
                        tt * r_v[0] - kv * sx, tt * r_v[1] - kv * sy, tt * r_v[2] - kv * sz,
                        face, o)
            if ob is None:
                alb = world.ground_albedo(hits)
            else:
                alb = ob.surface_albedo(world, hits)
            lam = (AMBIENT + (1 - AMBIENT) * np.clip(nx * SUN[0] + ny * SUN[1] + nz * SUN[2],
                                                     0.0, None)) / (
                AMBIENT + (1 - AMBIENT) * SUN[2])
            out[sel] = alb * np.asarray(lam, f32)
        img = cv2.resize(out.reshape(h, w), (self.rig.width, self.rig.height),
                         interpolation=cv2.INTER_AREA)
        return img.astype(np.float32)

    def sensor(self, radiance: np.ndarray, gain: float, offset: float,
               rng: np.random.Generator) -> np.ndarray:
        """Camera model: vignetting, blur, gain/offset, noise, mono8.

        Args:
            radiance: (H, W) float32 grey levels.
            gain, offset: this camera's response (grey = gain * radiance + offset).
            rng: noise source.
        Returns:
            (H, W) uint8.
        """
        img = radiance * self._vignette
        if self.rig.blur_sigma > 0:
            img = cv2.GaussianBlur(img, (0, 0), self.rig.blur_sigma,
                                   borderType=cv2.BORDER_REFLECT)
        img = gain * img + offset
        if self.rig.noise_sigma > 0:
            img = img + rng.normal(0.0, self.rig.noise_sigma, img.shape)
        return np.clip(np.rint(img), 0, 255).astype(np.uint8)

    # ------------------------------------------------------------------ public

    def truth(self, world: World, t: float, cam: CameraPose
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Ground truth through each pixel centre of a camera.

        Args:
            world: the scene at time ``t`` (s); cam: the camera's optical frame.
        Returns:
            depth (H, W) float64 metres (inf = sky), labels (H, W) int32 (0 ground,
            k obstacle id, -1 sky), faces (H, W) int32 (-1 sky).
        """
        res = self.cast(world, t, cam, centre=True)
        ids = np.array([0] + [ob.id for ob in res.prims[1:]], np.int32)
        hit = res.code >= 0
        labels = np.where(hit, ids[np.where(hit, res.code // FACES, 0)], SKY).astype(np.int32)
        faces = np.where(hit, res.code % FACES, -1).astype(np.int32)
        return res.t.copy(), labels, faces

    def exposed_radiance(self, world: World, t: float, pose: RigPose, right: bool,
                         pose_at: Callable[[float], RigPose] | None = None) -> np.ndarray:
        """One camera's radiance over the exposure: the radiance at ``t`` when
        ``exposure_time`` is 0 (or ``pose_at`` is None), else the mean of
        ``exposure_samples`` renders at times spread evenly over the exposure centred on
        ``t`` (rig poses from ``pose_at``, people where they are at each time). The
        right camera's rectification residual (``right_shift_px``,
        ``right_rotation_deg``) is applied to its radiance image.

        Returns:
            (H, W) float32 grey levels.
        """
        rig = self.rig
        if rig.exposure_time > 0 and pose_at is not None:
            n = int(rig.exposure_samples)
            acc = None
            for k in range(n):
                tk = t + rig.exposure_time * ((k + 0.5) / n - 0.5)
                cams = camera_poses(pose_at(tk), rig.baseline, rig.right_misalignment)
                r = self.radiance(world, tk, cams[1 if right else 0])
                acc = r if acc is None else acc + r
            rad = acc * np.float32(1.0 / n)
        else:
            cams = camera_poses(pose, rig.baseline, rig.right_misalignment)
            rad = self.radiance(world, t, cams[1 if right else 0])
        if right and (rig.right_shift_px or rig.right_rotation_deg):
            m = cv2.getRotationMatrix2D((rig.cx, rig.cy), rig.right_rotation_deg, 1.0)
            m[1, 2] += rig.right_shift_px
            rad = cv2.warpAffine(rad, m, (rig.width, rig.height), flags=cv2.INTER_LINEAR,
                                 borderMode=cv2.BORDER_REFLECT)
        return rad

    def render(self, world: World, t: float, pose: RigPose,
               rng: np.random.Generator | int | None = None,
               pose_at: Callable[[float], RigPose] | None = None,
               exposure: tuple[float, float] = (1.0, 1.0)) -> StereoImages:
        """Render the stereo pair seen from ``pose`` at time ``t`` (s).

        Args:
            world: the scene.
            t: seconds; selects the obstacles that exist (and where people are).
            pose: the rig (body frame) pose in the world at ``t``.
            rng: seed or Generator for the camera noise.
            pose_at: the rig pose at any time (s), for motion blur (``exposure_time``).
            exposure: (left, right) gain factors of the auto-exposure (``exposure_gains``).
        Returns:
            StereoImages (mono8 pair, left depth/labels/faces at ``t``, camera poses).
        """
        rng = np.random.default_rng(rng)
        left_cam, right_cam = camera_poses(pose, self.rig.baseline,
                                           self.rig.right_misalignment)
        plain = not self.rig.realism
        if plain:   # the original path, kept for identical output
            jobs = ((self.radiance, world, t, left_cam), (self.radiance, world, t, right_cam))
        else:
            jobs = ((self.exposed_radiance, world, t, pose, False, pose_at),
                    (self.exposed_radiance, world, t, pose, True, pose_at))
        if self._pool is not None:
            fut = [self._pool.submit(*j) for j in jobs]
            fut.append(self._pool.submit(self.truth, world, t, left_cam))
            rad_l, rad_r, (depth, labels, faces) = (j.result() for j in fut)
        else:
            rad_l = jobs[0][0](*jobs[0][1:])
            rad_r = jobs[1][0](*jobs[1][1:])
            depth, labels, faces = self.truth(world, t, left_cam)
        gl, gr = (float(g) for g in exposure)
        left = self.sensor(rad_l, self.rig.left_gain * gl, self.rig.left_offset, rng)
        right = self.sensor(rad_r, self.rig.right_gain * gr, self.rig.right_offset, rng)
        return StereoImages(left=left, right=right, depth=depth, labels=labels, faces=faces,
                            left_pose=left_cam, right_pose=right_cam)


def exposure_gains(rig: RigSettings, seed: int, t: float) -> tuple[float, float]:
    """Auto-exposure gain factors (left, right) at time t (s) for ``rig.gain_drift``.

    ``1 + A (c(t) + e(t) / 4)``: ``c`` shared by both cameras, ``e`` each camera's own,
    each a sum of three sines of periods 0.6-1.6 x ``gain_drift_period`` with phases
    drawn from ``seed``, normalised to unit amplitude. (1, 1) when the drift is off.
    """
    if rig.gain_drift <= 0:
        return 1.0, 1.0
    g = np.random.default_rng([int(seed), 0xE4905])
    per = rig.gain_drift_period * g.uniform(0.6, 1.6, (3, 3))
    ph = g.uniform(0.0, 2 * np.pi, (3, 3))
    wave = np.sum(np.sin(2 * np.pi * t / per + ph), axis=1) / 3.0
    return (1.0 + rig.gain_drift * (wave[0] + wave[1] / 4.0),
            1.0 + rig.gain_drift * (wave[0] + wave[2] / 4.0))
