"""Bright lamps of the World, lifted out of the image and shaded exactly per light direction.

Under a studio HDRI most of the light comes from a few small, very bright lamps (bpy's
``studio.exr``: 94 % of the power in 0.5 % of the pixels). A glossy film far from a lamp's
mirror direction still catches it in the GGX tail, and it does so with the film's colour *at
that lamp's half-vector*, which neither one colour per pixel (the split sum) nor a truncated SH
expansion (the paper's path) can give. So the World is split in two:

- **lamps**: the pixels brighter than ``threshold`` × the mean luminance, grouped into at most
  ``MAX_LAMPS`` clusters by spherical k-means (weighted by luminance × solid angle). Each
  cluster becomes a directional light: power = Σ L dω (RGB), direction = the power-weighted
  mean direction. Each is shaded with the exact microfacet BRDF, D G₂ F(ωo·h) / (4 cos θo),
  with the film's reflectance F at that light's half-vector (:func:`film_table`,
  :func:`shade`);
- **the rest**: the image with those pixels set to zero, which the split sum and SH paths use
  as before (:func:`remove`); the split sum's sharpest prefiltered levels keep the lamps
  (:data:`LAMP_LEVEL`).

The sum keeps every watt: rest + lamps = the image (tested).

Measured against Cycles (benchmarks/cycles_compare.py, mean ΔE2000, combined path, per-channel
colour mode; figures per case in docs/cycles-comparison.md): studio soap r 0.15: 5.14 → 1.4;
studio 400 nm r 0.6: 2.47 → 1.3. Threshold and cluster count: see :data:`THRESHOLD` and
:data:`MAX_LAMPS`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import brdf, constants, hdri
from .prefilter import LUMINANCE
from .render import _lerp_index

#: At most this many lamps (the shader's loop bound; 8 × 2 vec4 in the lighting uniform buffer).
#: Studio soap r 0.15 against Cycles (threshold 32): 8 / 16 clusters 1.53 / 1.29, every lamp
#: pixel its own light (969) 1.21; without lamps 5.14.
MAX_LAMPS = 8
#: A pixel is a lamp pixel when its luminance exceeds THRESHOLD × the World's mean luminance.
#: Against Cycles (8 clusters, the 11 cases of benchmarks/cycles_compare.py), threshold 8 / 32 /
#: 128: studio r 0.05 1.69 / 1.30 / 1.15; studio soap r 0.15 1.51 / 1.53 / 1.61; courtyard r 0.05
#: 2.28 / 0.24 / 0.24 (at 8 the sunlit walls became 8 points: a mirror shows their shape, not
#: points); courtyard r 0.15 1.83 / 0.71 / 0.72; studio r 0.6 1.30 / 1.30 / 1.37; forest r 0.3
#: 1.55 / 1.60 / 1.71. At 32 only small, very bright sources qualify (studio: 969 of 512 k
#: pixels, 87 % of the power; courtyard: the sun's 8 pixels).
THRESHOLD = 32.0
#: Samples of the film table in u = cos θ (uniform 0…1 inclusive).
FILM_SAMPLES = 128
#: Spherical k-means iterations (Lloyd); it stops earlier once the centres stop moving.
KMEANS_ITERATIONS = 30


@dataclass(frozen=True)
class Lamps:
    """Directional lights: unit ``directions`` (K, 3), ``power`` (K, 3) = Σ L dω per lamp (RGB).

    ``pixels``: how many image pixels were lifted out; ``share``: their part of the World's
    luminous power (0…1).
    """

    directions: np.ndarray
    power: np.ndarray
    pixels: int = 0
    share: float = 0.0

    @property
    def count(self) -> int:
        return int(self.directions.shape[0])

    @staticmethod
    def none() -> Lamps:
        return Lamps(np.zeros((0, 3)), np.zeros((0, 3)), 0, 0.0)


def _luminance(img: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """(finite mask, luminance with non-finite pixels 0, ∫ max(Y, 0) dω) of an (H, W, 3) image."""
    ok = np.isfinite(img).all(axis=-1)
    y = np.where(ok[..., None], img, 0.0) @ np.asarray(LUMINANCE)
    power = float(np.sum(np.maximum(y, 0.0) * hdri.equirect_solid_angles(*img.shape[:2])))
    return ok, y, power


def _checked(image, threshold) -> np.ndarray:
    img = np.asarray(image, dtype=np.float64)[..., :3]
    if img.ndim != 3 or img.shape[0] < 1 or img.shape[1] < 1:
        raise ValueError(f"image must have shape (H, W, 3), got {img.shape}")
    if not threshold > 0 or not np.isfinite(threshold):
        raise ValueError(f"threshold must be a positive number, got {threshold!r}")
    return img


def lamp_mask(image: np.ndarray, threshold: float = THRESHOLD) -> np.ndarray:
    """(H, W) bool: finite pixels brighter than ``threshold`` × the mean luminance."""
    ok, y, power = _luminance(_checked(image, threshold))
    return ok & (y > threshold * power / (4.0 * np.pi)) if power > 0.0 else np.zeros_like(ok)


def _kmeans(directions: np.ndarray, weights: np.ndarray, k: int) -> np.ndarray:
    """Labels (N,) of a weighted spherical k-means; deterministic (farthest-point start)."""
    centres = [directions[int(np.argmax(weights))]]
    for _ in range(1, k):
        dist = 1.0 - np.max(directions @ np.asarray(centres).T, axis=1)
        score = weights * np.maximum(dist, 0.0)
        if not np.any(score > 0):
            break
        centres.append(directions[int(np.argmax(score))])
    c = np.asarray(centres)
    labels = np.argmax(directions @ c.T, axis=1)
    for _ in range(KMEANS_ITERATIONS):
        sums = np.zeros_like(c)
        np.add.at(sums, labels, weights[:, None] * directions)
        norm = np.linalg.norm(sums, axis=1, keepdims=True)
        c = np.where(norm > 0, sums / np.where(norm > 0, norm, 1.0), c)
        new = np.argmax(directions @ c.T, axis=1)
        if np.array_equal(new, labels):
            break
        labels = new
    return labels


def extract(
    image: np.ndarray, threshold: float = THRESHOLD, max_lamps: int = MAX_LAMPS
) -> tuple[Lamps, np.ndarray]:
    """(lamps, mask): the World's bright pixels as at most ``max_lamps`` directional lights.

    ``image``: equirect radiance (H, W, 3), top row first (docs/conventions.md); NaN/Inf pixels
    are never lamps. ``mask`` (H, W) marks the pixels the lamps carry: :func:`remove` zeroes
    them. A World without pixels above the threshold (uniform, dim, black) gives no lamps.
    """
    if int(max_lamps) < 0:
        raise ValueError(f"max_lamps must be ≥ 0, got {max_lamps!r}")
    img = _checked(image, threshold)
    ok, y_all, total = _luminance(img)
    mask = ok & (y_all > threshold * total / (4.0 * np.pi)) if total > 0.0 else np.zeros_like(ok)
    if max_lamps == 0 or not mask.any():
        return Lamps.none(), np.zeros(img.shape[:2], dtype=bool)
    dirs = hdri.equirect_directions(*img.shape[:2])[mask]
    radiance = img[mask]
    w = hdri.equirect_solid_angles(*img.shape[:2])[mask]
    weights = y_all[mask] * w
    k = min(int(max_lamps), int(mask.sum()))
    labels = _kmeans(dirs, weights, k)
    directions, power = [], []
    for label in np.unique(labels):
        sel = labels == label
        d = np.sum(weights[sel, None] * dirs[sel], axis=0)
        norm = np.linalg.norm(d)
        if not norm > 0:
            continue
        directions.append(d / norm)
        power.append(np.sum(radiance[sel] * w[sel, None], axis=0))
    lamps = Lamps(
        np.asarray(directions, dtype=np.float64).reshape(-1, 3),
        np.asarray(power, dtype=np.float64).reshape(-1, 3),
        int(mask.sum()),
        float(np.sum(weights) / total) if total > 0 else 0.0,
    )
    return lamps, mask


def remove(image: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """The image with the lamp pixels set to zero (float64 copy)."""
    out = np.array(np.asarray(image, dtype=np.float64)[..., :3])
    out[np.asarray(mask, dtype=bool)] = 0.0
    return out


# ----------------------------------------------------------------------------------------------
# The split sum's sharpest levels keep the lamps
# ----------------------------------------------------------------------------------------------
#: Prefiltered levels below this index keep the lamps in the image (levels 0 and 1: roughness 0
#: and 0.0156); from it on (roughness ≥ 0.0625) they hold the World without them, and the lamps
#: are shaded analytically with the weight of the level blend (:func:`lamp_weight`). On a mirror
#: a directional light is a spike no pixel sample finds, and on a near-mirror it shows a
#: softbox as a few dots; the image shows their shape where Cycles does (tests/test_glossy.py).
#: From roughness ≈ 0.1 the GGX tails dominate and the per-lamp colour wins. Against Cycles
#: (mean ΔE2000, threshold 32): lamps lifted from level 1 / 2 / 3 on: studio r 0.05 1.23 / 1.39 /
#: 1.29; studio soap r 0.15 1.38 / 1.38 / 2.67; courtyard r 0.15 0.71 / 0.71 / 0.72. Level 2
#: keeps the softboxes' shape on the soap-bubble preset (roughness 0.05: 59 % from the image).
LAMP_LEVEL = 2


def level_lamp_weights(level_count: int) -> np.ndarray:
    """Per prefiltered level, the share of the lamps shaded analytically (0 or 1)."""
    return (np.arange(int(level_count)) >= LAMP_LEVEL).astype(np.float64)


def lamp_weight(lower_level, upper_weight, level_count: int) -> np.ndarray:
    """The analytic lamps' weight at a level blend (lower index, weight of the upper level)."""
    w = level_lamp_weights(level_count)
    lo = np.asarray(lower_level)
    f = np.asarray(upper_weight, dtype=float)
    return (1.0 - f) * w[lo] + f * w[np.minimum(lo + 1, level_count - 1)]


