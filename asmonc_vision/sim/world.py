"""The simulated world: a tiled pavement and obstacles, with ray intersection and textures.

World frame: z up, metres. The ground is a plane (optionally sloped) covered by a tiled
pavement; ``Terrace`` regions raise or lower convex parts of it (a kerb up, a step
down). ``Box`` and ``Cylinder`` obstacles stand on the ground (posts, bollards, doors,
walls are built from them, see the helper functions).

Every surface answers three questions for a batch of rays ``X = o + t r`` (``o`` (3,),
directions as three (N,) float64 arrays, not normalised): ``intersect`` (ray parameter t
of the first entry, ``inf`` if none, and a face index), ``normal`` (unit normal of the
visible side) and ``surface_albedo`` (grey levels before lighting, pre-filtered by the
sample footprint, see ``Hits``).

Obstacle ids are assigned by ``World`` in the order given, starting at 1 (label 0 is
the ground, -1 the sky).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from asmonc_vision.core.config import check_fields, param
from asmonc_vision.sim.relief import GroundProfile
from asmonc_vision.sim.surfaces import PAVEMENT_KINDS, Marking, apply_markings
from asmonc_vision.sim.texture import ValueNoise, detail_gain, line_coverage

_EPS_T = 1e-6
_INF = np.inf
_F = np.float32

# --------------------------------------------------------------------------- samples


@dataclass
class Hits:
    """Surface samples to shade (structure of arrays, all (N,)).

    Attributes:
        px, py, pz: float32 (sample grid) or float64 hit points, world metres.
        dux, duy, duz, dvx, dvy, dvz: float32 surface displacement (m) per sample step
            along the image u and v axes (ray differentials), world.
        face: int32 face index of the primitive hit.
        origin: (3,) float64 the viewing camera's centre.
    """

    px: np.ndarray
    py: np.ndarray
    pz: np.ndarray
    dux: np.ndarray
    duy: np.ndarray
    duz: np.ndarray
    dvx: np.ndarray
    dvy: np.ndarray
    dvz: np.ndarray
    face: np.ndarray
    origin: np.ndarray

    def subset(self, m) -> 'Hits':
        """The samples selected by a boolean mask or index array."""
        return Hits(*(getattr(self, f.name)[m] for f in dataclasses.fields(self)[:-1]),
                    origin=self.origin)

    def foot_h(self, ax: float, ay: float) -> np.ndarray:
        """Footprint (m, float32) along the horizontal unit axis (ax, ay)."""
        ax, ay = _F(ax), _F(ay)
        return np.abs(self.dux * ax + self.duy * ay) + np.abs(self.dvx * ax + self.dvy * ay)

    def foot_z(self) -> np.ndarray:
        """Footprint (m, float32) along world z."""
        return np.abs(self.duz) + np.abs(self.dvz)


def _smoothstep(x) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


# --------------------------------------------------------------------------- ground


@dataclass(frozen=True)
class PavementSettings:
    """The pavement covering the ground. Frozen; validated on construction.

    ``kind`` 'tiles' (the default) uses every field; 'asphalt' (fine grain, no joints)
    uses brightness, texture_contrast and the fade; 'concrete' (large slabs with thin
    joints and a brushed finish) uses the tile fields as slab sizes and joints.
    """

    kind: str = param('tiles', 'pavement kind', choices=('tiles', 'asphalt', 'concrete'))
    tile_length: float = param(0.45, 'tile size along the pavement a axis, metres',
                               range=(0.05, 3.0))
    tile_width: float = param(0.45, 'tile size along the pavement b axis, metres',
                              range=(0.05, 3.0))
    grout_width: float = param(0.012, 'width of the dark grout lines, metres',
                               range=(0.0, 0.1))
    pattern: str = param('grid', 'tile layout', choices=('grid', 'running_bond'))
    yaw_deg: float = param(0.0, 'direction of the pavement a axis in the world, degrees '
                           'from world x', range=(-180.0, 180.0))
    brightness: float = param(125.0, 'mean tile albedo, grey levels', range=(10.0, 240.0))
    tile_spread: float = param(0.12, 'per-tile relative brightness variation (+/-)',
                               range=(0.0, 0.5))
    grout_brightness: float = param(60.0, 'grout albedo, grey levels', range=(0.0, 240.0))
    texture_contrast: float = param(0.25, 'relative amplitude of the fine value-noise '
                                    'texture', range=(0.0, 0.6))
    fade_start: float = param(40.0, 'distance where the texture starts fading to '
                              'uniform, metres', range=(5.0, 1000.0))
    fade_end: float = param(80.0, 'distance beyond which the ground is uniform, metres',
                            range=(5.0, 1000.0))

    def __post_init__(self) -> None:
        check_fields(self)
        if self.grout_width >= min(self.tile_length, self.tile_width):
            raise ValueError('PavementSettings.grout_width must be smaller than the tiles')
        if self.fade_end <= self.fade_start:
            raise ValueError('PavementSettings.fade_end must exceed fade_start')

    @property
    def mean_albedo(self) -> float:
        """Average albedo over many tiles (grout included), grey levels."""
        if self.kind == 'asphalt':
            return self.brightness
        g = 1.0 - (1.0 - self.grout_width / self.tile_length) * (
            1.0 - self.grout_width / self.tile_width)
        return (1.0 - g) * self.brightness + g * self.grout_brightness


@dataclass(frozen=True)
class Ground:
    """The base ground plane ``z = z0 + tan(slope) * (x cos(psi) + y sin(psi))``.

    ``slope_deg`` > 0 rises towards the world direction ``slope_yaw_deg``.
    """

    slope_deg: float = param(0.0, 'ground slope, degrees (rising towards slope_yaw_deg)',
                             range=(-30.0, 30.0))
    slope_yaw_deg: float = param(0.0, 'world direction of steepest ascent, degrees',
                                 range=(-180.0, 180.0))
    z0: float = param(0.0, 'ground height at the world origin, metres',
                      range=(-1000.0, 1000.0))
    pavement: PavementSettings = field(default_factory=PavementSettings)

    def __post_init__(self) -> None:
        check_fields(self)

    @property
    def gradient(self) -> np.ndarray:
        """(2,) dz/dx, dz/dy of the base plane."""
        g = math.tan(math.radians(self.slope_deg))
        psi = math.radians(self.slope_yaw_deg)
        return np.array([g * math.cos(psi), g * math.sin(psi)])

    @property
    def plane(self) -> tuple[np.ndarray, float]:
        """(N (3,) unit up normal, offset) with ``N . X = offset`` on the base plane."""
        gx, gy = self.gradient
        n = np.array([-gx, -gy, 1.0])
        k = float(np.linalg.norm(n))
        return n / k, self.z0 / k

    def height(self, x, y) -> np.ndarray:
        """Base plane height z (m) at world x, y (arrays of equal shape; the dtype of
        float arrays is kept)."""
        gx, gy = (float(g) for g in self.gradient)
        if gx == 0.0 and gy == 0.0:
            return np.full(np.broadcast(x, y).shape, float(self.z0),
                           np.result_type(np.asarray(x), np.float32))
        return float(self.z0) + gx * np.asarray(x) + gy * np.asarray(y)

    def surface_albedo(self, noise: ValueNoise, h: Hits) -> np.ndarray:
        """Pavement albedo (grey levels, float32 (N,)) of ground samples ``h``."""
        pv = self.pavement
        if pv.kind != 'tiles':
            out = PAVEMENT_KINDS[pv.kind](pv, noise, h)
            return _fade(pv, h, out)
        c, s = math.cos(math.radians(pv.yaw_deg)), math.sin(math.radians(pv.yaw_deg))
        a = (h.px * c + h.py * s).astype(_F)
        b = (h.py * c - h.px * s).astype(_F)
        fa = h.foot_h(c, s)
        fb = h.foot_h(-s, c)
        row = np.floor(b * _F(1.0 / pv.tile_width))
        if pv.pattern == 'running_bond':
            a_t = a + (row.astype(np.int64) & 1).astype(_F) * _F(pv.tile_length / 2.0)
        else:
            a_t = a
        col = np.floor(a_t * _F(1.0 / pv.tile_length))
        tile_gain = detail_gain(fa, pv.tile_length) * detail_gain(fb, pv.tile_width)
        tile = (noise.cell(col, row) * _F(2.0) - _F(1.0)) * tile_gain
        tile *= _F(pv.tile_spread)
        tile += _F(1.0)
        tex = noise.fbm(a, b, (0.12, 0.045, 0.018), (0.4, 0.33, 0.27), fa, fb)
        tile *= _F(pv.brightness) * (_F(1.0) + _F(pv.texture_contrast) * tex)
        half = _F(pv.grout_width / 2.0)
        ca = line_coverage(a_t + half, pv.tile_length, pv.grout_width, fa)
        cb = line_coverage(b + half, pv.tile_width, pv.grout_width, fb)
        keep = (_F(1.0) - ca) * (_F(1.0) - cb)   # 1 - grout coverage
        out = keep * (tile - _F(pv.grout_brightness)) + _F(pv.grout_brightness)
        return _fade(pv, h, out)


def _fade(pv: PavementSettings, h: Hits, out: np.ndarray) -> np.ndarray:
    """Fade the albedo ``out`` (float32 (N,), changed in place) of ground samples to the
    pavement's mean beyond ``fade_start`` m from the camera."""
    dx = h.px - _F(h.origin[0])
    dy = h.py - _F(h.origin[1])
    dist2 = dx * dx
    dist2 += dy * dy
    far = np.flatnonzero(dist2 > _F(pv.fade_start ** 2))
    if far.size:
        w = _smoothstep((np.sqrt(dist2[far]) - pv.fade_start)
                        / (pv.fade_end - pv.fade_start)).astype(_F)
        out[far] += w * (_F(pv.mean_albedo) - out[far])
    return out


