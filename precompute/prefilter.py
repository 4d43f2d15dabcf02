"""Split-sum image-based lighting for glossy films (Karis 2013), with the film's spectral albedo.

The World's radiance is prefiltered by the GGX lobe at a ladder of roughness levels (n = v = r
assumption); at shading time it is looked up in the reflection direction and multiplied by the
film's directional albedo as a 3×3 matrix — the l = 0 table entry × √(4π), the response to
uniform white light — so no new table is needed.

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
from dataclasses import dataclass

import numpy as np

from . import brdf, constants, hdri

#: Roughness of each prefiltered level (Blender roughness; α = r²).
ROUGHNESS_LEVELS = tuple(np.linspace(0.0, 1.0, 9).tolist())
#: Width of the sharpest levels: 256 × 128 texels ≈ 1.4° each. Rougher levels use fewer texels
#: (see :func:`level_width`): a lobe of width α radians needs texels no finer than ≈ α/2.
LEVEL_WIDTH = 256
#: GGX samples per output texel (θ × φ strata); enough once each reads a matched mip level.
SAMPLES = (12, 6)
#: Effective roughness grows toward grazing views: r_eff = r / cos(θo)^GRAZING_EXPONENT,
#: because the reflected lobe is stretched along the view plane there. Measured against Cycles
#: (benchmarks/cycles_compare.py): exponent 0 beat 0.25 and 0.5 at roughness 0.05–0.3.
GRAZING_EXPONENT = 0.0


@dataclass(frozen=True)
class Prefiltered:
    """Prefiltered radiance: one (H_j, W_j, 3) image per ``roughness`` level; rejected pixel count."""

    levels: tuple
    roughness: np.ndarray
    rejected_pixels: int

    def resampled(self, width: int) -> np.ndarray:
        """All levels bilinearly resampled to (J, width/2, width, 3) — e.g. for one GPU array texture."""
        dirs = hdri.equirect_directions(width // 2, width)
        return np.stack([_bilinear(level, dirs) for level in self.levels])


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


def sample_lod(chain, directions: np.ndarray, lod: np.ndarray) -> np.ndarray:
    """Radiance at fractional mip level ``lod`` (trilinear: bilinear in two adjacent levels)."""
    lod = np.clip(lod, 0.0, len(chain) - 1.0)
    lo = np.floor(lod).astype(int)
    frac = (lod - lo)[..., None]
    out = np.zeros(directions.shape[:-1] + (3,))
    for level in np.unique(lo):
        sel = lo == level
        a = _bilinear(chain[level], directions[sel])
        b = _bilinear(chain[min(level + 1, len(chain) - 1)], directions[sel])
        out[sel] = (1 - frac[sel]) * a + frac[sel] * b
    return out


def _frame_around(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    helper = np.where(np.abs(z[..., :1]) < 0.9, np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
    x = np.cross(helper, z)
    x /= np.linalg.norm(x, axis=-1, keepdims=True)
    return x, np.cross(z, x)


def prefilter(
    image: np.ndarray, levels=ROUGHNESS_LEVELS, width: int = LEVEL_WIDTH, samples=SAMPLES
) -> Prefiltered:
    """GGX-prefiltered radiance for each roughness level (n = v = r assumption of the split sum)."""
    img = np.asarray(image, dtype=np.float64)
    bad = ~np.isfinite(img).all(axis=-1)
    rejected = int(bad.sum())
    if rejected:
        img = np.where(bad[..., None], 0.0, img)
    while img.shape[1] > width and img.shape[1] % 2 == 0:
        img = hdri.downsample(img, 2)
    chain = mip_chain(img)
    h0, w0 = chain[0].shape[:2]
    texel = 2.0 * np.pi * np.pi / (w0 * h0)  # solid angle of an equator texel at level 0
    out = []
    for r in levels:
        if r <= 0.0:
            out.append(chain[0])
            continue
        w_out = min(level_width(r, width), w0)
        dirs = hdri.equirect_directions(w_out // 2, w_out).reshape(-1, 3)
        x, y = _frame_around(dirs)
        alpha = max(float(r) ** 2, constants.MIN_ALPHA)
        h_local, w = brdf.ggx_importance_grid(alpha, *samples)
        n_dot_l = 2.0 * h_local[:, 2] ** 2 - 1.0  # n = v: l = 2(v·h)h − v, n·l = cos 2θh
        keep = n_dot_l > 0
        h_local, w, n_dot_l = h_local[keep], w[keep], n_dot_l[keep]
        pdf = brdf.D_ggx(h_local[:, 2], alpha) / 4.0  # pdf of l: D cosθh / (4 v·h), v·h = cosθh
        lod = np.clip(0.5 * np.log2(np.maximum(w / np.maximum(pdf, 1e-30), 1e-30) / texel) + 1.0, 0.0, None)
        # All samples of all texels at once: (K, N, 3) directions, K samples × N texels.
        hk = (
            h_local[:, None, 0:1] * x[None]
            + h_local[:, None, 1:2] * y[None]
            + h_local[:, None, 2:3] * dirs[None]
        )
        lk = 2.0 * h_local[:, None, 2:3] * hk - dirs[None]
        radiance = sample_lod(chain, lk, np.broadcast_to(lod[:, None], lk.shape[:2]))
        acc = np.einsum("k,knc->nc", w * n_dot_l, radiance) / np.sum(w * n_dot_l)
        out.append(acc.reshape(w_out // 2, w_out, 3))
    return Prefiltered(tuple(out), np.asarray(levels, dtype=float), rejected)


def effective_roughness(roughness: float, cos_o) -> np.ndarray:
    """r_eff = r / cos(θo)^GRAZING_EXPONENT, clamped to [r, 1]."""
    c = np.clip(np.asarray(cos_o, dtype=float), constants.MIN_COS, 1.0)
    return np.clip(roughness / c**GRAZING_EXPONENT, roughness, 1.0)


def lookup(pre: Prefiltered, directions: np.ndarray, roughness) -> np.ndarray:
    """Prefiltered radiance in ``directions`` at per-pixel ``roughness`` (linear between levels)."""
    r = np.broadcast_to(np.asarray(roughness, dtype=float), directions.shape[:-1])
    pos = np.interp(r, pre.roughness, np.arange(pre.roughness.size))
    lo = np.minimum(np.floor(pos).astype(int), pre.roughness.size - 2)
    frac = (pos - lo)[..., None]
    out = np.zeros(directions.shape[:-1] + (3,))
    for level in np.unique(lo):
        sel = lo == level
        a = _bilinear(pre.levels[level], directions[sel])
        b = _bilinear(pre.levels[min(level + 1, len(pre.levels) - 1)], directions[sel])
        out[sel] = (1 - frac[sel]) * a + frac[sel] * b
    return out


#: Roughness range over which shading hands over from the split sum to SH (smoothstep).
#: Measured against Cycles (mean ΔE2000, 64 px sphere, per-channel mode, 4×4 supersampled):
#: r 0.05 split 8.4 / SH 38; r 0.15 split 2.0 / SH 10.7; r 0.3 split 6.6 / SH 7.8 / 50:50 6.4;
#: r 0.5 split 10.3 / SH 3.8; r 0.6 split 13.1 / SH 4.2.
SH_BLEND = (0.25, 0.5)


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
    """Film albedo (3×3, from the l = 0 entry) × prefiltered radiance in the reflection direction."""
    from .render import lookup as table_lookup

    n = np.asarray(normals, dtype=float)
    v = np.asarray(views, dtype=float)
    cos_o = np.clip(np.sum(n * v, axis=-1), 0.0, 1.0)
    refl = 2.0 * cos_o[..., None] * n - v
    radiance = lookup(pre, refl, effective_roughness(result.material.roughness, cos_o))
    m = table_lookup(result.data, cos_o, _thickness_position(result, thickness_nm))
    m0 = np.take(m, 0, axis=-3 if result.data.ndim == 5 else -2)  # coefficient l = 0: (…, 3, 3) or (…, 3)
    albedo = m0 * math.sqrt(4.0 * math.pi)
    if albedo.ndim == radiance.ndim + 1:
        return np.maximum(np.einsum("...kc,...c->...k", albedo, radiance), 0.0)
    return np.maximum(albedo * radiance, 0.0)


def shade_combined(result, world_coeffs, pre: Prefiltered, normals, views, thickness_nm=None) -> np.ndarray:
    """The product's shading: split sum for glossy films, SH for rough ones, blended by roughness."""
    from .render import shade_sh

    w = sh_weight(result.material.roughness)
    out = 0.0
    if w < 1.0:
        out = (1.0 - w) * shade_split_sum(result, pre, normals, views, thickness_nm)
    if w > 0.0:
        out = out + w * shade_sh(result, world_coeffs, normals, views, thickness_nm)
    return out
