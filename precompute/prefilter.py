"""Split-sum image-based lighting for glossy films (Karis 2013), with the film's spectral albedo.

The World's radiance is prefiltered by the GGX lobe at a ladder of roughness levels (n = v = r
assumption); at shading time it is looked up in the reflection direction and multiplied by the
film's directional albedo as a 3×3 matrix — the l = 0 table entry × √(4π), the response to
uniform white light — so no new table is needed.

The film's colour is the albedo at the angle of the light that the lobe actually gathers: a
second prefilter of luminance × direction gives the light-weighted mean direction c inside the
lobe, and the albedo is looked up at cos θ' = √((1 + v·c)/2), the half-vector angle of that
light (:func:`dominant_cosine`). Where a glossy lobe is lit only by its tails catching a lamp
20–40° away, the colour is that of the lamp's half-vector angle, not of the view angle.

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

import math
from dataclasses import dataclass, replace

import numpy as np

from . import brdf, constants, hdri

#: Number of prefiltered levels. Level k holds roughness (k / (J − 1))² — dense where the lobe
#: changes fastest — and a roughness between two levels blends them (:func:`level_blend`,
#: mirrored in tf_split_sum.glsl). With levels uniform in r (0, 0.125, …) a roughness of
#: 0.05 blended a mirror with a 0.125 lobe and was off by a mean ΔE2000 of 8.4 under the
#: studio HDRI (docs/cycles-comparison.md); at the exact roughness it was 1.8.
LEVEL_COUNT = 9
#: Roughness of each prefiltered level (Blender roughness; α = r²).
ROUGHNESS_LEVELS = tuple(((np.arange(LEVEL_COUNT) / (LEVEL_COUNT - 1)) ** 2).tolist())
#: Width of the sharpest levels: 512 × 256 texels ≈ 0.7° each (the addon's World panorama is
#: 512 wide). Rougher levels use fewer texels (see :func:`level_width`). Against Cycles at
#: roughness 0.05 (studio HDRI): 256 → 2.08, 512 → 1.78, 1024 → 1.73 mean ΔE2000.
LEVEL_WIDTH = 512
#: GGX samples per output texel (θ × φ strata); enough once each reads a matched mip level.
SAMPLES = (12, 6)
#: Mip-level bias of filtered importance sampling. Křivánek & Colbert add 1 (a wider footprint
#: hides undersampling); measured against Cycles at roughness 0.05 it blurred small HDR lamps
#: (mean ΔE2000 2.39 with 1, 1.73 with 0), so samples read the level whose texel matches.
LOD_BIAS = 0.0
#: The prefiltered lobe narrows toward grazing views: r_eff = r · cos(θo)^GRAZING_EXPONENT.
#: The n = v = r lobe of the prefilter is wider than what the masked, horizon-clipped lobe
#: gathers at grazing angles. Measured against Cycles (mean ΔE2000, benchmarks/cycles_compare.py
#: cases, 64 px sphere), exponents 0 / 0.25 / 0.5 / 1: courtyard r 0.3: 5.06 / 4.23 / 4.11 / 5.15;
#: forest r 0.3: 2.36 / 2.44 / 2.89 / 3.97; courtyard r 0.15: 1.04 / 0.64 / 0.72 / 1.25; studio
#: soap r 0.15: 9.95 / 8.17 / 7.07 / 6.77; studio soap r 0.05: 1.69 / 1.43 / 1.36 / 1.35.
#: Widening instead (r / cos^0.5) made every case worse (courtyard r 0.3: 8.85).
GRAZING_EXPONENT = 0.5
#: Rec.709 luminance weights (Blender's scene-linear RGB): the weight of each direction in the
#: light-weighted mean direction of :func:`dominant_cosine`.
LUMINANCE = (0.2126, 0.7152, 0.0722)


@dataclass(frozen=True)
class Prefiltered:
    """Prefiltered radiance: one (H_j, W_j, 3) image per ``roughness`` level; rejected pixel count.

    ``moments``: per level, the same GGX prefilter of luminance × direction, ∫ Y(l) D l dl
    (H_j, W_j, 3), whose direction is the light-weighted mean direction inside the lobe; None
    when not computed (then :func:`dominant_cosine` falls back to the view angle).
    """

    levels: tuple
    roughness: np.ndarray
    rejected_pixels: int
    moments: tuple | None = None
    #: Per level, the share of the lifted-out lamps (lamps.py) that the level does *not* hold:
    #: level j = rest + (1 − w_j) × lamps, and the analytic lamps are added with the same level
    #: blend of these weights (:func:`lamp_weight_at`). None: no lamps were lifted out.
    lamp_weights: np.ndarray | None = None

    def resampled(self, width: int) -> np.ndarray:
        """All levels bilinearly resampled to (J, width/2, width, 3) — e.g. for one GPU texture."""
        return _resample(self.levels, width)

    def resampled_moments(self, width: int) -> np.ndarray | None:
        """The direction moments resampled like :meth:`resampled`, or None."""
        return None if self.moments is None else _resample(self.moments, width)


def _resample(stack, width: int) -> np.ndarray:
    dirs = hdri.equirect_directions(width // 2, width)
    return np.stack([_bilinear(level, dirs) for level in stack])


def level_width(roughness: float, max_width: int = LEVEL_WIDTH) -> int:
    """Texels across for a level: a power of two with texels ≈ α/2 wide, in [32, max_width]."""
    alpha = max(float(roughness) ** 2, constants.MIN_ALPHA)
    wanted = 2.0 * np.pi / (0.5 * alpha)
    return int(min(max_width, max(32, 2 ** math.ceil(math.log2(wanted)))))


def mip_chain(image: np.ndarray, min_width: int = 8) -> list[np.ndarray]:
    """Solid-angle-exact 2× reductions of an equirect image down to ``min_width``."""
    chain = [np.asarray(image, dtype=np.float64)]
    while chain[-1].shape[1] > min_width and chain[-1].shape[0] % 2 == 0 and chain[-1].shape[1] % 2 == 0:
        chain.append(hdri.downsample(chain[-1], 2))
    return chain


def _bilinear(image: np.ndarray, directions: np.ndarray) -> np.ndarray:
    from .render import equirect_lookup

    return equirect_lookup(image, directions)


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
    cp, sp = math.cos(phi0), math.sin(phi0)
    z = np.stack([sin_t * cp, sin_t * sp, cos_t], axis=-1)
    x = np.stack([cos_t * cp, cos_t * sp, -sin_t], axis=-1)
    y = np.cross(z, x)
    hw = np.einsum("ki,rid->rkd", h_local, np.stack([x, y, z], axis=1))  # half-vectors (rows, samples, 3)
    lw = 2.0 * h_local[None, :, 2:3] * hw - z[:, None]  # (rows, samples, 3) at column 0
    u = 0.5 - np.arctan2(lw[..., 1], lw[..., 0]) / (2.0 * np.pi)
    v = np.arccos(np.clip(lw[..., 2], -1.0, 1.0)) / np.pi
    shift = np.arange(w_out) / w_out
    out = np.zeros((h_out, w_out, chain[0].shape[-1]))
    for m, mip in enumerate(chain):
        # trilinear: a sample with lod in [m, m + 1) reads level m with 1 − frac, m + 1 with frac
        cm = np.where(lo == m, weight * (1.0 - frac), 0.0) + np.where(lo == m - 1, weight * frac, 0.0)
        ks = np.nonzero(cm)[0]
        if ks.size == 0:
            continue
        hm, wm = mip.shape[:2]
        yy = v[:, ks] * hm - 0.5
        y0 = np.clip(np.floor(yy).astype(int), 0, hm - 1)
        fy = np.clip(yy - y0, 0.0, 1.0)
        y1 = np.minimum(y0 + 1, hm - 1)
        for b in range(0, h_out, rows_per_batch):
            sl = slice(b, b + rows_per_batch)
            rows = (1.0 - fy[sl])[..., None, None] * mip[y0[sl]] + fy[sl][..., None, None] * mip[y1[sl]]
            xx = (u[sl][:, ks, None] + shift) * wm - 0.5  # (batch, samples, w_out)
            x0 = np.floor(xx).astype(int)
            fx = (xx - x0)[..., None]
            a = np.take_along_axis(rows, (x0 % wm)[..., None], axis=2)
            c = np.take_along_axis(rows, ((x0 + 1) % wm)[..., None], axis=2)
            out[sl] += np.einsum("k,bkjc->bjc", cm[ks], (1.0 - fx) * a + fx * c)
    return out


def prefilter(
    image: np.ndarray,
    levels=ROUGHNESS_LEVELS,
    width: int = LEVEL_WIDTH,
    samples=SAMPLES,
    lod_bias: float = LOD_BIAS,
    lamp_mask: np.ndarray | None = None,
) -> Prefiltered:
    """GGX-prefiltered radiance for each roughness level (n = v = r assumption of the split sum).

    Each level also carries the prefiltered luminance × direction (``Prefiltered.moments``):
    both are filtered together as one 6-channel image, so the two share every sample.

    ``lamp_mask`` (H, W) bool, the pixels :func:`lamps.extract` lifted out: level j holds
    rest + (1 − w_j) lamps, with w_j = :func:`lamps.level_lamp_weights` (0 or 1,
    ``Prefiltered.lamp_weights``): the whole World below lamps.LAMP_LEVEL, the World without its
    lamps from there on.
    """
    from . import lamps as lamps_mod

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
        return mip_chain(np.concatenate([rgb, luminance[..., None] * directions], axis=-1))

    # Each level filters one image: the whole World, or (from lamps.LAMP_LEVEL on, weight 1)
    # the World without its lamps: no level needs both.
    weights = None if lamp_img is None else lamps_mod.level_lamp_weights(len(levels))
    chains = {0.0: chain_of(img[..., :3])}
    if weights is not None:
        if not np.all((weights == 0.0) | (weights == 1.0)):
            raise ValueError("level lamp weights must be 0 or 1")
        if np.any(weights == 1.0):
            chains[1.0] = chain_of(img[..., :3] - img[..., 3:6])
    out = []
    for j, r in enumerate(levels):
        chain = chains[0.0 if weights is None else float(weights[j])]
        if r <= 0.0:
            out.append(chain[0])
            continue
        alpha = max(float(r) ** 2, constants.MIN_ALPHA)
        out.append(_level(chain, alpha, min(level_width(r, width), chain[0].shape[1]), samples, lod_bias))
    return Prefiltered(
        tuple(level[..., :3] for level in out),
        np.asarray(levels, dtype=float),
        rejected,
        tuple(level[..., 3:] for level in out),
        weights,
    )


def effective_roughness(roughness: float, cos_o) -> np.ndarray:
    """r_eff = r · cos(θo)^GRAZING_EXPONENT (cos θo clamped to [MIN_COS, 1])."""
    c = np.clip(np.asarray(cos_o, dtype=float), constants.MIN_COS, 1.0)
    return np.clip(roughness, 0.0, 1.0) * c**GRAZING_EXPONENT


def level_blend(roughness, level_roughness) -> tuple[np.ndarray, np.ndarray]:
    """(lower level index, weight of the upper level) for ``roughness`` between two levels.

    The levels are blended so that the blend's α² (= r⁴) is the material's: w = (r⁴ − r₀⁴) /
    (r₁⁴ − r₀⁴). GGX tails scale as α², and with HDR lamps the tails are what shows: blending
    by level position instead overweights the wider level (at r = 0.05 between 0.016 and
    0.0625: weight 0.79 instead of 0.41, 1.9× the lamps' glow; mean ΔE2000 vs Cycles under the
    studio HDRI 2.31 instead of 1.8). Mirrored in tf_split_sum.glsl.
    """
    levels = np.asarray(level_roughness, dtype=float)
    r = np.clip(np.asarray(roughness, dtype=float), levels[0], levels[-1])
    lo = np.clip(np.searchsorted(levels, r, side="right") - 1, 0, levels.size - 2)
    a4, b4 = levels[lo] ** 4, levels[lo + 1] ** 4
    return lo, np.clip((r**4 - a4) / np.maximum(b4 - a4, 1e-30), 0.0, 1.0)


def _blend(pre: Prefiltered, directions: np.ndarray, roughness, stacks) -> list[np.ndarray]:
    """Each of ``stacks`` (per-level images) at ``directions``, α²-matched level blend shared."""
    r = np.broadcast_to(np.asarray(roughness, dtype=float), directions.shape[:-1])
    lo, frac = level_blend(r, pre.roughness)
    frac = frac[..., None]
    outs = [np.zeros(directions.shape[:-1] + (3,)) for _ in stacks]
    for level in np.unique(lo):
        sel = lo == level
        for out, levels in zip(outs, stacks, strict=True):
            a = _bilinear(levels[level], directions[sel])
            b = _bilinear(levels[level + 1], directions[sel])
            out[sel] = (1 - frac[sel]) * a + frac[sel] * b
    return outs


def lamp_weight_at(pre: Prefiltered, roughness) -> np.ndarray:
    """The analytic lamps' weight at the level blend of (effective) ``roughness``; 0 without lamps."""
    from . import lamps as lamps_mod

    r = np.asarray(roughness, dtype=float)
    if pre.lamp_weights is None:
        return np.zeros(r.shape)
    lo, frac = level_blend(r, pre.roughness)
    return lamps_mod.lamp_weight(lo, frac, len(pre.levels))