# --------------------------------------------------------------------------- obstacles


@dataclass(frozen=True, kw_only=True)
class Obstacle:
    """Common obstacle fields.

    Attributes:
        kind: 'box', 'post', 'bollard', 'door', 'wall', 'kerb', 'drop', ...
        name: free text for logs and the bag README.
        albedo: mean albedo of its faces, grey levels.
        appear, vanish: seconds; the obstacle exists for appear <= t < vanish.
        id: ground-truth id (>= 1); assigned by ``World``.
        texture: strength of the side faces' texture, relative (1: the usual; 0: a plain
            painted face, which shows no edges but its outline).
    """

    kind: str = 'box'
    name: str = ''
    albedo: float = 70.0
    appear: float = -math.inf
    vanish: float = math.inf
    id: int = 0
    texture: float = 1.0

    def __post_init__(self) -> None:
        if not 0.0 <= self.texture <= 1.0:
            raise ValueError(f'texture = {self.texture} must be in [0, 1]')

    def active(self, t: float) -> bool:
        """Whether the obstacle exists at time t (s)."""
        return self.appear <= t < self.vanish

    def at(self, t: float, world: 'World') -> 'Obstacle':
        """The obstacle as it is at time t (s): itself, unless it moves (``Person``)."""
        return self

    @property
    def finite(self) -> bool:
        """True for compact obstacles (analytic ground truth), False for terraces."""
        return True

    def _stripes(self, noise: ValueNoise, h: Hits, foot_s, foot_z) -> np.ndarray:
        """Relative texture of a vertical face with vertical structure: value noise of
        world (x, y) only (constant along z, world-fixed, seamless round corners), plus
        faint 2-D detail. float32 (N,), roughly in [-0.4, 0.4]."""
        k = 10 + 4 * self.id
        x = (h.px + 3.1 * self.id).astype(_F)
        y = h.py.astype(_F)
        v = noise.fbm(x, y, (0.11, 0.045, 0.02), (0.45, 0.35, 0.2), foot_s, foot_s,
                      first_octave=k)
        d = noise.fbm(x + y, h.pz.astype(_F), (0.05,), (1.0,), foot_s, foot_z,
                      first_octave=k + 3)
        return _F(self.texture) * (_F(0.35) * v + _F(0.06) * d)   # x 1.0 is exact


