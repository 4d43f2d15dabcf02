"""The World's lamps shaded per light direction (numpy twin of glsl/tf_lamps.glsl).

Each lamp (precompute.world.lamps.extract) is a directional light shaded with the exact microfacet
BRDF, D G₂ F(ωo·h) / (4 cos θo), with the film's reflectance F at that light's half-vector
(precompute.colour.film_colour.film_table), times the multiple-scattering factor at the view angle.
The split sum's sharpest levels keep the lamps in the image (policy.LAMP_LEVEL): the analytic
lamps take the rest (:func:`lamp_weight`; the split sum's level blend of it:
split_sum.lamp_weight_at).

References
----------
- Walter, B., Marschner, S., Li, H. & Torrance, K. (2007). Microfacet models for refraction
  through rough surfaces. EGSR.
- Heitz, E. (2014). Understanding the masking-shadowing function in microfacet-based BRDFs.
  JCGT 3(2) (height-correlated Smith G₂).
"""

from __future__ import annotations

import numpy as np

from .. import brdf
from .policy import LAMP_LEVEL, MIN_COS
from .table import lerp_index


def level_lamp_weights(level_count: int) -> np.ndarray:
    """Per prefiltered level, the share of the lamps shaded analytically (0 or 1)."""
    return (np.arange(int(level_count)) >= LAMP_LEVEL).astype(np.float64)


def lamp_weight(lower_level, upper_weight, level_count: int) -> np.ndarray:
    """The analytic lamps' weight at a level blend (lower index, weight of the upper level)."""
    w = level_lamp_weights(level_count)
    lo = np.asarray(lower_level)
    f = np.asarray(upper_weight, dtype=float)
    return (1.0 - f) * w[lo] + f * w[np.minimum(lo + 1, level_count - 1)]


def _lerp(count: int, pos):
    """(lower, upper, weight) for a position in [0, count − 1] (table.lerp_index)."""
    i0, w = lerp_index(pos, count)
    return i0, np.minimum(i0 + 1, count - 1), w


def thickness_lerp(film, thickness_position, count: int):
    """(lower row, upper row, weight) along the film table's thickness rows for ``count``
    points at ``thickness_position`` in [0, 1] (None: the first row), as tf_table_lerp."""
    t_count = film.reflectance.shape[0]
    if thickness_position is None or t_count == 1:
        t0 = np.zeros(count, dtype=int)
        return t0, t0, np.zeros(count)
    return _lerp(t_count, np.asarray(thickness_position, dtype=float).reshape(-1) * (t_count - 1))


def film_at(film, table, rows, u) -> np.ndarray:
    """``table`` (the film's reflectance or multiscatter) at cosine ``u`` (N,) and the thickness
    ``rows`` of :func:`thickness_lerp`, linear in both, like tf_film_at."""
    u_count = film.reflectance.shape[1]
    t_i0, t_i1, t_w = rows
    i0, i1, w = _lerp(u_count, np.asarray(u) * (u_count - 1))
    shape = (-1,) + (1,) * (table.ndim - 2)
    w = w.reshape(shape)
    t_w = np.asarray(t_w).reshape(shape)
    lo = (1 - w) * table[t_i0, i0] + w * table[t_i0, i1]
    hi = (1 - w) * table[t_i1, i0] + w * table[t_i1, i1]
    return (1 - t_w) * lo + t_w * hi


def lit_pixels(film, count: int, roughness: float, normals, views, thickness_position=None) -> tuple:
    """What a light loop needs of its pixels once (the shader's prologue of tf_shade_lamps and
    tf_shade_lights): (normals (N, 3), views (N, 3), GGX α, the film's thickness rows
    (:func:`thickness_lerp`), cos θo clamped to [MIN_COS, 1]); α and what follows are None when
    there is nothing to shade (``count`` lights or no pixel)."""
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    v = np.asarray(views, dtype=np.float64).reshape(-1, 3)
    if count == 0 or n.shape[0] == 0:
        return n, v, None, None, None
    alpha = float(brdf.alpha_from_roughness(roughness))
    rows = thickness_lerp(film, thickness_position, n.shape[0])
    return n, v, alpha, rows, np.clip(np.sum(n * v, axis=-1), MIN_COS, 1.0)


def shade(film, lamps, roughness: float, normals, views, thickness_position=None) -> np.ndarray:
    """Σ_k D G₂ F(ωo·h_k) / (4 cos θo) × power_k × multiscatter(cos θo): (N, 3), mirrored by tf_lamps.glsl.

    ``film``: a :class:`precompute.colour.film_colour.FilmTable`; ``lamps``: a
    :class:`precompute.world.lamps.Lamps`. ``thickness_position`` in [0, 1] along the film table's
    thickness rows (None: the first). F is interpolated linearly in u and thickness, like the
    shader.
    """
    n, v, alpha, rows, cos_o = lit_pixels(film, lamps.count, roughness, normals, views, thickness_position)
    out = np.zeros((n.shape[0], 3))
    if alpha is None:
        return out
    for d, p in zip(lamps.directions, lamps.power, strict=True):
        cos_i = n @ d
        h = v + d
        h /= np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-30)
        weight = brdf.D_ggx(np.clip(np.sum(n * h, axis=-1), 0.0, 1.0), alpha)
        weight = weight * brdf.G2_smith_height_correlated(np.maximum(cos_i, MIN_COS), cos_o, alpha)
        weight = np.where(cos_i > 0.0, weight / (4.0 * cos_o), 0.0)
        u = np.clip(np.sum(v * h, axis=-1), 0.0, 1.0)
        f = film_at(film, film.reflectance, rows, u)
        rgb = f @ p if film.spectral else f * p
        out += weight[:, None] * rgb
    return out * film_at(film, film.multiscatter, rows, cos_o)
