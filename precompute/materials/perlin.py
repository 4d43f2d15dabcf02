"""Blender's Noise Texture (4-D, fBm) in numpy: the *Blender Noise* thickness source.

The extension writes its *Blender Noise* source as Blender's own Noise Texture node (4-D, the
object-space position and W = the seed, both times the scale; Detail 2, Roughness 0.5,
Lacunarity 2, normalized), so Cycles and EEVEE render it. This module computes that node's
*Fac* the way Blender defines it, so the overlay draws the same pattern per pixel
(``glsl/tf_perlin.glsl`` is its GLSL mirror) with no bake:

- gradient noise on the integer lattice of 4-D space (Perlin 2002): each lattice point's
  gradient is picked by Bob Jenkins' lookup3 hash of its four coordinates (``hashword`` with
  four words: the ``mix`` after three, the ``final`` after the fourth; initial value
  0xdeadbeef + 16 + 13), one of 32 gradients with three ±1 components (``grad4``), blended
  with the quintic fade; scaled by 0.8344 (Blender's ``noise_scale4``) into about [−1, 1];
- fractal Brownian motion: octaves at frequencies 1, 2, 4, … (Lacunarity) with amplitudes 1,
  0.5, 0.25, … (Roughness), ``floor(Detail) + 1`` of them, the fraction of Detail blending one
  more; normalized to 0.5 · sum / Σ amplitudes + 0.5.

Against Cycles' bake of the node at a sphere's face corners the mirror is within 1.1e-3 of
*Fac* (median 1e-4): the bake's own spread, since Cycles offsets each corner's shading point
off its face, and two faces' corners at one vertex differ by as much
(tests/extension/test_linked_thickness.py). float32 throughout, as Cycles and the GPU compute it.

References
----------
K. Perlin (2002), "Improving Noise", ACM Transactions on Graphics 21(3), 681–682.
R. J. Jenkins (2006), lookup3.c, public domain (``hashword``, ``mix``, ``final``).
Blender manual, *Noise Texture* node (Detail, Roughness, Lacunarity, Normalize).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import ramp

__all__ = [
    "DETAIL",
    "LACUNARITY",
    "ROUGHNESS",
    "NoiseSpec",
    "blender_noise",
    "fbm",
    "distortion_offsets",
    "hash2",
    "hash3",
    "hash4",
    "noise_texture",
    "perlin",
]

#: The written node's Detail, Roughness and Lacunarity (Blender's defaults).
DETAIL, ROUGHNESS, LACUNARITY = 2.0, 0.5, 2.0
#: Blender's ``noise_scale4``: the 4-D gradient noise into about [−1, 1].
_SCALE4 = np.float32(0.8344)
_U32 = np.uint32


def _rot(x, k: int):
    return (x << _U32(k)) | (x >> _U32(32 - k))


def _mix3(a, b, c, r: tuple):
    """Half of lookup3's ``mix``: three subtract-xor-rotate steps with the rotations ``r``."""
    a = (a - c) ^ _rot(c, r[0])
    c = c + b
    b = (b - a) ^ _rot(a, r[1])
    a = a + c
    c = (c - b) ^ _rot(b, r[2])
    return a, b + a, c


def hash4(kx, ky, kz, kw) -> np.ndarray:
    """lookup3's ``hashword`` of four uint32 words (wrapping arithmetic), as uint32."""
    with np.errstate(over="ignore"):
        start = _U32(0xDEADBEEF + (4 << 2) + 13)
        a = np.asarray(kx, dtype=_U32) + start
        b = np.asarray(ky, dtype=_U32) + start
        c = np.asarray(kz, dtype=_U32) + start
        a, b, c = _mix3(a, b, c, (4, 6, 8))  # mix
        a, b, c = _mix3(a, b, c, (16, 19, 4))
        a = a + np.asarray(kw, dtype=_U32)
        return _final(a, b, c)


def _final(a, b, c):
    """lookup3's ``final``: c of the last avalanche."""
    c = (c ^ b) - _rot(b, 14)
    a = (a ^ c) - _rot(c, 11)
    b = (b ^ a) - _rot(a, 25)
    c = (c ^ b) - _rot(b, 16)
    a = (a ^ c) - _rot(c, 4)
    b = (b ^ a) - _rot(a, 14)
    return (c ^ b) - _rot(b, 24)