@dataclass(frozen=True, kw_only=True)
class Box(Obstacle):
    """An upright box (also posts, doors, walls) standing on the ground.

    Attributes:
        x, y: centre of the footprint, world metres.
        length, width: footprint along the box's own x and y axes, metres.
        height: top above the ground under the centre, metres.
        yaw_deg: direction of the box x axis in the world, degrees.
        lift: gap between the ground and the bottom, metres (a door's bottom gap).
        base_z: z of the ground under the centre; None = set by ``World``.
    """

    x: float
    y: float
    length: float
    width: float
    height: float
    yaw_deg: float = 0.0
    lift: float = 0.0
    base_z: float | None = None

    def _axes(self) -> tuple[float, float]:
        return math.cos(math.radians(self.yaw_deg)), math.sin(math.radians(self.yaw_deg))

    @property
    def z_top(self) -> float:
        """World z of the top face, metres."""
        return float(self.base_z) + self.height

    def bounds(self) -> np.ndarray:
        """(8, 3) world corners of the box."""
        xy = self.top_polygon()[:, :2]
        return np.vstack([np.column_stack([xy, np.full(4, z)])
                          for z in (float(self.base_z) + self.lift, self.z_top)])

    def top_polygon(self) -> np.ndarray:
        """(4, 3) world corners of the top face, counter-clockwise seen from above."""
        c, s = self._axes()
        hl, hw = self.length / 2.0, self.width / 2.0
        loc = np.array([[-hl, -hw], [hl, -hw], [hl, hw], [-hl, hw]])
        xy = loc @ np.array([[c, s], [-s, c]]) + [self.x, self.y]
        return np.column_stack([xy, np.full(4, self.z_top)])

    def intersect(self, o, rx, ry, rz) -> tuple[np.ndarray, np.ndarray]:
        """First entry of rays ``o + t r`` into the box (slab method).

        Args:
            o: (3,) ray origin, world; rx, ry, rz: (N,) float64 ray directions.
        Returns:
            (t (N,) float64, inf where missed; face (N,) int32: 0 -x, 1 +x, 2 -y, 3 +y
            (box axes), 4 bottom, 5 top).
        """
        c, s = self._axes()
        ox, oy, oz = (float(v) for v in o)
        dx, dy = ox - self.x, oy - self.y
        ol = (c * dx + s * dy, -s * dx + c * dy, oz)
        rl = (c * rx + s * ry, c * ry - s * rx, rz)
        lo = (-self.length / 2, -self.width / 2, float(self.base_z) + self.lift)
        hi = (self.length / 2, self.width / 2, self.z_top)
        tnear = np.full(rx.shape, -_INF, rx.dtype)
        tfar = np.full(rx.shape, _INF, rx.dtype)
        face = np.zeros(rx.shape, np.int32)
        with np.errstate(divide='ignore', invalid='ignore'):
            for k in range(3):
                inv = 1.0 / rl[k]
                t1 = (lo[k] - ol[k]) * inv
                t2 = (hi[k] - ol[k]) * inv
                tmin = np.fmin(t1, t2)
                tmax = np.fmax(t1, t2)
                tmin = np.where(np.isnan(tmin), -_INF, tmin)
                tmax = np.where(np.isnan(tmax), _INF, tmax)
                upd = tmin > tnear
                tnear = np.where(upd, tmin, tnear)
                face = np.where(upd, 2 * k + (rl[k] < 0), face)
                tfar = np.minimum(tfar, tmax)
        hit = (tnear <= tfar) & (tnear > _EPS_T)
        return np.where(hit, tnear, _INF), face.astype(np.int32)

    def normal(self, world: 'World', px, py, pz, face):
        """Unit outward normals (nx, ny, nz) (N,) of the given faces."""
        c, s = self._axes()
        table = np.array([[-c, -s, 0], [c, s, 0], [s, -c, 0], [-s, c, 0],
                          [0, 0, -1], [0, 0, 1]], float)
        n = table[face]
        return n[:, 0], n[:, 1], n[:, 2]

    def surface_albedo(self, world: 'World', h: Hits) -> np.ndarray:
        """Albedo (float32 (N,)): vertical-structure texture on the sides, 2-D on top."""
        c, s = self._axes()
        out = np.empty(h.px.shape, _F)
        side = h.face < 4
        if side.any():
            hs = h.subset(side)
            along_y = hs.face < 2   # faces -x/+x run along the box y axis
            foot_s = np.where(along_y, hs.foot_h(-s, c), hs.foot_h(c, s))
            rel = self._stripes(world.noise, hs, foot_s, hs.foot_z())
            out[side] = _F(self.albedo) * (_F(1.0) + rel)
        top = ~side
        if top.any():
            ht = h.subset(top)
            f = ht.foot_h(1.0, 0.0) + ht.foot_h(0.0, 1.0)
            t = world.noise.fbm(ht.px.astype(_F), (ht.py + 5.3 * self.id).astype(_F),
                                (0.08, 0.03), (0.6, 0.4), f, f, first_octave=40 + self.id)
            out[top] = _F(self.albedo * 1.12) * (_F(1.0) + _F(0.15) * t)
        return out


