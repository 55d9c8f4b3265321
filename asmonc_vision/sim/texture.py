"""Procedural, world-fixed textures with analytic pre-filtering.

Every texture is a function of surface coordinates in metres (world-fixed), so the two
cameras see the same surface pattern. Each function also takes the *footprint* of one
sample (ray) on the surface along each texture axis, in metres, and removes detail finer
than the footprint (exact box filter for the grout lines and joints, amplitude roll-off
for noise octaves) so that supersampling then gives realistic pixel averaging without
aliasing. Arrays are float32 unless stated otherwise (speed); coordinates up to a few
hundred metres keep sub-millimetre precision.
"""
from __future__ import annotations

import cv2
import numpy as np

_TABLE_SIZE = 1024
_F = np.float32


class ValueNoise:
    """Periodic lattice value noise (bilinear), sampled fast with ``cv2.remap``.

    One random lattice of ``size x size`` values in [-1, 1] (seeded); an octave of
    wavelength L samples it at (a / L + offset, b / L + offset) with wrap-around, so its
    period is ``size * L`` metres (13 m for L = 1.3 cm at the default size). Also holds
    a 256 x 256 table of uniform [0, 1) values for per-cell hashes (tiles, stones).

    Args:
        seed: integer seed of the lattice.
        size: lattice size (cells per side).
    """

    def __init__(self, seed: int = 0, size: int = _TABLE_SIZE) -> None:
        rng = np.random.default_rng(seed)
        self.size = int(size)
        self.table = rng.uniform(-1.0, 1.0, (self.size, self.size)).astype(_F)
        self.cells = rng.random((256, 256))
        self._cells_flat = self.cells.astype(_F).ravel()

    def cell(self, i, j) -> np.ndarray:
        """Uniform [0, 1) value of integer cell (i, j) (arrays of equal shape, ints or
        integral floats); period 256 cells along each index. Returns float32."""
        ii = np.asarray(i).astype(np.int32)
        jj = np.asarray(j).astype(np.int32)
        ii &= 255
        ii <<= 8
        jj &= 255
        ii |= jj
        return self._cells_flat.take(ii)

    def sample(self, a, b, wavelength: float, octave: int = 0) -> np.ndarray:
        """One octave at surface coordinates ``a, b`` (metres, (N,) arrays).

        Returns:
            float32 (N,) values in [-1, 1].
        """
        a = np.asarray(a, _F).ravel()
        b = np.asarray(b, _F).ravel()
        n = a.size
        if n == 0:
            return np.zeros(0, _F)
        cols = 1024
        rows = -(-n // cols)
        maps = []
        inv = _F(1.0 / wavelength)
        for src, off in ((a, 131.37 * (octave + 1) + 0.5), (b, 71.91 * (octave + 1) + 0.5)):
            m = np.empty(rows * cols, _F)
            m[n:] = 0.0
            d = m[:n]
            np.multiply(src, inv, out=d)
            d += _F(off % self.size)
            # wrap into [0, size): remap's fast path (no per-pixel border handling)
            d -= np.floor(d * _F(1.0 / self.size)) * _F(self.size)
            maps.append(m.reshape(rows, cols))
        out = cv2.remap(self.table, maps[0], maps[1], interpolation=cv2.INTER_LINEAR,
                        borderMode=cv2.BORDER_WRAP)
        return out.ravel()[:n]

    def fbm(self, a, b, wavelengths, weights, foot_a, foot_b, first_octave: int = 0
            ) -> np.ndarray:
        """Sum of octaves, each attenuated by ``1 / (1 + 4 (fa^2 + fb^2) / L^2)``.

        Args:
            a, b: (N,) surface coordinates, metres.
            wavelengths, weights: sequences of equal length (metres, amplitudes).
            foot_a, foot_b: (N,) sample footprints along a and b, metres.
            first_octave: index of the first octave (decorrelates different textures).
        Returns:
            float32 (N,) sum of weighted octaves (|value| <= sum(weights)).
        """
        a = np.asarray(a, _F).ravel()
        b = np.asarray(b, _F).ravel()
        f2 = np.square(np.asarray(foot_a, _F))
        f2 += np.square(np.asarray(foot_b, _F))
        f2 *= _F(4.0)
        out = np.zeros(a.size, _F)
        for k, (lam, w) in enumerate(zip(wavelengths, weights)):
            g = f2 * _F(1.0 / (lam * lam))
            g += _F(1.0 / w)
            # only the span of samples where this octave keeps > 0.5 % of its amplitude
            # (samples come roughly sorted by distance, so this is cheap and exact to
            # well below a grey level)
            keep = g < _F(200.0 / w)
            if not keep.any():
                continue
            i0 = int(np.argmax(keep))
            i1 = keep.size - int(np.argmax(keep[::-1]))
            out[i0:i1] += self.sample(a[i0:i1], b[i0:i1], lam, first_octave + k) / g[i0:i1]
        return out


def detail_gain(footprint, wavelength: float) -> np.ndarray:
    """Amplitude kept of detail of ``wavelength`` (m) averaged over ``footprint`` (m).

    ``1 / (1 + 4 (footprint / wavelength)^2)``: ~1 for fine sampling, 0.5 when a sample
    covers half a wavelength, ~0 when it covers several. float32.
    """
    x = np.asarray(footprint, _F) * _F(1.0 / wavelength)
    return _F(1.0) / (_F(1.0) + _F(4.0) * x * x)


def line_coverage(x, period: float, width: float, window) -> np.ndarray:
    """Fraction of a box window covered by periodic lines (grout, joints, bands).

    Lines occupy ``[k * period, k * period + width)`` for every integer k.

    Args:
        x: (N,) window centres, metres.
        period, width: metres (width < period).
        window: (N,) or scalar window widths, metres (>= 0).
    Returns:
        float32 (N,) coverage in [0, 1]; point sampling where the window is ~0.
    """
    x = np.asarray(x, _F)
    w = np.maximum(np.asarray(window, _F), _F(1e-6))
    half = w * _F(0.5)
    inv, per, wid = _F(1.0 / period), _F(period), _F(width)

    def cumulative(s):   # integral of the line indicator from 0 to s (s is consumed)
        k = np.floor(s * inv)
        tmp = k * per
        s -= tmp
        np.minimum(s, wid, out=s)
        k *= wid
        k += s
        return k

    cov = cumulative(x + half)
    cov -= cumulative(x - half)
    cov /= w
    return np.clip(cov, _F(0.0), _F(1.0), out=cov)