# ----------------------------------------------------------------------------------------------
# The film's reflectance per light direction
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class FilmTable:
    """The film's specular reflectance against u = cos θ (uniform 0…1, ``FILM_SAMPLES``).

    ``reflectance``: (T, U, 3, 3) spectral (row = output RGB, column = light RGB) or (T, U, 3)
    per channel, T = the bake's thickness rows. ``multiscatter``: (T, U, 3) the factor the
    bake applied at view cosine u (1 without multiple scattering), so lamps match the table.
    """

    reflectance: np.ndarray
    multiscatter: np.ndarray
    thicknesses_nm: np.ndarray

    @property
    def spectral(self) -> bool:
        return self.reflectance.ndim == 4


def film_table(result, samples: int = FILM_SAMPLES) -> FilmTable:
    """The film reflectance of a :class:`bake.BakeResult` 's material at its thickness rows."""
    from .render import film_rgb_matrices

    material = result.material
    thicknesses = np.atleast_1d(np.asarray(result.thicknesses_nm, dtype=float))
    u = np.linspace(0.0, 1.0, int(samples))
    rows = []
    for t in thicknesses:
        _, rg, _, _, _ = film_rgb_matrices(material, float(t) if material.thicknesses() else None, samples)
        rows.append(rg)
    rg = np.stack(rows)  # (T, U, 3, 3)
    spectral = np.asarray(result.data).ndim == 5
    reflectance = rg if spectral else np.einsum("tukk->tuk", rg)
    ms = np.stack([_multiscatter(material, u, rg_t) for rg_t in rg])
    return FilmTable(reflectance, np.ascontiguousarray(ms), thicknesses)