@dataclass(frozen=True, kw_only=True)
class Cylinder(Obstacle):
    """An upright cylinder (post, bollard) standing on the ground.

    Attributes:
        x, y: axis position, world metres.
        radius: metres.
        height: top above the ground, metres.
        band: (lo, hi) heights (m above the ground) of a bright band (reflector), or None.
        base_z: z of the ground at the axis; None = set by ``World``.
    """

    x: float
    y: float
    radius: float
    height: float
    band: tuple[float, float] | None = None
    base_z: float | None = None
    kind: str = 'bollard'

    @property
    def z_top(self) -> float:
        """World z of the top cap, metres."""
        return float(self.base_z) + self.height

    def bounds(self) -> np.ndarray:
        """(8, 3) world corners of the bounding box."""
        r = self.radius
        return np.array([[self.x + sx * r, self.y + sy * r, z] for sx in (-1, 1)
                         for sy in (-1, 1) for z in (float(self.base_z), self.z_top)])

    def top_polygon(self, n: int = 48) -> np.ndarray:
        """(n, 3) world points around the top cap, counter-clockwise from above."""
        a = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
        return np.column_stack([self.x + self.radius * np.cos(a),
                                self.y + self.radius * np.sin(a), np.full(n, self.z_top)])

    def intersect(self, o, rx, ry, rz) -> tuple[np.ndarray, np.ndarray]:
        """First entry through the side (face 0) or the top cap (face 1); see Box."""
        ox, oy, oz = (float(v) for v in o)
        dx, dy = ox - self.x, oy - self.y
        a = rx * rx + ry * ry
        b = 2.0 * (dx * rx + dy * ry)
        c = dx * dx + dy * dy - self.radius ** 2
        disc = b * b - 4 * a * c
        with np.errstate(divide='ignore', invalid='ignore'):
            ts = (-b - np.sqrt(np.maximum(disc, 0.0))) / (2 * a)
            zs = oz + ts * rz
            side_ok = (disc >= 0) & (ts > _EPS_T) & (zs >= float(self.base_z)) & (
                zs <= self.z_top)
            tc = (self.z_top - oz) / rz
        xc = dx + tc * rx
        yc = dy + tc * ry
        cap_ok = (tc > _EPS_T) & np.isfinite(tc) & (xc * xc + yc * yc <= self.radius ** 2)
        ts = np.where(side_ok, ts, _INF)
        tc = np.where(cap_ok, tc, _INF)
        face = (tc < ts).astype(np.int32)
        return np.minimum(ts, tc), face

    def normal(self, world: 'World', px, py, pz, face):
        """Unit normals (nx, ny, nz): radial on the side, up on the cap."""
        cap = face == 1
        nx = np.where(cap, 0.0, (px - self.x) / self.radius)
        ny = np.where(cap, 0.0, (py - self.y) / self.radius)
        return nx, ny, cap.astype(float)

    def surface_albedo(self, world: 'World', h: Hits) -> np.ndarray:
        """Albedo (float32 (N,)): vertical stripes on the side, an optional band, cap."""
        out = np.empty(h.px.shape, _F)
        side = h.face == 0
        if side.any():
            hs = h.subset(side)
            tx = (-(hs.py - self.y) / self.radius).astype(_F)
            ty = ((hs.px - self.x) / self.radius).astype(_F)
            foot_s = (np.abs(hs.dux * tx + hs.duy * ty) + np.abs(hs.dvx * tx + hs.dvy * ty))
            foot_z = hs.foot_z()
            val = _F(self.albedo) * (_F(1.0) + self._stripes(world.noise, hs, foot_s, foot_z))
            if self.band is not None:
                lo, hi = self.band
                cov = line_coverage((hs.pz - float(self.base_z) - lo).astype(_F), 1e6,
                                    hi - lo, foot_z)
                val = val + cov * (_F(225.0) - val)
            out[side] = val
        if (~side).any():
            out[~side] = _F(self.albedo * 1.1)
        return out