def lookup(pre: Prefiltered, directions: np.ndarray, roughness, moments: bool = False) -> np.ndarray:
    """Prefiltered radiance in ``directions`` at per-pixel ``roughness`` (α²-matched level blend).

    ``moments=True`` reads the luminance × direction moments instead (same blend).
    """
    return _blend(pre, directions, roughness, [pre.moments if moments else pre.levels])[0]


def _cosine_from_moment(moment, views, cos_o) -> np.ndarray:
    norm2 = np.sum(moment * moment, axis=-1)
    ok = norm2 > 1e-30  # as tf_split_sum.glsl (float32)
    c = moment / np.sqrt(np.where(ok, norm2, 1.0))[..., None]
    cos_p = np.sqrt(np.clip(0.5 * (1.0 + np.sum(np.asarray(views, dtype=float) * c, axis=-1)), 0.0, 1.0))
    return np.where(ok, cos_p, cos_o)


def dominant_cosine(pre: Prefiltered, reflections, roughness, views, cos_o) -> np.ndarray:
    """cos θ' = √((1 + v·c)/2): the half-vector cosine of the lobe's light-weighted mean direction c.

    c is the direction of the prefiltered luminance × direction moment at the lookup's level
    and direction. v·l is linear in l, so v·c is the light-weighted mean of v·l up to c's
    normalisation; l = reflect(v, h) gives v·h = √((1 + v·l)/2). Uniform light gives c = r
    and cos θ' = cos θo. Where the moment vanishes (black World in the lobe, or no moments)
    the view angle is kept. Measured against Cycles (benchmarks/cycles_compare.py, mean
    ΔE2000, split sum alone): studio soap r 0.15: 7.07 → 5.14; courtyard r 0.3: 4.11 → 3.27;
    forest r 0.3: 2.89 → 2.67; studio soap r 0.05: 1.36 → 1.29; others unchanged (±0.01). An
    exact per-pixel lobe with the same single colour reaches 3.81 on the studio case, with the
    film's colour per light direction 1.51: one colour per pixel is this method's floor.
    """
    cos_o = np.asarray(cos_o, dtype=float)
    if pre.moments is None:
        return cos_o
    return _cosine_from_moment(lookup(pre, reflections, roughness, moments=True), views, cos_o)