def _multiscatter(material, u: np.ndarray, rg: np.ndarray) -> np.ndarray:
    """(U, 3): the factor :func:`bake.apply_multiscatter` applies at view cosine u.

    "cycles": the bare dielectric's F_avg, as the bake. "film": F_avg per channel from the
    film's single-scattering white-light albedo over E (the bake takes the same ratio on its
    own view samples, so the two agree to the quadrature: a few 1e-3 of the factor).
    """
    from . import bake

    if material.multiscatter == "none" or material.roughness <= 0.0:
        return np.ones((u.size, 3))
    if material.multiscatter == "cycles":  # the bake's own factor, per output row of a unit table
        return bake.apply_multiscatter(np.ones((1, u.size, 1, 3, 1)), material, u)[0, :, 0, :, 0]
    white = rg.sum(axis=-1)  # (U, 3): the film's reflectance of white light per output channel
    mu, wmu = np.polynomial.legendre.leggauss(32)
    mu, wmu = 0.5 * (mu + 1.0), 0.5 * wmu

    def reflectance(x):
        return np.stack([np.interp(x, u, white[:, c]) for c in range(3)], axis=-1)

    e_film = brdf.directional_albedo(mu, material.roughness, reflectance, 128, 64)  # (32, 3)
    e = brdf.ggx_E(float(material.roughness), tuple(np.clip(mu, constants.MIN_COS, 1.0).tolist()))
    f_avg = np.clip(np.sum(e_film / e[:, None] * (2.0 * mu * wmu)[:, None], axis=0), 0.0, 1.0)
    return np.stack([brdf.multiscatter_scale(u, material.roughness, f) for f in f_avg], axis=-1)