@dataclass(frozen=True, kw_only=True)
class Terrace(Obstacle):
    """A convex region of ground raised (kerb up, ``rise`` > 0) or lowered (step down,
    ``rise`` < 0) by ``rise`` metres relative to the base plane.

    Its top is paved like the ground; its vertical faces (the polygon edges, from the base
    plane to the top) are kerb stones with vertical joints. Terraces must not overlap.

    Attributes:
        polygon: ((x, y), ...) convex, counter-clockwise, world metres (>= 3 vertices).
        rise: metres (non-zero).
        stone_length: kerb stone length along an edge, metres.
    """

    polygon: tuple[tuple[float, float], ...]
    rise: float
    stone_length: float = 0.8
    albedo: float = 165.0
    kind: str = 'kerb'

    def __post_init__(self) -> None:
        super().__post_init__()
        if len(self.polygon) < 3 or self.rise == 0:
            raise ValueError('Terrace needs >= 3 polygon vertices and a non-zero rise')
        p = np.asarray(self.polygon, float)
        e = np.roll(p, -1, axis=0) - p
        cross = e[:, 0] * np.roll(e, -1, axis=0)[:, 1] - e[:, 1] * np.roll(e, -1, axis=0)[:, 0]
        if np.any(cross <= 0):
            raise ValueError('Terrace polygon must be convex and counter-clockwise')

    @property
    def finite(self) -> bool:
        return False

    def _poly(self) -> np.ndarray:
        return np.asarray(self.polygon, float)

    def bounds_with(self, ground: Ground) -> np.ndarray:
        """(2M, 3) world corners of the prism between the base plane and the top."""
        p = self._poly()
        zb = ground.height(p[:, 0], p[:, 1])
        return np.vstack([np.column_stack([p, zb]), np.column_stack([p, zb + self.rise])])

    def contains(self, x, y) -> np.ndarray:
        """Whether world x, y (arrays) lie inside the polygon (edges included)."""
        poly = [(float(a), float(b)) for a, b in self.polygon]
        x = np.asarray(x)
        y = np.asarray(y)
        inside = np.ones(np.broadcast(x, y).shape, bool)
        with np.errstate(invalid='ignore'):   # inf coordinates (missed rays) are outside
            for i in range(len(poly)):
                p0, p1 = poly[i], poly[(i + 1) % len(poly)]
                inside &= (p1[0] - p0[0]) * (y - p0[1]) >= (p1[1] - p0[1]) * (x - p0[0])
        return inside

    def edge(self, i: int) -> tuple[np.ndarray, np.ndarray, float]:
        """Edge i (face i + 1): (start (2,), unit direction (2,), length m)."""
        poly = self._poly()
        p0, p1 = poly[i], poly[(i + 1) % len(poly)]
        length = float(np.hypot(*(p1 - p0)))
        return p0, (p1 - p0) / length, length

    def edge_corners(self, ground: Ground, i: int) -> np.ndarray:
        """(4, 3) world corners of the vertical face of edge i."""
        p0, e, length = self.edge(i)
        xy = np.array([p0, p0 + e * length])
        zb = ground.height(xy[:, 0], xy[:, 1])
        return np.vstack([np.column_stack([xy, zb]), np.column_stack([xy, zb + self.rise])])

    def intersect_with(self, ground: Ground, o, rx, ry, rz, edges=None
                       ) -> tuple[np.ndarray, np.ndarray]:
        """First hit on the top (face 0) or an edge face (face 1 + edge index); see Box.

        Args:
            edges: indices of the edges whose faces may be hit (default: all).
        """
        n, off = ground.plane
        nx, ny, nz = (float(v) for v in n)
        ox, oy, oz = (float(v) for v in o)
        with np.errstate(divide='ignore', invalid='ignore'):
            t_top = (float(off) + self.rise * nz - (ox * nx + oy * ny + oz * nz)) / (
                rx * nx + ry * ny + rz * nz)
        ok = (t_top > _EPS_T) & np.isfinite(t_top)
        ok &= self.contains(ox + t_top * rx, oy + t_top * ry)
        t_best = np.where(ok, t_top, _INF)
        face = np.zeros(rx.shape, np.int32)
        for i in (range(len(self.polygon)) if edges is None else edges):
            p0, e, length = self.edge(i)
            p0 = (float(p0[0]), float(p0[1]))
            e = (float(e[0]), float(e[1]))
            ne = (e[1], -e[0])  # outward normal (counter-clockwise polygon)
            with np.errstate(divide='ignore', invalid='ignore'):
                te = ((p0[0] - ox) * ne[0] + (p0[1] - oy) * ne[1]) / (
                    rx * ne[0] + ry * ne[1])
            xe = ox + te * rx
            ye = oy + te * ry
            ze = oz + te * rz
            s = (xe - p0[0]) * e[0] + (ye - p0[1]) * e[1]
            zb = ground.height(xe, ye)
            oke = (te > _EPS_T) & (s >= 0) & (s <= length)
            oke &= (ze >= zb + min(self.rise, 0.0)) & (ze <= zb + max(self.rise, 0.0))
            better = oke & (te < t_best)
            t_best = np.where(better, te, t_best)
            face = np.where(better, 1 + i, face)
        return t_best, face

    def normal(self, world: 'World', px, py, pz, face):
        """Unit normals (nx, ny, nz) of the visible sides (the ground normal on top)."""
        table = [world.ground.plane[0]]
        sign = 1.0 if self.rise > 0 else -1.0
        for i in range(len(self.polygon)):
            _, e, _ = self.edge(i)
            table.append(sign * np.array([e[1], -e[0], 0.0]))
        n = np.asarray(table)[face]
        return n[:, 0], n[:, 1], n[:, 2]

    def surface_albedo(self, world: 'World', h: Hits) -> np.ndarray:
        """Albedo (float32 (N,)): pavement on top, kerb stones with joints on faces."""
        out = np.empty(h.px.shape, _F)
        top = h.face == 0
        if top.any():
            out[top] = world.ground_albedo(h.subset(top))
        for i in np.unique(h.face[~top]):
            m = h.face == i
            hm = h.subset(m)
            p0, e, _ = self.edge(int(i) - 1)
            s = ((hm.px - float(p0[0])) * float(e[0])
                 + (hm.py - float(p0[1])) * float(e[1])).astype(_F)
            fs = hm.foot_h(e[0], e[1])
            fz = hm.foot_z()
            stone = np.floor(s * _F(1.0 / self.stone_length))
            base = _F(self.albedo) * (_F(1.0) + _F(0.1) * (
                _F(2.0) * world.noise.cell(stone, 97 * i + self.id) - _F(1.0))
                * detail_gain(fs, self.stone_length))
            tex = world.noise.fbm(s, hm.pz.astype(_F), (0.06, 0.02), (0.6, 0.4), fs, fz,
                                  first_octave=60 + self.id)
            joint = line_coverage(s + _F(0.006), self.stone_length, 0.012, fs)
            out[m] = (_F(1.0) - joint) * base * (_F(1.0) + _F(0.15) * tex) + joint * _F(
                0.45 * self.albedo)
        return out


