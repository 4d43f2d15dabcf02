"""The World's lamps in the tails of rough solid glass's paths (glsl/tf_glass_tails.glsl
``tf_glass_spread``, ``tf_lamp_tails``).

Solid glass's paths are followed as smooth glass (:mod:`.glass_exit`); a rough face (GGX, α =
roughness²) turns each path by its facet's tilt times the face's *gain*, and a later refraction
magnifies what came before. The core of that spread is far below a pixel at the benchmark's
roughness (α = 0.0025: 0.14°), but GGX's tails fall as α² / ψ⁴ only: a lamp of 616 seen through
a glass ball's rim, where the exit magnifies every turn many times, shows as a glow a few pixels
wide around each glint, which Cycles renders and a smooth path cannot (the ball's lower rim was
0.78× Cycles' luminance there, docs/transparent-films.md#rough-glass-tails).

The spread, per unit α², in the path's plane of incidence and across it (:func:`path_spread`):

- entering from air at cos θₒ (inside cos θᵢ, Snell): in the plane the refracted direction turns
  by cos θₒ / (η cos θᵢ) − 1 times the tilt, across it by cos θₒ / η − cos θᵢ;
- each reflection inside turns it by 2 (the glints' chosen reflections; totally reflecting faces
  are not counted);
- leaving at cos θₓ inside (cos θₜ outside) magnifies an earlier turn by m = η cos θₓ / cos θₜ in
  the plane (bounded by :data:`..policy.GLASS_TAIL_MAX_GAIN`: at the critical angle it is
  unbounded) and by η across it, and turns the path by m − 1 (η cos θₓ − cos θₜ across);
- the turns' squares add (independent facets): s = Σ gainᵢ² × (later magnification)².

The lobe of directions the path leaves in is GGX's shape in slope space with widths a² = s α²
(:func:`lamp_tails`; a single reflection at normal incidence has s = 4, GGX's own tails); a lamp
of power P (Σ L dω) at slope (x, y) from the exit direction adds P × that density. The lamps are
points, and the World's sharp level already shows each lamp's own image: the lobe is widened by
the lamp's radius :data:`..policy.GLASS_TAIL_CORE` (a² + c², the part a² / (a² + c²) of its
energy left outside the image) and its density inside that radius faded out (× ψ² / (ψ² + c²)).
The plane of incidence is taken through the exit direction and the path's last chord from the
point it entered (exact for a sphere, whose paths lie in one plane).
"""

from __future__ import annotations

import numpy as np

from ..policy import DIVISION_FLOOR, GLASS_TAIL_CORE, GLASS_TAIL_MAX_GAIN, MIN_COS, WALL_GUARD
from .refract import _unit, inner_cosine

__all__ = ["lamp_tails", "path_spread"]


def path_spread(cos_outside, cos_exit, eta: float, reflections: int = 0) -> np.ndarray:
    """(N, 2) spread, per unit α², of paths entering glass of index ``eta`` at cos θₒ =
    ``cos_outside`` (N,), reflected ``reflections`` times inside and leaving at cos θₓ =
    ``cos_exit`` (N,) inside: (in the plane of incidence, across it); see the module."""
    e = max(float(eta), WALL_GUARD)
    co = np.clip(np.asarray(cos_outside, dtype=np.float64), 0.0, 1.0)
    ci = np.maximum(inner_cosine(co, e), MIN_COS)
    cx = np.clip(np.asarray(cos_exit, dtype=np.float64), 0.0, 1.0)
    ct = np.sqrt(np.maximum(1.0 - e * e * (1.0 - cx * cx), 0.0))
    m = e * cx / np.maximum(ct, np.maximum(e * cx / GLASS_TAIL_MAX_GAIN, DIVISION_FLOOR))
    in_plane, in_across = co / (e * ci) - 1.0, co / e - ci
    out_plane, out_across = m - 1.0, e * cx - ct
    k4 = 4.0 * int(reflections)
    return np.stack(
        [
            (in_plane**2 + k4) * m * m + out_plane**2,
            (in_across**2 + k4) * e * e + out_across**2,
        ],
        axis=-1,
    )


def lamp_tails(entry, exits, dirs, spread, roughness: float, lamps) -> np.ndarray:
    """(N, 3) radiance of the World's ``lamps`` (:class:`precompute.world.lamps.Lamps`, in the
    frame of ``dirs``; None: none) in the tails of paths that entered at ``entry`` (N, 3) and
    leave at ``exits`` (N, 3) along unit ``dirs`` (N, 3) with ``spread`` (N, 2)
    (:func:`path_spread`) through glass of ``roughness``; see the module."""
    dirs = np.asarray(dirs, dtype=np.float64)
    out = np.zeros(dirs.shape)
    if lamps is None or not lamps.count:
        return out
    alpha = float(roughness) ** 2
    a2 = np.asarray(spread, dtype=np.float64) * alpha * alpha
    c2 = GLASS_TAIL_CORE * GLASS_TAIL_CORE
    wide = a2 + c2
    scale = np.sqrt(a2[:, 0] * a2[:, 1]) / (np.pi * wide[:, 0] * wide[:, 1])
    chord = np.asarray(exits, dtype=np.float64) - np.asarray(entry, dtype=np.float64)
    e1 = _unit(
        chord - np.sum(chord * dirs, -1, keepdims=True) * dirs,
        _unit(np.cross(dirs, [0.0, 0.0, 1.0]), [1.0, 0.0, 0.0]),
    )
    e2 = np.cross(dirs, e1)
    for direction, power in zip(
        np.asarray(lamps.directions, float), np.asarray(lamps.power, float), strict=True
    ):
        along = dirs @ direction
        ahead = along > 0.0
        safe = np.where(ahead, along, 1.0)
        x, y = (e1 @ direction) / safe, (e2 @ direction) / safe
        s2 = x * x + y * y
        q = 1.0 + x * x / wide[:, 0] + y * y / wide[:, 1]
        weight = np.where(ahead & (a2[:, 0] > 0.0) & (a2[:, 1] > 0.0), scale / (q * q) * s2 / (s2 + c2), 0.0)
        out += weight[:, None] * power
    return out