#: Lowest SH order at which a film drawn by both halves (0 < SH weight < 1) reads its albedo at
#: the dominant-direction angle (:func:`dominant_cosine`); below it, at the view angle. The
#: moment is a second texture fetch: on llvmpipe (benchmarks/viewport.py, 1080p, the combined
#: film) it cost 0.35× of the SH-only frame at l = 2 and 0.10× at l = 5 (combined ÷ SH only
#: 1.53 → 1.18 and 1.34 → 1.24 without it), a few % from l = 8. Its gain does not depend on the
#: order (benchmarks/cycles_compare.py cases, mean ΔE2000 with → without): courtyard r 0.3 at
#: l = 2 / 5 / 8 / 12: 8.99 → 9.35, 5.12 → 5.48, 3.39 → 3.82, 2.61 → 3.07; forest r 0.3: 3.93
#: → 4.01, 2.32 → 2.39, 1.79 → 1.87, 1.60 → 1.68. So it is kept where the SH half is dear and
#: accurate (the automatic order of these films is 12) and dropped at forced orders ≤ 5, whose
#: SH error is ten times its gain. Split-only films (SH weight 0) always use it: they have no SH
#: sum to compare with, and it is their largest correction (studio r 0.15: 1.67 → 1.38).
MOMENT_MIN_L = 6