# --------------------------------------------------------------------------- builders


def post(x: float, y: float, *, height: float = 2.2, size: float = 0.1,
         round_: bool = False, albedo: float = 60.0, **kw) -> Box | Cylinder:
    """A thin tall post: square (``size`` m side) or round (``size`` m diameter)."""
    if round_:
        return Cylinder(x=x, y=y, radius=size / 2.0, height=height, kind='post',
                        albedo=albedo, **kw)
    return Box(x=x, y=y, length=size, width=size, height=height, kind='post',
               albedo=albedo, **kw)


def bollard(x: float, y: float, *, height: float = 0.9, radius: float = 0.1,
            albedo: float = 55.0, **kw) -> Cylinder:
    """A short cylinder (0.8-1 m) with a bright reflective band near the top."""
    return Cylinder(x=x, y=y, radius=radius, height=height, kind='bollard',
                    band=(height - 0.17, height - 0.09), albedo=albedo, **kw)


def wall(x0: float, y0: float, x1: float, y1: float, *, height: float = 2.4,
         thickness: float = 0.2, albedo: float = 170.0, **kw) -> Box:
    """A wall whose face runs from (x0, y0) to (x1, y1) (centre line), world metres."""
    dx, dy = x1 - x0, y1 - y0
    return Box(x=(x0 + x1) / 2, y=(y0 + y1) / 2, length=float(np.hypot(dx, dy)),
               width=thickness, height=height, yaw_deg=math.degrees(math.atan2(dy, dx)),
               kind='wall', albedo=albedo, **kw)


