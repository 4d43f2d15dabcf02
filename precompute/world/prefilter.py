"""GGX prefiltering of the World for the split sum (Karis 2013), with its direction moments.

The World's radiance is prefiltered by the GGX lobe at a ladder of roughness levels
(policy.ROUGHNESS_LEVELS; n = v = r assumption). Each level also carries the prefilter of
luminance × direction, whose direction is the light-weighted mean direction inside the lobe: the
split sum reads the film's albedo at the half-vector angle of that light
(shading.split_sum.dominant_cosine). Looking the levels up and shading with them is
shading/split_sum.py's (the numpy twin of glsl/tf_split_sum.glsl); this module only computes
them.

Prefiltering uses filtered importance sampling (Křivánek & Colbert 2008): each GGX sample reads
a mip level whose texel solid angle matches the sample's, so an HDR sun of 10⁵ spreads
smoothly instead of producing fireflies; non-finite pixels are zeroed and counted first.

References
----------
- Karis, B. (2013). Real Shading in Unreal Engine 4. SIGGRAPH course notes (split-sum).
- Křivánek, J. & Colbert, M. (2008). Real-time shading with filtered importance sampling.
  Computer Graphics Forum 27(4) (EGSR).
"""

from __future__ import annotations

import concurrent.futures
import math
import os
from dataclasses import dataclass, replace

import numpy as np

from .. import brdf, constants
from ..shading.lamps import level_lamp_weights
from ..shading.policy import ROUGHNESS_LEVELS
from . import hdri

#: Width of the sharpest levels: 512 × 256 texels ≈ 0.7° each (the addon's World panorama is
#: 512 wide); rougher levels use fewer texels (:func:`level_width`) (docs/tuning.md#level-width).
LEVEL_WIDTH = 512
#: GGX samples per output texel (θ × φ strata); enough once each reads a matched mip level.
SAMPLES = (12, 6)
#: A level's texels are at most this × α wide (:func:`level_width`): against a 32 × 16-sample
#: reference at 512 texels, a level this coarse (bilinearly resampled) is as close as one at
#: twice the width, 1.6 × α is not (docs/world-latency.md).
TEXEL_ALPHA = 1.25
#: Mip-level bias of filtered importance sampling: 0, not Křivánek & Colbert's 1, so small HDR
#: lamps are not blurred (docs/tuning.md#lod-bias).
LOD_BIAS = 0.0
#: Threads that filter levels at once (bounded by the cores): the levels are independent.
LEVEL_THREADS = 4
#: Rec.709 luminance weights (Blender's scene-linear RGB): the weight of each direction in the
#: light-weighted mean direction of shading.split_sum.dominant_cosine.
LUMINANCE = (0.2126, 0.7152, 0.0722)


@dataclass(frozen=True)
class Prefiltered:
    """Prefiltered radiance: one (H_j, W_j, 3) image per ``roughness`` level; rejected pixel count.

    ``moments``: per level, the same GGX prefilter of luminance × direction, ∫ Y(l) D l dl
    (H_j, W_j, 3), whose direction is the light-weighted mean direction inside the lobe; None
    when not computed (then shading.split_sum.dominant_cosine falls back to the view angle).
    """

    levels: tuple
    roughness: np.ndarray
    rejected_pixels: int
    moments: tuple | None = None
    #: Per level, the share of the lifted-out lamps (lamps.py) that the level does *not* hold:
    #: level j = rest + (1 − w_j) × lamps, and the analytic lamps are added with the same level
    #: blend of these weights (shading.split_sum.lamp_weight_at). None: no lamps were lifted out.
    lamp_weights: np.ndarray | None = None
    #: The World's turn and strength applied at lookup time, without recomputation (a Mapping
    #: rotation, a Background Strength): the level images are of the *content* (the image as
    #: read); the World's radiance in direction d is ``scale`` × level(Q d), Q = ``rotation``
    #: (3×3 orthogonal: image direction = Q · world direction; None: the identity), and a
    #: moment m read there points along Qᵀ m in the World (shading.split_sum mirrors
    #: tf_prefiltered_lookup).
    rotation: np.ndarray | None = None
    scale: float = 1.0

    def transformed(self, rotation=None, scale: float = 1.0) -> Prefiltered:
        """The same levels seen through the World's ``rotation`` (Q, 3×3) and ``scale``: no
        recomputation, only what the lookup applies (:attr:`rotation`, :attr:`scale`)."""
        q = None if rotation is None else np.asarray(rotation, dtype=np.float64).reshape(3, 3)
        if q is not None and not np.allclose(q @ q.T, np.eye(3), atol=1e-9):
            raise ValueError("rotation must be an orthogonal 3×3 matrix")
        if not np.isfinite(scale):
            raise ValueError(f"scale must be finite, got {scale!r}")
        return replace(self, rotation=q, scale=float(scale))

    def resampled(self, width: int) -> np.ndarray:
        """All levels bilinearly resampled to (J, width/2, width, 3) — e.g. for one GPU texture."""
        return _resample(self.levels, width)

    def resampled_moments(self, width: int) -> np.ndarray | None:
        """The direction moments resampled like :meth:`resampled`, or None."""
        return None if self.moments is None else _resample(self.moments, width)