def _gradient(h, x, y, z, w):
    """The dot product of the position in the cell with gradient ``h & 31`` (three of the four
    axes, each ±1)."""
    h = h & _U32(31)
    u = np.where(h < 24, x, y)
    v = np.where(h < 16, y, z)
    s = np.where(h < 8, z, w)
    return np.where(h & 1, -u, u) + np.where(h & 2, -v, v) + np.where(h & 4, -s, s)


def _gradient3(h, x, y, z):
    """The dot product of the position in a 3-D cell with gradient ``h & 15`` (two of the three
    axes, each ±1; Perlin's 12 edges and 4 repeats)."""
    h = h & _U32(15)
    u = np.where(h < 8, x, y)
    v = np.where(h < 4, y, np.where((h == 12) | (h == 14), x, z))
    return np.where(h & 1, -u, u) + np.where(h & 2, -v, v)


def _fade(t):
    return t * t * t * (t * (t * np.float32(6.0) - np.float32(15.0)) + np.float32(10.0))


#: The 16 corners of a 4-D lattice cell, as offsets (16, 4).
_CORNERS = np.array([[(c >> k) & 1 for k in range(4)] for c in range(16)], dtype=np.uint32)


#: The 8 corners of a 3-D lattice cell, as offsets (8, 3).
_CORNERS3 = np.array([[(c >> k) & 1 for k in range(3)] for c in range(8)], dtype=np.uint32)
#: Blender's ``noise_scale3``: the 3-D gradient noise into about [−1, 1].
_SCALE3 = np.float32(0.9820)


def _perlin3(p: np.ndarray) -> np.ndarray:
    """:func:`perlin` of (N, 3) points: 3-D gradient noise, :func:`hash3`, scaled by 0.9820."""
    cell = np.floor(p)
    f = (p - cell).astype(np.float32)
    corners = cell.astype(np.int64).astype(np.uint32)[..., None, :] + _CORNERS3  # (N, 8, 3)
    h = hash3(corners[..., 0], corners[..., 1], corners[..., 2])
    q = f[..., None, :] - _CORNERS3.astype(np.float32)
    g = _gradient3(h, q[..., 0], q[..., 1], q[..., 2])
    t = _fade(f)[..., None, :]
    weights = np.prod(np.where(_CORNERS3 == 1, t, np.float32(1.0) - t), axis=-1)
    value = np.sum(weights * g, axis=-1, dtype=np.float32)
    return _SCALE3 * np.where(np.isfinite(value), value, np.float32(0.0))


#: Points per block of :func:`perlin` (its (block, 16, 4) temporaries stay in the cache).
_BLOCK = 1024


def perlin(points) -> np.ndarray:
    """Signed gradient noise of (N, 4) points (or (N, 3): Blender's 3-D noise), scaled as
    Blender's (about [−1, 1]): the 16 (8) corners' gradients weighted by the products of their
    fades (the nested blends of ``tf_perlin.glsl``, multiplied out)."""
    p = np.asarray(points, dtype=np.float32)
    if p.ndim == 2 and p.shape[0] > _BLOCK:
        return np.concatenate([_perlin(p[i : i + _BLOCK]) for i in range(0, p.shape[0], _BLOCK)])
    return _perlin(p)


def _perlin(p: np.ndarray) -> np.ndarray:
    if p.shape[-1] == 3:
        return _perlin3(p)
    cell = np.floor(p)
    f = (p - cell).astype(np.float32)
    lattice = cell.astype(np.int64).astype(np.uint32)  # wraps below zero as C's int → uint
    corners = lattice[..., None, :] + _CORNERS  # (N, 16, 4)
    h = hash4(corners[..., 0], corners[..., 1], corners[..., 2], corners[..., 3])
    q = f[..., None, :] - _CORNERS.astype(np.float32)
    g = _gradient(h, q[..., 0], q[..., 1], q[..., 2], q[..., 3])
    t = _fade(f)[..., None, :]
    weights = np.prod(np.where(_CORNERS == 1, t, np.float32(1.0) - t), axis=-1)
    value = np.sum(weights * g, axis=-1, dtype=np.float32)
    return _SCALE4 * np.where(np.isfinite(value), value, np.float32(0.0))