def uses_moment(sh_order: int, split_only: bool) -> bool:
    """Whether the split sum reads the albedo at the dominant-direction angle (see
    :data:`MOMENT_MIN_L`): always for split-only films, from SH order 6 for combined ones."""
    return bool(split_only) or int(sh_order) >= MOMENT_MIN_L


#: Roughness range over which shading hands over from the split sum to SH (smoothstep).
#: Measured against Cycles (mean ΔE2000, 64 px sphere, per-channel mode, 4×4 supersampled;
#: benchmarks/cycles_compare.py cases) with the automatic SH order (12 below roughness 0.7),
#: SH weight 0 / 0.1 / 0.2 / 0.35 / 0.5 / 0.8 / 0.9 / 1: r 0.3 courtyard 3.27 / 2.96 / 2.74 /
#: 2.61 / 2.71 / 3.43 / 3.78 / 4.15, forest 2.67 / 2.34 / 2.09 / 1.89 / 1.89 / 2.49 / 2.81 /
#: 3.17; r 0.5 courtyard 6.69 / 5.97 / 5.28 / 4.30 / 3.39 / 1.87 / 1.57 / 1.49, forest 4.56 /
#: 4.02 / 3.50 / 2.77 / 2.09 / 0.99 / 0.81 / 0.87; r 0.6 studio 13.4 / 11.8 / 10.3 / 8.3 /
#: 6.5 / 3.2 / 2.5 / 2.5. Below 0.2 the split sum alone is best (SH: 3–35 at r ≤ 0.15).
#: Smoothstep over 0.2–0.45 gives 0.35 at r 0.3 and 1 from 0.45 (with SH at l = 8 the
#: hand-over was 0.2–0.6: 0.16 at r 0.3, 0.84 at r 0.5).
SH_BLEND = (0.2, 0.45)


