"""Bright lamps of the World, found and lifted out of the image (extraction only).

Under a studio HDRI most of the light comes from a few small, very bright lamps (bpy's
``studio.exr``: 94 % of the power in 0.5 % of the pixels). A glossy film far from a lamp's
mirror direction still catches it in the GGX tail, and it does so with the film's colour *at
that lamp's half-vector*, which neither one colour per pixel (the split sum) nor a truncated SH
expansion (the paper's path) can give. So the World is split in two:

- **lamps**: the pixels brighter than ``threshold`` × the mean luminance, grouped into at most
  policy.MAX_LAMPS clusters by spherical k-means (weighted by luminance × solid angle). Each
  cluster becomes a directional light: power = Σ L dω (RGB), direction = the power-weighted
  mean direction (:func:`extract`). They are shaded with the exact microfacet BRDF and the
  film's reflectance at each light's half-vector by shading.lamps.shade (film table:
  film_colour.film_table);
- **the rest**: the image with those pixels set to zero, which the split sum and SH paths use
  as before (:func:`remove`); the split sum's sharpest prefiltered levels keep the lamps
  (policy.LAMP_LEVEL).

The sum keeps every watt: rest + lamps = the image (tested). What the lamps gain against Cycles:
docs/tuning.md#lamps.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..shading.policy import MAX_LAMPS
from . import hdri
from .prefilter import LUMINANCE

#: A pixel is a lamp pixel when its luminance exceeds THRESHOLD × the World's mean luminance:
#: only small, very bright sources qualify (docs/tuning.md#lamp-threshold).
THRESHOLD = 32.0
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
        """Number of lamps."""
        return int(self.directions.shape[0])

    @staticmethod
    def none() -> Lamps:
        """An empty lamp set (a World without lamps)."""
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