def fbm(points, detail: float = DETAIL, roughness: float = ROUGHNESS, lacunarity: float = LACUNARITY):
    """Blender's normalized fBm of :func:`perlin` at (N, 4) points, in about [0, 1]."""
    p = np.asarray(points, dtype=np.float32)
    detail = float(np.clip(detail, 0.0, 15.0))
    roughness = max(float(roughness), 0.0)
    scale, amplitude, total_amplitude = 1.0, 1.0, 0.0
    total = np.zeros(p.shape[:-1], dtype=np.float32)
    for _ in range(int(detail) + 1):
        total = total + np.float32(amplitude) * perlin(np.float32(scale) * p)
        total_amplitude += amplitude
        amplitude *= roughness
        scale *= lacunarity
    value = np.float32(0.5) * total / np.float32(total_amplitude) + np.float32(0.5)
    rest = detail - np.floor(detail)
    if rest == 0.0:
        return value
    more = total + np.float32(amplitude) * perlin(np.float32(scale) * p)
    value_more = np.float32(0.5) * more / np.float32(total_amplitude + amplitude) + np.float32(0.5)
    return np.float32(1.0 - rest) * value + np.float32(rest) * value_more


def noise_texture(
    vectors,
    w: float = 0.0,
    dimensions: int = 3,
    scale: float = 5.0,
    detail: float = DETAIL,
    roughness: float = ROUGHNESS,
    lacunarity: float = LACUNARITY,
    distortion: float = 0.0,
) -> np.ndarray:
    """A Noise Texture node's *Fac* (fBm, normalized) at (N, 3) ``vectors``: 3-D noise of
    vector · scale, or 4-D of (vector, ``w``) · scale (float64 (N,)). A ``distortion`` d ≠ 0
    first moves the scaled point p by d times one octave of the noise per axis, each read at p
    plus that axis's fixed offset (:func:`distortion_offsets`), as Blender does."""
    v = np.asarray(vectors, dtype=np.float32).reshape(-1, 3)
    if int(dimensions) == 4:
        v = np.concatenate([v, np.full((v.shape[0], 1), np.float32(w), dtype=np.float32)], axis=1)
    elif int(dimensions) != 3:
        raise ValueError(f"a Noise Texture of {dimensions} dimensions is not mirrored (3 or 4)")
    p = v * np.float32(scale)
    if float(distortion) != 0.0:
        moved = [perlin(p + offset) * np.float32(distortion) for offset in distortion_offsets(p.shape[1])]
        p = p + np.stack(moved, axis=1)
    return fbm(p, detail, roughness, lacunarity).astype(np.float64)


def hash2(kx, ky) -> np.ndarray:
    """lookup3's ``hashword`` of two uint32 words (no ``mix``: only the ``final``), as uint32."""
    with np.errstate(over="ignore"):
        start = _U32(0xDEADBEEF + (2 << 2) + 13)
        a = np.asarray(kx, dtype=_U32) + start
        b = np.asarray(ky, dtype=_U32) + start
        return _final(a, b, np.full_like(a, start))


def distortion_offsets(dimensions: int) -> np.ndarray:
    """The fixed offsets at which a distorted Noise Texture reads its distortion, one row per
    axis ((dimensions, dimensions) float32): component k of axis i's is 100 + 100 h, h the
    two-word hash of the bits of the floats i and k over 2³² (Blender's ``random_floatN_offset``
    of seed i), so each axis reads an unrelated part of the noise."""
    seed, k = np.meshgrid(np.arange(dimensions), np.arange(dimensions), indexing="ij")
    bits = [np.asarray(x, dtype=np.float32).view(_U32) for x in (seed, k)]
    h = hash2(*bits).astype(np.float32) / np.float32(0xFFFFFFFF)
    return np.float32(100.0) + h * np.float32(100.0)


def blender_noise(positions, scale: float, seed: float) -> np.ndarray:
    """The *Blender Noise* source's node at (N, 3) object-space ``positions``: 4-D noise at
    (position, ``seed``) · ``scale``, its *Fac* (float64 (N,), about [0, 1])."""
    return noise_texture(positions, seed, 4, scale)


