"""Split-sum image-based lighting and the product's combined shading (numpy twin of
glsl/tf_split_sum.glsl).

The World prefiltered by the GGX lobe at a ladder of roughness levels (precompute.world.prefilter) is
looked up in the reflection direction and multiplied by the film's directional albedo, the l = 0
table entry × √(4π) (Karis 2013). The albedo is read at the half-vector angle of the lobe's
light-weighted mean direction (:func:`dominant_cosine`) where policy.uses_moment says so.
:func:`shade_combined` blends this with the SH path by roughness (policy.sh_weight) and adds the
World's lamps (shading.lamps), as ``tf_shade_combined`` does.

References
----------
- Karis, B. (2013). Real Shading in Unreal Engine 4. SIGGRAPH course notes (split-sum).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..world.hdri import equirect_lookup
from . import lamps as lamp_shading
from .policy import DIVISION_FLOOR, MOMENT_EPS, effective_roughness, sh_weight, uses_moment
from .sh_sum import shade_sh
from .table import lookup as table_lookup
from .table import thickness_position


def level_blend(roughness, level_roughness) -> tuple[np.ndarray, np.ndarray]:
    """(lower level index, weight of the upper level) for ``roughness`` between two levels.

    The levels are blended so that the blend's α² (= r⁴) is the material's: w = (r⁴ − r₀⁴) /
    (r₁⁴ − r₀⁴). GGX tails scale as α², and with HDR lamps the tails are what shows
    (docs/tuning.md#level-blend). Mirrored in tf_split_sum.glsl.
    """
    levels = np.asarray(level_roughness, dtype=float)
    r = np.clip(np.asarray(roughness, dtype=float), levels[0], levels[-1])
    lo = np.clip(np.searchsorted(levels, r, side="right") - 1, 0, levels.size - 2)
    a4, b4 = levels[lo] ** 4, levels[lo + 1] ** 4
    return lo, np.clip((r**4 - a4) / np.maximum(b4 - a4, DIVISION_FLOOR), 0.0, 1.0)


def _blend(pre, directions: np.ndarray, roughness, stacks) -> list[np.ndarray]:
    """Each of ``stacks`` (per-level images) at ``directions``, α²-matched level blend shared.

    The World's turn and strength (``pre.rotation`` Q, ``pre.scale``) apply here, as in
    tf_prefiltered_lookup: the levels are read at Q d and scaled; :func:`_to_world` turns a
    moment read this way back into the World's frame.
    """
    directions = np.asarray(directions, dtype=float)
    r = np.broadcast_to(np.asarray(roughness, dtype=float), directions.shape[:-1])
    q = getattr(pre, "rotation", None)
    if q is not None:
        directions = directions @ np.asarray(q, dtype=float).T
    lo, frac = level_blend(r, pre.roughness)
    frac = frac[..., None]
    outs = [np.zeros(directions.shape[:-1] + (3,)) for _ in stacks]
    for level in np.unique(lo):
        sel = lo == level
        for out, levels in zip(outs, stacks, strict=True):
            a = equirect_lookup(levels[level], directions[sel])
            b = equirect_lookup(levels[level + 1], directions[sel])
            out[sel] = (1 - frac[sel]) * a + frac[sel] * b
    scale = float(getattr(pre, "scale", 1.0))
    return [out * scale if scale != 1.0 else out for out in outs]


def _to_world(pre, moment: np.ndarray) -> np.ndarray:
    """A moment read by :func:`_blend` (the content's frame) in the World's frame: Qᵀ m."""
    q = getattr(pre, "rotation", None)
    return moment if q is None else moment @ np.asarray(q, dtype=float)


def lamp_weight_at(pre, roughness) -> np.ndarray:
    """The analytic lamps' weight at the level blend of (effective) ``roughness``; 0 without lamps.

    Here rather than in shading/lamps.py because, as in the GLSL (tf_prefiltered_lookup), it is
    part of the split sum's level lookup.
    """
    r = np.asarray(roughness, dtype=float)
    if pre.lamp_weights is None:
        return np.zeros(r.shape)
    lo, frac = level_blend(r, pre.roughness)
    return lamp_shading.lamp_weight(lo, frac, len(pre.levels))


def lookup(pre, directions: np.ndarray, roughness, moments: bool = False) -> np.ndarray:
    """Prefiltered radiance in ``directions`` at per-pixel ``roughness`` (α²-matched level blend).

    ``pre``: a :class:`precompute.world.prefilter.Prefiltered`. ``moments=True`` reads the luminance ×
    direction moments instead (same blend).
    """
    found = _blend(pre, directions, roughness, [pre.moments if moments else pre.levels])[0]
    return _to_world(pre, found) if moments else found


def _cosine_from_moment(moment, views, cos_o) -> np.ndarray:
    norm2 = np.sum(moment * moment, axis=-1)
    ok = norm2 > MOMENT_EPS
    c = moment / np.sqrt(np.where(ok, norm2, 1.0))[..., None]
    cos_p = np.sqrt(np.clip(0.5 * (1.0 + np.sum(np.asarray(views, dtype=float) * c, axis=-1)), 0.0, 1.0))
    return np.where(ok, cos_p, cos_o)


def dominant_cosine(pre, reflections, roughness, views, cos_o) -> np.ndarray:
    """cos θ' = √((1 + v·c)/2): the half-vector cosine of the lobe's light-weighted mean direction c.

    c is the direction of the prefiltered luminance × direction moment at the lookup's level
    and direction. v·l is linear in l, so v·c is the light-weighted mean of v·l up to c's
    normalisation; l = reflect(v, h) gives v·h = √((1 + v·l)/2). Uniform light gives c = r
    and cos θ' = cos θo. Where the moment vanishes (black World in the lobe, or no moments)
    the view angle is kept. Measurements: docs/tuning.md#dominant-cosine.
    """
    cos_o = np.asarray(cos_o, dtype=float)
    if pre.moments is None:
        return cos_o
    return _cosine_from_moment(lookup(pre, reflections, roughness, moments=True), views, cos_o)


def shade_split_sum(result, pre, normals, views, thickness_nm=None) -> np.ndarray:
    """Film albedo (3×3, from the l = 0 entry) × prefiltered radiance in the reflection direction.

    The albedo is read at the half-vector angle of the lobe's light (:func:`dominant_cosine`).
    """
    n = np.asarray(normals, dtype=float)
    v = np.asarray(views, dtype=float)
    cos_o = np.clip(np.sum(n * v, axis=-1), 0.0, 1.0)
    refl = 2.0 * cos_o[..., None] * n - v
    r_eff = effective_roughness(result.material.roughness, cos_o)
    if pre.moments is None:
        radiance, cos_p = lookup(pre, refl, r_eff), cos_o
    else:  # dominant_cosine, sharing the level blend with the radiance
        radiance, moment = _blend(pre, refl, r_eff, [pre.levels, pre.moments])
        moment = _to_world(pre, moment)
        cos_p = _cosine_from_moment(moment, v, cos_o)
    m = table_lookup(result.data, cos_p, thickness_position(result, thickness_nm))
    m0 = np.take(m, 0, axis=-3 if result.data.ndim == 5 else -2)  # coefficient l = 0: (…, 3, 3) or (…, 3)
    albedo = m0 * math.sqrt(4.0 * math.pi)
    if albedo.ndim == radiance.ndim + 1:
        return np.maximum(np.einsum("...kc,...c->...k", albedo, radiance), 0.0)
    return np.maximum(albedo * radiance, 0.0)


def shade_combined(
    result, world_coeffs, pre, normals, views, thickness_nm=None, lamps=None, film=None
) -> np.ndarray:
    """The product's shading: split sum for glossy films, SH for rough ones, blended by roughness.

    With ``lamps`` (:class:`precompute.world.lamps.Lamps`) and ``film``
    (:func:`precompute.colour.film_colour.film_table`) the World's lamps are added, shaded per light
    direction (:func:`precompute.shading.lamps.shade`); ``world_coeffs`` and ``pre`` from
    ``prefilter(…, lamp_mask=…)``. The SH half sees the World without its lamps (weight 1); the
    split-sum half keeps them in its sharpest levels (:func:`lamp_weight_at`). The split sum reads
    the albedo at the dominant-direction angle where policy.uses_moment says so, else at the view
    angle.
    """
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
            raise ValueError("lamps need the film table (film_colour.film_table)")
        n = np.asarray(normals, dtype=float)
        v = np.asarray(views, dtype=float)
        cos_o = np.clip(np.sum(n * v, axis=-1), 0.0, 1.0)
        weight = w + (1.0 - w) * lamp_weight_at(pre, effective_roughness(result.material.roughness, cos_o))
        position = thickness_position(result, thickness_nm)
        if position is not None:
            position = position / (result.thicknesses_nm.size - 1)
        lit = lamp_shading.shade(film, lamps, result.material.roughness, n, v, position)
        out = out + weight[..., None] * lit.reshape(n.shape)
    return out