def sh_weight(roughness: float) -> float:
    """Weight of the SH path, smoothstep over ``SH_BLEND`` (0 = split sum only, 1 = SH only)."""
    lo, hi = SH_BLEND
    t = min(max((float(roughness) - lo) / (hi - lo), 0.0), 1.0)
    return t * t * (3.0 - 2.0 * t)


def _thickness_position(result, thickness_nm):
    if thickness_nm is None or result.thicknesses_nm.size < 2:
        return None
    lo, hi = result.thicknesses_nm[0], result.thicknesses_nm[-1]
    return (np.asarray(thickness_nm, dtype=float) - lo) / (hi - lo) * (result.thicknesses_nm.size - 1)


def shade_split_sum(result, pre: Prefiltered, normals, views, thickness_nm=None) -> np.ndarray:
    """Film albedo (3×3, from the l = 0 entry) × prefiltered radiance in the reflection direction.

    The albedo is read at the half-vector angle of the lobe's light (:func:`dominant_cosine`).
    """
    from .render import lookup as table_lookup

    n = np.asarray(normals, dtype=float)
    v = np.asarray(views, dtype=float)
    cos_o = np.clip(np.sum(n * v, axis=-1), 0.0, 1.0)
    refl = 2.0 * cos_o[..., None] * n - v
    r_eff = effective_roughness(result.material.roughness, cos_o)
    if pre.moments is None:
        radiance, cos_p = lookup(pre, refl, r_eff), cos_o
    else:  # dominant_cosine, sharing the level blend with the radiance
        radiance, moment = _blend(pre, refl, r_eff, [pre.levels, pre.moments])
        cos_p = _cosine_from_moment(moment, v, cos_o)
    m = table_lookup(result.data, cos_p, _thickness_position(result, thickness_nm))
    m0 = np.take(m, 0, axis=-3 if result.data.ndim == 5 else -2)  # coefficient l = 0: (…, 3, 3) or (…, 3)
    albedo = m0 * math.sqrt(4.0 * math.pi)
    if albedo.ndim == radiance.ndim + 1:
        return np.maximum(np.einsum("...kc,...c->...k", albedo, radiance), 0.0)
    return np.maximum(albedo * radiance, 0.0)