def hash3(kx, ky, kz) -> np.ndarray:
    """lookup3's ``hashword`` of three uint32 words (no ``mix``: only the ``final``), as uint32."""
    with np.errstate(over="ignore"):
        start = _U32(0xDEADBEEF + (3 << 2) + 13)
        a = np.asarray(kx, dtype=_U32) + start
        b = np.asarray(ky, dtype=_U32) + start
        c = np.asarray(kz, dtype=_U32) + start
        return _final(a, b, c)


@dataclass(frozen=True)
class NoiseSpec:
    """A Noise Texture that gives a film's thickness, as the shader computes it per pixel
    (``tf_perlin.glsl``: ``tf_noise_texture``, ``TF_THICKNESS_PERLIN``).

    The node's settings (:func:`noise_texture`) read at ``space_scale`` · p + ``space_offset``
    of the object-space position p (Object coordinates: 1 and 0; Generated: the texture space),
    or at M · p + ``space_offset`` with M = ``space_matrix`` (a Mapping node folded in);
    its *Fac* becomes the table's thickness parameter as ``gain`` · x + ``bias`` clamped to
    [``low``, ``high``] and to [0, 1] (a Map Range, and the table's range, folded in), where x
    is *Fac*, or a Color Ramp's value at *Fac* where ``ramp`` holds its table
    (:func:`.ramp.lookup`: the luminance of its Color, or its Alpha, at
    :func:`.ramp.table_positions`; ``ramp_interpolate`` False for a *Constant* ramp).
    ``orco``: p is where the vertices were before a deformation (Generated coordinates after
    Deform modifiers or shape keys: the batch's ``orco`` attribute, ``TF_NOISE_ORCO``), not
    their positions.
    """

    dimensions: int = 4
    scale: float = 5.0
    w: float = 0.0
    detail: float = DETAIL
    roughness: float = ROUGHNESS
    lacunarity: float = LACUNARITY
    space_scale: tuple = (1.0, 1.0, 1.0)
    space_offset: tuple = (0.0, 0.0, 0.0)
    gain: float = 1.0
    bias: float = 0.0
    low: float = 0.0
    high: float = 1.0
    ramp: tuple = ()
    ramp_interpolate: bool = True
    distortion: float = 0.0
    space_matrix: tuple = ()
    orco: bool = False

    def space(self) -> np.ndarray:
        """The coordinates' linear part (3, 3): ``space_matrix`` (9 floats, row-major: a Mapping
        node's rotation and scale folded in) where given, else diag(``space_scale``); the
        coordinates of p are space() · p + ``space_offset``."""
        if self.space_matrix:
            return np.asarray(self.space_matrix, dtype=np.float64).reshape(3, 3)
        return np.diag(np.asarray(self.space_scale, dtype=np.float64))

    def fac(self, positions) -> np.ndarray:
        """The node's *Fac* at (N, 3) object-space ``positions``."""
        p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
        v = p @ self.space().T + np.asarray(self.space_offset)
        return noise_texture(
            v,
            self.w,
            self.dimensions,
            self.scale,
            self.detail,
            self.roughness,
            self.lacunarity,
            self.distortion,
        )

    def parameter(self, positions) -> np.ndarray:
        """The thickness parameter in [0, 1] at (N, 3) object-space ``positions``."""
        x = self.fac(positions)
        if self.ramp:
            x = ramp.lookup(self.ramp, x, self.ramp_interpolate)
        value = np.clip(self.gain * x + self.bias, self.low, self.high)
        return np.clip(value, 0.0, 1.0)

    def uniforms(self) -> dict:
        """The object block's noise members (``addon/gpu/layout.py`` OBJECT), vec4s."""
        return {
            "noise": [
                float(self.scale),
                float(self.w),
                float(bool(self.ramp_interpolate)),
                float(self.distortion),
            ],
            "noise_fbm": [
                float(np.clip(self.detail, 0.0, 15.0)),
                max(float(self.roughness), 0.0),
                float(self.lacunarity),
                float(self.dimensions),
            ],
            "noise_map": [float(self.gain), float(self.bias), float(self.low), float(self.high)],
            **{
                f"noise_space_{axis}": [*(float(v) for v in row), 0.0]
                for axis, row in zip("xyz", self.space(), strict=True)
            },
            "noise_offset": [*(float(v) for v in self.space_offset), 0.0],
        }