def door(hinge_x: float, hinge_y: float, closed_yaw_deg: float, open_deg: float, *,
         width: float = 0.9, thickness: float = 0.04, height: float = 2.0,
         lift: float = 0.01, albedo: float = 95.0, **kw) -> Box:
    """A door slab hinged at (hinge_x, hinge_y), opened ``open_deg`` from its closed
    direction ``closed_yaw_deg`` (world degrees from the hinge to the latch edge)."""
    yaw = math.radians(closed_yaw_deg + open_deg)
    cx = hinge_x + math.cos(yaw) * width / 2
    cy = hinge_y + math.sin(yaw) * width / 2
    return Box(x=cx, y=cy, length=width, width=thickness, height=height,
               yaw_deg=math.degrees(yaw), lift=lift, kind='door', albedo=albedo, **kw)


def _band_polygon(x: float, y: float, yaw_deg: float, depth: float, half_width: float
                  ) -> tuple[tuple[float, float], ...]:
    """CCW rectangle starting at the line through (x, y) across direction yaw_deg."""
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    pts = [(0.0, -half_width), (depth, -half_width), (depth, half_width), (0.0, half_width)]
    return tuple((x + c * a - s * b, y + s * a + c * b) for a, b in pts)


def kerb_up(x: float, y: float, yaw_deg: float, *, rise: float = 0.12, depth: float = 4.0,
            half_width: float = 40.0, **kw) -> Terrace:
    """A raised region (kerb step up) whose near edge passes through (x, y) across the
    direction ``yaw_deg``, ``depth`` m deep along it and ``2 half_width`` m wide."""
    return Terrace(polygon=_band_polygon(x, y, yaw_deg, depth, half_width), rise=abs(rise),
                   kind='kerb', **kw)