def shade_combined(
    result, world_coeffs, pre: Prefiltered, normals, views, thickness_nm=None, lamps=None, film=None
) -> np.ndarray:
    """The product's shading: split sum for glossy films, SH for rough ones, blended by roughness.

    With ``lamps`` (:class:`lamps.Lamps`) and ``film`` (:func:`lamps.film_table`) the World's
    lamps are added, shaded per light direction (:func:`lamps.shade`); ``world_coeffs`` and
    ``pre`` from ``prefilter(…, lamp_mask=…)``. The SH half sees the World without its lamps
    (weight 1); the split-sum half keeps them in its sharpest levels (:func:`lamp_weight_at`).
    The split sum reads the albedo at the dominant-direction angle where :func:`uses_moment`
    says so, else at the view angle.
    """
    from . import lamps as lamps_mod
    from .render import shade_sh

    w = sh_weight(result.material.roughness)
    out = 0.0
    if w < 1.0:
        if pre.moments is not None and not uses_moment(result.sh_order, w <= 0.0):
            pre = replace(pre, moments=None)  # the albedo at the view angle (MOMENT_MIN_L)
        out = (1.0 - w) * shade_split_sum(result, pre, normals, views, thickness_nm)
    if w > 0.0:
        out = out + w * shade_sh(result, world_coeffs, normals, views, thickness_nm)
    if lamps is not None and lamps.count:
        if film is None:
            raise ValueError("lamps need the film table (lamps.film_table)")
        n = np.asarray(normals, dtype=float)
        v = np.asarray(views, dtype=float)
        cos_o = np.clip(np.sum(n * v, axis=-1), 0.0, 1.0)
        weight = w + (1.0 - w) * lamp_weight_at(pre, effective_roughness(result.material.roughness, cos_o))
        position = _thickness_position(result, thickness_nm)
        if position is not None:
            position = position / (result.thicknesses_nm.size - 1)
        lit = lamps_mod.shade(film, lamps, result.material.roughness, n, v, position)
        out = out + weight[..., None] * lit.reshape(n.shape)
    return out