def _lerp(count: int, pos):
    """(lower, upper, weight) for a position in [0, count − 1] (render._lerp_index)."""
    i0, w = _lerp_index(pos, count)
    return i0, np.minimum(i0 + 1, count - 1), w


def shade(
    film: FilmTable, lamps: Lamps, roughness: float, normals, views, thickness_position=None
) -> np.ndarray:
    """Σ_k D G₂ F(ωo·h_k) / (4 cos θo) × power_k × multiscatter(cos θo): (N, 3), mirrored by tf_lamps.glsl.

    ``thickness_position`` in [0, 1] along the film table's thickness rows (None: the first).
    F is interpolated linearly in u and thickness, like the shader.
    """
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    v = np.asarray(views, dtype=np.float64).reshape(-1, 3)
    out = np.zeros((n.shape[0], 3))
    if lamps.count == 0 or n.shape[0] == 0:
        return out
    alpha = float(brdf.alpha_from_roughness(roughness))
    t_count, u_count = film.reflectance.shape[:2]
    if thickness_position is None or t_count == 1:
        t0 = np.zeros(n.shape[0], dtype=int)
        t1, tw = t0, np.zeros(n.shape[0])
    else:
        t0, t1, tw = _lerp(t_count, np.asarray(thickness_position, dtype=float).reshape(-1) * (t_count - 1))

    def at(table, t_i0, t_i1, t_w, u):
        i0, i1, w = _lerp(u_count, u * (u_count - 1))
        shape = (-1,) + (1,) * (table.ndim - 2)
        w = w.reshape(shape)
        t_w = t_w.reshape(shape)
        lo = (1 - w) * table[t_i0, i0] + w * table[t_i0, i1]
        hi = (1 - w) * table[t_i1, i0] + w * table[t_i1, i1]
        return (1 - t_w) * lo + t_w * hi

    cos_o = np.clip(np.sum(n * v, axis=-1), constants.MIN_COS, 1.0)
    for d, p in zip(lamps.directions, lamps.power, strict=True):
        cos_i = n @ d
        h = v + d
        h /= np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-30)
        weight = brdf.D_ggx(np.clip(np.sum(n * h, axis=-1), 0.0, 1.0), alpha)
        weight = weight * brdf.G2_smith_height_correlated(np.maximum(cos_i, constants.MIN_COS), cos_o, alpha)
        weight = np.where(cos_i > 0.0, weight / (4.0 * cos_o), 0.0)
        u = np.clip(np.sum(v * h, axis=-1), 0.0, 1.0)
        f = at(film.reflectance, t0, t1, tw, u)
        rgb = f @ p if film.spectral else f * p
        out += weight[:, None] * rgb
    return out * at(film.multiscatter, t0, t1, tw, cos_o)
