"""Ground surfaces beside the tiles: asphalt and concrete slabs, and flat markings.

Pavement kinds (``PAVEMENT_KINDS``, chosen by ``PavementSettings.kind``; the tiled
pavement itself lives in ``world.Ground``):

* ``asphalt``: no joints; fine aggregate grain (value noise of 4-25 mm wavelengths),
  sparse bright and dark stones, and large soft patches of wear (1-3 m).
* ``concrete``: large slabs (the tile sizes, 1-2 m) with thin dark joints, a small
  per-slab brightness spread, a brushed finish (fine streaks across the slab's a axis)
  and a faint mottle.

``Marking``: a flat mark on the ground, at height 0 (it changes the albedo of ground
samples and nothing else, so it is never an obstacle in the ground truth). A shape
(``rect`` or ``ellipse``, with a soft or noisy edge) is filled by a named rule
(``FILLS``): ``paint`` (painted lines, stop lines), ``stripes`` (zebra crossings: bars
across the mark's length axis), ``grate`` (a drainage grate: a metal frame with narrow
dark slots, a repetitive pattern that stereo matching mismatches), ``manhole`` (a metal
disc with a rim and a raised cross-hatch), ``multiply`` (stains, patches and cast
shadows: the ground darkened or brightened by ``factor``). All coverages are box-filtered
by the sample footprint (``Hits.foot_h``), so edges and bars alias no more than the
grout lines do.

All functions take a ``world.Hits`` (ground samples, float32 positions in metres) and
return float32 (N,) grey levels.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from asmonc_vision.sim.texture import ValueNoise, detail_gain, line_coverage

_F = np.float32


# --------------------------------------------------------------------------- pavements


def asphalt_albedo(pv, noise: ValueNoise, h) -> np.ndarray:
    """Asphalt: fine grain, stones and large wear patches (float32 (N,) grey levels)."""
    c, s = math.cos(math.radians(pv.yaw_deg)), math.sin(math.radians(pv.yaw_deg))
    a = (h.px * c + h.py * s).astype(_F)
    b = (h.py * c - h.px * s).astype(_F)
    fa = h.foot_h(c, s)
    fb = h.foot_h(-s, c)
    grain = noise.fbm(a, b, (0.025, 0.011, 0.0045), (0.4, 0.35, 0.3), fa, fb,
                      first_octave=20)
    patch = noise.fbm(a, b, (2.5, 0.9), (0.6, 0.4), fa, fb, first_octave=24)
    # sparse stones: bright (or dark) where a fine octave peaks, faded with the footprint
    stone = noise.sample(a, b, 0.008, 27)
    gain = detail_gain(fa + fb, 0.016)
    stones = np.clip((stone - _F(0.75)) * _F(4.0), _F(0.0), _F(1.0)) * gain
    out = _F(1.0) + _F(pv.texture_contrast) * (grain + _F(0.35) * patch)
    out += _F(0.5) * stones
    out *= _F(pv.brightness)
    return out


def concrete_albedo(pv, noise: ValueNoise, h) -> np.ndarray:
    """Concrete slabs with thin joints and a brushed finish (float32 (N,))."""
    c, s = math.cos(math.radians(pv.yaw_deg)), math.sin(math.radians(pv.yaw_deg))
    a = (h.px * c + h.py * s).astype(_F)
    b = (h.py * c - h.px * s).astype(_F)
    fa = h.foot_h(c, s)
    fb = h.foot_h(-s, c)
    row = np.floor(b * _F(1.0 / pv.tile_width))
    col = np.floor(a * _F(1.0 / pv.tile_length))
    slab_gain = detail_gain(fa, pv.tile_length) * detail_gain(fb, pv.tile_width)
    slab = _F(1.0) + (noise.cell(col + 31, row + 17) * _F(2.0) - _F(1.0)) * slab_gain * _F(
        pv.tile_spread)
    # brushed finish: streaks across a (long along b), plus a faint mottle
    brush = noise.fbm(a, b * _F(0.08), (0.006, 0.015), (0.6, 0.4), fa, fb * _F(0.08),
                      first_octave=30)
    mottle = noise.fbm(a, b, (0.35, 0.08, 0.025), (0.5, 0.3, 0.2), fa, fb, first_octave=33)
    tex = _F(pv.texture_contrast) * (_F(0.6) * brush + mottle)
    slab *= _F(pv.brightness) * (_F(1.0) + tex)
    half = _F(pv.grout_width / 2.0)
    ca = line_coverage(a + half, pv.tile_length, pv.grout_width, fa)
    cb = line_coverage(b + half, pv.tile_width, pv.grout_width, fb)
    keep = (_F(1.0) - ca) * (_F(1.0) - cb)
    return keep * (slab - _F(pv.grout_brightness)) + _F(pv.grout_brightness)


#: Pavement kind -> albedo function(PavementSettings, ValueNoise, Hits) (not 'tiles').
PAVEMENT_KINDS: dict[str, Callable] = {'asphalt': asphalt_albedo,
                                       'concrete': concrete_albedo}


# --------------------------------------------------------------------------- markings


@dataclass(frozen=True)
class Marking:
    """A flat mark on the ground (height 0: never an obstacle).

    Attributes:
        kind: what it is, for the docs and logs ('line', 'zebra', 'grate', 'manhole',
            'stain', 'patch', 'shadow').
        x, y: centre, world metres; yaw_deg: direction of its length axis (a), degrees.
        length, width: full extents along a and across (b), metres (an ellipse's
            diameters).
        shape: 'rect' or 'ellipse'.
        fill: the rule in ``FILLS``: 'paint', 'stripes', 'grate', 'manhole', 'multiply'.
        albedo: grey level of the paint, the bars, the metal.
        factor: for 'multiply', the ground's albedo is multiplied by it (0.5: a shadow).
        period, bar: 'stripes' / 'grate' / 'manhole' pattern period and bar (or slot)
            width along a, metres.
        edge: extra edge softness, metres (a shadow's penumbra).
        wobble: relative noise of an ellipse's outline (0 = a clean ellipse).
        wear: 'paint' worn away by up to this share.
    """

    kind: str
    x: float
    y: float
    yaw_deg: float
    length: float
    width: float
    shape: str = 'rect'
    fill: str = 'paint'
    albedo: float = 215.0
    factor: float = 0.6
    period: float = 1.0
    bar: float = 0.5
    edge: float = 0.0
    wobble: float = 0.0
    wear: float = 0.0

    def __post_init__(self) -> None:
        if self.shape not in ('rect', 'ellipse') or self.fill not in FILLS:
            raise ValueError(f'Marking: unknown shape {self.shape!r} or fill {self.fill!r}')
        if not (self.length > 0 and self.width > 0 and 0 < self.bar < self.period
                and self.factor >= 0 and self.edge >= 0):
            raise ValueError(f'Marking: bad sizes {self}')

    def coverage(self, noise: ValueNoise, a, b, fa, fb) -> np.ndarray:
        """Share (float32 (N,), 0-1) of each sample's footprint inside the shape."""
        ha, hb = _F(self.length / 2), _F(self.width / 2)
        if self.shape == 'rect':
            ca = np.clip(_F(0.5) + (ha - np.abs(a)) / (fa + _F(self.edge + 1e-4)), 0, 1)
            cb = np.clip(_F(0.5) + (hb - np.abs(b)) / (fb + _F(self.edge + 1e-4)), 0, 1)
            return (ca * cb).astype(_F)
        r = np.sqrt(np.square(a / ha) + np.square(b / hb))
        rim = _F(1.0)
        if self.wobble > 0:
            rim = rim + _F(self.wobble) * noise.sample(a, b, 0.35 * min(self.length,
                                                                         self.width),
                                                       41 + int(abs(self.x * 7)) % 5)
        dist = (rim - r) * _F(min(self.length, self.width) / 2)   # ~ metres inside
        soft = np.maximum(fa, fb) + _F(self.edge + 1e-4)
        return np.clip(_F(0.5) + dist / soft, 0, 1).astype(_F)


def _fill_paint(m: Marking, noise, a, b, fa, fb, cov, under):
    """Paint: ``albedo`` with a fine grain, worn away in places by up to ``wear``."""
    val = _F(m.albedo) * (_F(1.0) + _F(0.05) * noise.fbm(a, b, (0.02,), (1.0,), fa, fb,
                                                          first_octave=50))
    if m.wear > 0:
        worn = noise.fbm(a, b, (0.06, 0.02), (0.6, 0.4), fa, fb, first_octave=52)
        cov = cov * (_F(1.0) - _F(m.wear) * np.clip(worn + _F(0.5), 0, 1))
    return under + cov * (val - under)


def _fill_stripes(m: Marking, noise, a, b, fa, fb, cov, under):
    """Bars of width ``bar`` every ``period`` along a (zebra), painted ``albedo``."""
    bars = line_coverage(a + _F(m.length / 2), m.period, m.bar, fa)
    return _fill_paint(m, noise, a, b, fa, fb, cov * bars, under)


def _fill_grate(m: Marking, noise, a, b, fa, fb, cov, under):
    """A grate: metal (``albedo``) with dark slots of width ``bar`` every ``period``
    along a, inside a 3 cm frame."""
    frame = _F(0.03)
    inner_a = np.clip(_F(0.5) + (_F(m.length / 2) - frame - np.abs(a)) / (fa + _F(1e-4)),
                      0, 1)
    inner_b = np.clip(_F(0.5) + (_F(m.width / 2) - frame - np.abs(b)) / (fb + _F(1e-4)),
                      0, 1)
    slots = line_coverage(a + _F(m.length / 2), m.period, m.bar, fa) * inner_a * inner_b
    metal = _F(m.albedo) * (_F(1.0) + _F(0.08) * noise.fbm(a, b, (0.03,), (1.0,), fa, fb,
                                                           first_octave=55))
    val = metal + slots * (_F(18.0) - metal)
    return under + cov * (val - under)


def _fill_manhole(m: Marking, noise, a, b, fa, fb, cov, under):
    """A manhole cover: metal disc, a 4 cm darker rim, a raised cross-hatch (bright
    lines of width ``bar`` every ``period`` along a and b)."""
    hatch = np.maximum(line_coverage(a, m.period, m.bar, fa),
                       line_coverage(b, m.period, m.bar, fb))
    r = np.sqrt(a * a + b * b)
    rim = np.clip(_F(0.5) + (r - _F(m.length / 2 - 0.04)) / (np.maximum(fa, fb) + _F(1e-4)),
                  0, 1)
    val = _F(m.albedo) * (_F(1.0) + _F(0.35) * hatch * (_F(1.0) - rim) - _F(0.3) * rim)
    return under + cov * (val - under)


def _fill_multiply(m: Marking, noise, a, b, fa, fb, cov, under):
    """A stain, patch or shadow: the ground's albedo times ``factor``."""
    return under * (_F(1.0) - cov * _F(1.0 - m.factor))


#: Fill rule -> function(marking, noise, a, b, fa, fb, coverage, albedo under) -> albedo.
FILLS: dict[str, Callable] = {'paint': _fill_paint, 'stripes': _fill_stripes,
                              'grate': _fill_grate, 'manhole': _fill_manhole,
                              'multiply': _fill_multiply}


def apply_markings(markings: Sequence[Marking], noise: ValueNoise, h, albedo: np.ndarray
                   ) -> np.ndarray:
    """Draw the markings, in order, over the ground albedo of samples ``h``.

    Each mark touches only the samples inside its (rotated) bounding rectangle plus a
    margin for the footprint, so long thin lines and small marks cost little.

    Args:
        markings: the marks; noise: the world's value noise; h: ground samples (Hits).
        albedo: (N,) float32 pavement albedo of the samples (changed in place).
    Returns:
        (N,) float32 albedo.
    """
    for m in markings:
        c, s = math.cos(math.radians(m.yaw_deg)), math.sin(math.radians(m.yaw_deg))
        grow = 1.0 + m.wobble
        ha = m.length / 2 * grow + m.edge + 0.05
        hb = m.width / 2 * grow + m.edge + 0.05
        ex, ey = abs(c) * ha + abs(s) * hb, abs(s) * ha + abs(c) * hb
        dx = h.px - _F(m.x)
        sel = np.flatnonzero(np.abs(dx) < _F(ex))
        if sel.size == 0:
            continue
        dy = h.py[sel] - _F(m.y)
        keep = np.abs(dy) < _F(ey)
        sel, dx, dy = sel[keep], dx[sel[keep]], dy[keep]
        a = dx * _F(c) + dy * _F(s)
        b = dy * _F(c) - dx * _F(s)
        keep = (np.abs(a) < _F(ha)) & (np.abs(b) < _F(hb))
        if not keep.any():
            continue
        idx, a, b = sel[keep], a[keep], b[keep]
        dux, duy, dvx, dvy = h.dux[idx], h.duy[idx], h.dvx[idx], h.dvy[idx]
        fa = np.abs(dux * _F(c) + duy * _F(s)) + np.abs(dvx * _F(c) + dvy * _F(s))
        fb = np.abs(duy * _F(c) - dux * _F(s)) + np.abs(dvy * _F(c) - dvx * _F(s))
        cov = m.coverage(noise, a, b, fa, fb)
        inside = cov > 0
        if not inside.any():
            continue
        j = idx[inside]
        albedo[j] = FILLS[m.fill](m, noise, a[inside], b[inside], fa[inside], fb[inside],
                                  cov[inside], albedo[j])
    return albedo