def _resample(stack, width: int) -> np.ndarray:
    return np.stack([resample_equirect(level, width) for level in stack])


def _taps(n_out: int, n_in: int) -> tuple[np.ndarray, np.ndarray]:
    """Lower tap and its weight of each of ``n_out`` texel centres on an ``n_in``-texel axis."""
    x = (np.arange(n_out) + 0.5) * (n_in / n_out) - 0.5
    x0 = np.floor(x).astype(np.intp)
    return x0, x - x0


def resample_equirect(level: np.ndarray, width: int) -> np.ndarray:
    """``level`` (h, w, C) bilinearly resampled to (width/2, width, C): :func:`hdri.equirect_lookup`
    at the texel centres, done per axis (the grids are aligned: a texel centre's θ depends only on
    its row, its φ only on its column), wrapping in u and clamping rows at the poles."""
    h, w = level.shape[:2]
    if (h, w) == (width // 2, width):
        return np.array(level)
    y0, fy = _taps(width // 2, h)
    fy = np.where(y0 < 0, 0.0, np.clip(fy, 0.0, 1.0))
    y0 = np.clip(y0, 0, h - 1)
    y1 = np.minimum(y0 + 1, h - 1)
    fy = fy.astype(level.dtype)[:, None, None]
    rows = (1 - fy) * level[y0] + fy * level[y1]
    x0, fx = _taps(width, w)
    fx = fx.astype(level.dtype)[None, :, None]
    return (1 - fx) * rows[:, x0 % w] + fx * rows[:, (x0 + 1) % w]


def level_width(roughness: float, max_width: int = LEVEL_WIDTH) -> int:
    """Texels across for a level: the narrowest power of two whose texels are at most
    :data:`TEXEL_ALPHA` × α wide, in [32, max_width]."""
    alpha = max(float(roughness) ** 2, constants.MIN_ALPHA)
    wanted = 2.0 * np.pi / (TEXEL_ALPHA * alpha)
    return int(min(max_width, max(32, 2 ** math.ceil(math.log2(wanted)))))


def mip_chain(image: np.ndarray, min_width: int = 8, dtype=np.float64) -> list[np.ndarray]:
    """Solid-angle-exact 2× reductions of an equirect image down to ``min_width`` (each level
    reduced in float64, stored as ``dtype``)."""
    top = np.asarray(image, dtype=np.float64)
    chain = [top]
    while chain[-1].shape[1] > min_width and chain[-1].shape[0] % 2 == 0 and chain[-1].shape[1] % 2 == 0:
        chain.append(hdri.downsample(chain[-1], 2))
    return [np.ascontiguousarray(level, dtype=dtype) for level in chain]


def level_samples(alpha: float, width: int, samples=SAMPLES) -> tuple[int, int]:
    """GGX samples (θ × φ strata) for a level of ``alpha`` filtered at ``width`` texels across.

    A lobe whose reflected width (≈ 2α) is under :data:`SHARP_TEXELS` of a texel is the image
    itself but for its far tail, which only an HDR lamp makes visible: :data:`SHARP_SAMPLES`
    reach it as well as ``samples`` do (filtered importance sampling reads the tail's samples
    from coarse mip levels); a lobe under one texel takes :data:`SUBTEXEL_SAMPLES`; every
    other level keeps ``samples`` (docs/world-latency.md).
    """
    texel = 2.0 * np.pi / width
    if 2.0 * alpha < SHARP_TEXELS * texel:
        return SHARP_SAMPLES
    if 2.0 * alpha < texel:
        return SUBTEXEL_SAMPLES
    return tuple(samples)


#: A level whose reflected lobe (2α) is narrower than this share of a level-0 texel gets
#: :data:`SHARP_SAMPLES` (policy.ROUGHNESS_LEVELS' level 1 at 512 texels: 2α ≈ 0.04 texel).
SHARP_TEXELS = 0.1
#: GGX samples of such a sharp level: as close to a 512-sample reference as :data:`SAMPLES`
#: (docs/world-latency.md), a quarter of the work.
SHARP_SAMPLES = (6, 3)
#: GGX samples of a level whose lobe is under one texel (level 2 at 512 texels: 2α ≈ 0.6
#: texel): the φ strata of :data:`SAMPLES` (the ones its error depends on), fewer θ strata.
SUBTEXEL_SAMPLES = (8, 6)


def _level(chain, alpha: float, w_out: int, samples, lod_bias: float, rows_per_batch: int = 8) -> np.ndarray:
    """One prefiltered level (w_out/2, w_out, 3) by filtered importance sampling.

    The lobe around a texel depends only on its row: rotating the World about z by one column
    moves every sample one column in u. So the GGX samples are placed once per row (frame
    x = ∂/∂θ, y = z × x, z = the texel's direction) and each sample's radiance for the whole
    row is a shifted, bilinearly interpolated row of the mip chain: no per-texel trigonometry.
    """
    h_out = w_out // 2
    cos_t, sin_t = hdri.equirect_polar(h_out)
    phi0 = float(hdri.equirect_azimuths(w_out)[0])
    h_local, w = brdf.ggx_importance_grid(alpha, *samples)
    n_dot_l = 2.0 * h_local[:, 2] ** 2 - 1.0  # n = v: l = 2(v·h)h − v, n·l = cos 2θh
    keep = n_dot_l > 0
    h_local, w, n_dot_l = h_local[keep], w[keep], n_dot_l[keep]
    h0, w0 = chain[0].shape[:2]
    texel = 2.0 * np.pi * np.pi / (w0 * h0)  # solid angle of an equator texel at level 0
    pdf = brdf.D_ggx(h_local[:, 2], alpha) / 4.0  # pdf of l: D cosθh / (4 v·h), v·h = cosθh
    lod = 0.5 * np.log2(np.maximum(w / np.maximum(pdf, 1e-30), 1e-30) / texel) + lod_bias
    lod = np.clip(lod, 0.0, len(chain) - 1.0)
    lo = np.floor(lod).astype(int)
    frac = lod - lo
    weight = w * n_dot_l / np.sum(w * n_dot_l)
    dtype = chain[0].dtype
    cp, sp = math.cos(phi0), math.sin(phi0)
    z = np.stack([sin_t * cp, sin_t * sp, cos_t], axis=-1)
    x = np.stack([cos_t * cp, cos_t * sp, -sin_t], axis=-1)
    y = np.cross(z, x)
    hw = np.einsum("ki,rid->rkd", h_local, np.stack([x, y, z], axis=1))  # half-vectors (rows, samples, 3)
    lw = 2.0 * h_local[None, :, 2:3] * hw - z[:, None]  # (rows, samples, 3) at column 0
    u = 0.5 - np.arctan2(lw[..., 1], lw[..., 0]) / (2.0 * np.pi)
    v = np.arccos(np.clip(lw[..., 2], -1.0, 1.0)) / np.pi
    shift = np.arange(w_out) / w_out
    out = np.zeros((h_out, w_out, chain[0].shape[-1]), dtype=dtype)
    for m, mip in enumerate(chain):
        # trilinear: a sample with lod in [m, m + 1) reads level m with 1 − frac, m + 1 with frac
        cm = np.where(lo == m, weight * (1.0 - frac), 0.0) + np.where(lo == m - 1, weight * frac, 0.0)
        ks = np.nonzero(cm)[0]
        if ks.size == 0:
            continue
        hm, wm = mip.shape[:2]
        yy = v[:, ks] * hm - 0.5
        y0 = np.clip(np.floor(yy).astype(np.intp), 0, hm - 1)
        fy = np.clip(yy - y0, 0.0, 1.0).astype(dtype)
        ck = cm[ks].astype(dtype)
        # each texel with its right, lower and lower-right neighbours (wrapping in u, clamped in
        # v): one gather of 4 C floats reads a sample's four bilinear taps
        below = np.concatenate([mip[1:], mip[-1:]], axis=0)
        quad = np.stack([mip, np.roll(mip, -1, axis=1), below, np.roll(below, -1, axis=1)], axis=2)
        flat = quad.reshape(hm * wm, -1)
        for b in range(0, h_out, rows_per_batch):
            sl = slice(b, b + rows_per_batch)
            xx = (u[sl][:, ks, None] + shift) * wm - 0.5  # (batch, samples, w_out)
            x0 = np.floor(xx).astype(np.intp)
            fx = (xx - x0).astype(dtype)
            x0 %= wm
            wy1 = fy[sl][..., None] * ck[:, None]
            wy0 = ck[:, None] - wy1
            # gathered in (row, column, sample) order: per texel a (1 × 4K) @ (4K × C) product
            weights = np.stack([wy0 * (1 - fx), wy0 * fx, wy1 * (1 - fx), wy1 * fx], axis=-1)
            weights = weights.transpose(0, 2, 1, 3).reshape(-1, 1, 4 * len(ks))
            index = (y0[sl][..., None] * wm + x0).transpose(0, 2, 1)
            taps = flat.take(index.reshape(-1), axis=0).reshape(weights.shape[0], 4 * len(ks), -1)
            out[sl] += np.matmul(weights, taps).reshape(out[sl].shape)
    return out


def prefilter(
    image: np.ndarray,
    levels=ROUGHNESS_LEVELS,
    width: int = LEVEL_WIDTH,
    samples=SAMPLES,
    lod_bias: float = LOD_BIAS,
    lamp_mask: np.ndarray | None = None,
    *,
    dtype=np.float32,
    adaptive: bool = True,
) -> Prefiltered:
    """GGX-prefiltered radiance for each roughness level (n = v = r assumption of the split sum).

    Each level also carries the prefiltered luminance × direction (``Prefiltered.moments``):
    both are filtered together as one 6-channel image, so the two share every sample.

    ``lamp_mask`` (H, W) bool, the pixels :func:`lamps.extract` lifted out: level j holds
    rest + (1 − w_j) lamps, with w_j = shading.lamps.level_lamp_weights (0 or 1,
    ``Prefiltered.lamp_weights``): the whole World below policy.LAMP_LEVEL, the World without its
    lamps from there on.

    ``dtype``: the mip chain's and the levels' float type (float32: half the data moved, the
    levels within 3e-7 of the peak of float64's); ``adaptive``: fewer GGX samples for a level
    sharper than :data:`SHARP_TEXELS` (:func:`level_samples`). ``dtype=np.float64,
    adaptive=False`` filters as before issue 16 (docs/world-latency.md compares the two).
    """
    img = np.asarray(image, dtype=np.float64)[..., :3]
    bad = ~np.isfinite(img).all(axis=-1)
    rejected = int(bad.sum())
    if rejected:
        img = np.where(bad[..., None], 0.0, img)
    lamp_img = None
    if lamp_mask is not None:
        mask = np.asarray(lamp_mask, dtype=bool)
        if mask.shape != img.shape[:2]:
            raise ValueError(f"lamp_mask must have shape {img.shape[:2]}, got {mask.shape}")
        lamp_img = np.where(mask[..., None], img, 0.0)
        img = np.concatenate([img, lamp_img], axis=-1)  # downsampled together, split below
    while img.shape[1] > width and img.shape[1] % 2 == 0:
        img = hdri.downsample(img, 2)
    directions = hdri.equirect_directions(*img.shape[:2])

    def chain_of(rgb):
        luminance = np.maximum(rgb @ np.asarray(LUMINANCE), 0.0)
        return mip_chain(np.concatenate([rgb, luminance[..., None] * directions], axis=-1), dtype=dtype)

    # Each level filters one image: the whole World, or (from policy.LAMP_LEVEL on, weight 1)
    # the World without its lamps: no level needs both.
    weights = None if lamp_img is None else level_lamp_weights(len(levels))
    chains = {0.0: chain_of(img[..., :3])}
    if weights is not None:
        if not np.all((weights == 0.0) | (weights == 1.0)):
            raise ValueError("level lamp weights must be 0 or 1")
        if np.any(weights == 1.0):
            chains[1.0] = chain_of(img[..., :3] - img[..., 3:6])

    def one(j: int) -> np.ndarray:
        r = levels[j]
        chain = chains[0.0 if weights is None else float(weights[j])]
        if r <= 0.0:
            return chain[0]
        alpha = max(float(r) ** 2, constants.MIN_ALPHA)
        w_out = min(level_width(r, width), chain[0].shape[1])
        level_n = level_samples(alpha, chain[0].shape[1], samples) if adaptive else samples
        return _level(chain, alpha, w_out, level_n, lod_bias)

    # the levels are independent and numpy's gathers and products release the GIL: one thread
    # per core (at most LEVEL_THREADS), the widest levels first
    order = sorted(range(len(levels)), key=lambda j: -min(level_width(levels[j], width), width))
    threads = max(1, min(LEVEL_THREADS, os.cpu_count() or 1))
    if threads > 1:
        with concurrent.futures.ThreadPoolExecutor(threads) as pool:
            done = dict(zip(order, pool.map(one, order), strict=True))
    else:
        done = {j: one(j) for j in order}
    out = [done[j] for j in range(len(levels))]
    return Prefiltered(
        tuple(level[..., :3] for level in out),
        np.asarray(levels, dtype=float),
        rejected,
        tuple(level[..., 3:] for level in out),
        weights,
    )