def step_down(x: float, y: float, yaw_deg: float, *, drop: float = 0.15,
              depth: float = 300.0, half_width: float = 300.0, **kw) -> Terrace:
    """Ground beyond the line through (x, y) across ``yaw_deg`` drops by ``drop`` m."""
    return Terrace(polygon=_band_polygon(x, y, yaw_deg, depth, half_width),
                   rise=-abs(drop), kind='drop', **kw)


# --------------------------------------------------------------------------- world


class World:
    """The ground and its obstacles. Ids are 1..K in the order given.

    Args:
        ground: the base ground.
        obstacles: Box / Cylinder / Terrace / Person instances; ``id`` and ``base_z`` are
            filled.
        seed: texture seed (the value-noise lattice).
        profile: an optional height profile added to the base plane (slopes that start
            or end ahead, crests, dips, a kerb ramp; ``relief.GroundProfile``). Terraces
            keep their tops at ``rise`` above the base plane.
        markings: flat marks drawn on the ground (``surfaces.Marking``): paint, zebra
            stripes, manhole covers, grates, stains, shadows. They change the ground's
            albedo only: never obstacles.
    """

    def __init__(self, ground: Ground | None = None, obstacles: Sequence[Obstacle] = (),
                 seed: int = 0, profile: GroundProfile | None = None,
                 markings: Sequence[Marking] = ()) -> None:
        self.ground = ground if ground is not None else Ground()
        self.seed = int(seed)
        self.profile = profile
        self.markings = tuple(markings)
        lattice_seed = np.random.SeedSequence([self.seed, 0x7E47]).generate_state(1)[0]
        self.noise = ValueNoise(seed=int(lattice_seed))
        obs = [dataclasses.replace(o, id=i + 1) for i, o in enumerate(obstacles)]
        self.terraces = [o for o in obs if isinstance(o, Terrace)]
        resolved = []
        for o in obs:
            if not isinstance(o, Terrace) and getattr(o, 'base_z', 0.0) is None:
                o = dataclasses.replace(o, base_z=float(self.ground_height(o.x, o.y)))
            resolved.append(o)
        self.obstacles: list[Obstacle] = resolved

    def active(self, t: float) -> list[Obstacle]:
        """Obstacles that exist at time t (s), in id order, placed where they are at t."""
        return [o.at(t, self) for o in self.obstacles if o.active(t)]

    def terrace_at(self, x: float, y: float, t: float = 0.0) -> Terrace | None:
        """The terrace containing world (x, y) at time t, if any."""
        for o in self.terraces:
            if o.active(t) and bool(o.contains(x, y)):
                return o
        return None

    def ground_height(self, x, y, t: float = 0.0) -> np.ndarray:
        """Ground surface z (m) at world x, y (arrays), profile and terraces included."""
        base = self.ground.height(x, y)
        if self.profile is None:
            z = base
            for o in self.terraces:
                if o.active(t):
                    z = z + np.where(o.contains(x, y), o.rise, 0.0)
            return z
        z = base + self.profile.offset(x, y)
        for o in self.terraces:
            if o.active(t):
                z = np.where(o.contains(x, y), base + o.rise, z)
        return z

    def ground_gradient(self, x, y, t: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """(dz/dx, dz/dy) of the ground at world x, y (arrays of one shape, float64)."""
        shape = np.broadcast(np.asarray(x), np.asarray(y)).shape
        gx, gy = (float(v) for v in self.ground.gradient)
        if self.profile is None:
            return np.full(shape, gx), np.full(shape, gy)
        ax, ay = self.profile.gradient(x, y, (gx, gy))
        inside = np.zeros(shape, bool)
        for o in self.terraces:
            if o.active(t):
                inside |= o.contains(x, y)
        return np.where(inside, gx, ax), np.where(inside, gy, ay)

    def ground_plane(self, x: float, y: float, t: float = 0.0) -> tuple[np.ndarray, float]:
        """World plane of the ground at (x, y): (N (3,) unit up, offset), N . X = offset
        (the base plane, the terrace top, or the profile piece there)."""
        n, off = self.ground.plane
        ter = self.terrace_at(x, y, t)
        if ter is not None:
            off = off + ter.rise * n[2]
        elif self.profile is not None:
            k = int(self.profile.segment(self.profile.s(x, y)))
            n, off, _, _ = self.profile.pieces(self.ground.gradient, self.ground.z0)[k]
        return n, off

    def ground_albedo(self, h: Hits) -> np.ndarray:
        """Albedo (float32 (N,)) of ground samples: the pavement, then the markings."""
        out = self.ground.surface_albedo(self.noise, h)
        if self.markings:
            out = apply_markings(self.markings, self.noise, h, out)
        return out
