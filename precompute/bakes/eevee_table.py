"""The film table EEVEE renders a film from: the film's albedo over EEVEE's own split sum.

EEVEE (Blender 5.x) shades a Glossy BSDF of colour C as C × E(μ, r) × the prefiltered radiance
of its lobe (``node_bsdf_glossy``: ``F_brdf_single_scatter(C, C, lut)`` with F0 = F90 = C, so
C × (scale + bias) of its split-sum LUT), and its light objects as C × E(μ, r) × the light's
normalised GGX lobe (LTC). Our film's split sum is A(μ, d) × the prefiltered radiance, A the
film's lobe-integrated directional albedo (the l = 0 table entry × √(4π), the 3×3 matrix's row
sums for white light in the spectral mode). So a Glossy colour of A / E makes EEVEE return our
albedo (:func:`glossy_colour`); the image holds it on the bake's own axes: view angle θo
uniform 0…90° (width) × the table's thickness rows (height), one band of rows per quantity
(:data:`BANDS`).

E is EEVEE's LUT as EEVEE defines it (``eevee_bxdf_lut``: GGX single scattering with the
separable Smith G₁(v)·G₁(l), α = roughness², on a 64 × 64 grid in (roughness, √(1 − μ)) read
bilinearly at texel centres): :func:`eevee_split_sum` integrates it on that grid and reads it
the same way (:func:`eevee_lut_scale`). Measured residual against real EEVEE renders:
docs/eevee-native.md.

Bands (rows ``band · T … band · T + T − 1``):

- ``specular``: A × S (S the transparent wall's reflection scale, 1 for an opaque film);
- ``inverse``: 1/E(θo) (the same in every row), which the group multiplies by;
- ``diffuse`` (a diffuse base): the base's uniform-light albedo under the film divided by the
  base colour per channel (Cycles' layering weight in the per-channel mode), which the node
  group multiplies by the Base Color socket;
- ``transmission`` (a transparent wall, :mod:`precompute.shading.transmit`): the wall's transmittance T
  per channel, a Transparent BSDF's colour (EEVEE passes it through unchanged).

No bpy here: the add-on writes :attr:`FilmImage.pixels` into a packed float image
(addon/eevee/).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from .. import brdf
from ..shading import transmit

__all__ = [
    "BANDS",
    "DIRECTIONS_SIZE",
    "EEVEE_LUT_SIZE",
    "FORMAT_VERSION",
    "FilmImage",
    "LobeLights",
    "dominant_directions",
    "decode_directions",
    "dominant_weight",
    "eevee_lut_scale",
    "eevee_split_sum",
    "film_image",
    "glossy_colour",
    "light_moments",
    "lobe_norm",
    "shadow_fit",
    "shadow_model",
    "table_albedo",
    "white_reflectance_at",
]

#: Version of the image's layout and maths: part of the key the add-on stores with an image.
FORMAT_VERSION = 4
#: EEVEE's utility LUT is EEVEE_LUT_SIZE² texels (``UTIL_TEX_SIZE``), read with linear filtering.
EEVEE_LUT_SIZE = 64
#: EEVEE clamps the LUT's view cosine to [1e-4, 0.9999] when it integrates it.
LUT_COS_MIN, LUT_COS_MAX = 1e-4, 0.9999
#: The image's bands, in row order (a band is present only when the film needs it).
BANDS = ("specular", "inverse", "diffuse", "transmission")
#: Gauss–Legendre nodes over the GGX half-vector CDF and half-plane azimuth nodes of the LUT's
#: integral: E to < 1e-4 against 4× as many (tests/eevee/test_eevee_table.py).
_XI_NODES, _PHI_NODES = 64, 48
#: A split sum below this counts as 0 (a view at the horizon): the colour there is not divided.
MIN_SCALE = 1e-4
#: The dominant-direction image: (width, height) of its equirect grid. The moment field is
#: GGX-blurred, smooth at the glossiest level the prefilter keeps; EEVEE reads it bilinearly.
DIRECTIONS_SIZE = (128, 64)
#: Roughness ramp (from, to) of the lobe light's angle: below ``from`` the film is read at the
#: view angle, above ``to`` at θ', linearly between. Measured with EEVEE against Cycles (64 px,
#: 256 spp, mean ΔE2000 view angle → θ'): forest 400 nm r 0.3 3.24 → 2.78, courtyard 800 nm
#: r 0.3 4.68 → 4.25, r 0.5 8.39 → 7.26; but studio 500 nm r 0.05 2.96 → 3.73, r 0.15 12.6 →
#: 12.9, courtyard 300 nm r 0.15 1.44 → 1.48: a glossy lobe's prefiltered moment points at the
#: lamps EEVEE lights the film with separately (its extracted sun), away from the view angle
#: the highlight is seen at.
DOMINANT_RAMP = (0.15, 0.3)
#: Squared moment length below which the World is black in the lobe: the reflection direction
#: itself (then θ' = θo), as shading/split_sum.MOMENT_EPS.
MOMENT_EPS = 1e-30
#: Length of the stored direction where the light objects hold none of the lobe's light; where
#: they hold all of it, 1: the length encodes their share s as 0.5 + 0.5 s (:func:`dominant_directions`).
SHARE_FLOOR = 0.5
#: Midpoints over the GGX half-vector CDF of :func:`lobe_norm` (the kink at θh = 45° makes
#: Gauss–Legendre no better): Z to < 1e-4 against 8× as many.
_NORM_NODES = 2048


def _smith_g1(cos_x, a2):
    """Smith's GGX masking G₁ for a direction at cosine ``cos_x`` (EEVEE's ``bxdf_ggx_smith_G1``)."""
    c = np.maximum(np.asarray(cos_x, dtype=np.float64), 1e-12)
    return 2.0 / (1.0 + np.sqrt(1.0 + a2 * (1.0 / (c * c) - 1.0)))


def eevee_split_sum(cos_o, roughness: float) -> np.ndarray:
    """E(μ, r): the directional albedo of EEVEE's single-scattering GGX (Fresnel 1) at view cosines
    ``cos_o`` (any shape) and Blender roughness ``roughness`` (α = r²), with the separable Smith
    G₁(v)·G₁(l) of its LUT (``GGXBrdfClosure``: ``scale + bias``). Exact integral (no LUT grid).

    E = ∫ D(h) G₁(v) G₁(l) (v·h) / μ dω_h over half vectors with l = reflect(v, h) above the
    surface, integrated by importance over D(h) cos θ_h (Gauss–Legendre in the CDF, a uniform
    grid in azimuth).
    """
    mu = np.clip(np.asarray(cos_o, dtype=np.float64), LUT_COS_MIN, LUT_COS_MAX)
    alpha = max(float(roughness) ** 2, 1e-7)
    a2 = alpha * alpha
    x, w = np.polynomial.legendre.leggauss(_XI_NODES)
    xi, w_xi = 0.5 * (x + 1.0), 0.5 * w
    cos2 = (1.0 - xi) / (1.0 + (a2 - 1.0) * xi)  # GGX: cos²θ_h of the CDF's quantile ξ
    ch = np.sqrt(cos2)
    sh = np.sqrt(np.maximum(1.0 - cos2, 0.0))
    phi = (np.arange(_PHI_NODES) + 0.5) * np.pi / _PHI_NODES  # the half plane; mirror symmetric
    hx = sh[:, None] * np.cos(phi)[None, :]
    hz = np.broadcast_to(ch[:, None], hx.shape)
    flat = mu.reshape(-1)
    sv = np.sqrt(1.0 - flat * flat)
    vh = sv[:, None, None] * hx[None] + flat[:, None, None] * hz[None]  # v = (sin, 0, cos)
    nl = 2.0 * vh * hz[None] - flat[:, None, None]  # (reflect(−v, h))·n
    ok = (nl > 0.0) & (vh > 0.0)
    g = _smith_g1(flat, a2)[:, None, None] * _smith_g1(nl, a2)
    f = np.where(ok, g * vh / (flat[:, None, None] * hz[None]), 0.0)
    out = np.einsum("mij,i->m", f, w_xi) / _PHI_NODES
    return out.reshape(mu.shape)


@functools.lru_cache(maxsize=8)
def _lut_column(index: int) -> np.ndarray:
    """E at the LUT's roughness node ``index`` (of ``EEVEE_LUT_SIZE``) and its 64 view nodes
    y = √(1 − μ) = j / 63. Cached, read-only."""
    y = np.arange(EEVEE_LUT_SIZE) / (EEVEE_LUT_SIZE - 1.0)
    column = eevee_split_sum(1.0 - y * y, index / (EEVEE_LUT_SIZE - 1.0))
    column.flags.writeable = False
    return column


def eevee_lut_scale(cos_o, roughness: float) -> np.ndarray:
    """E(μ, r) as EEVEE reads it: its LUT's nodes (:func:`eevee_split_sum` at roughness i/63 and
    √(1 − μ) = j/63) interpolated bilinearly, as the GPU's linear filter does at texel centres
    (``utility_tx_sample_lut``)."""
    last = EEVEE_LUT_SIZE - 1
    r = min(max(float(roughness), 0.0), 1.0) * last
    r0 = min(int(math.floor(r)), last - 1)
    wr = r - r0
    y = np.sqrt(np.clip(1.0 - np.asarray(cos_o, dtype=np.float64), 0.0, 1.0)) * last
    j0 = np.minimum(np.floor(y).astype(int), last - 1)
    wy = y - j0
    out = 0.0
    for index, weight in ((r0, 1.0 - wr), (r0 + 1, wr)):
        if weight == 0.0:
            continue
        column = _lut_column(index)
        out = out + weight * ((1.0 - wy) * column[j0] + wy * column[j0 + 1])
    return np.asarray(out)


def glossy_colour(albedo, cos_o, roughness: float) -> np.ndarray:
    """The Glossy BSDF colour (…, 3) that makes EEVEE return ``albedo`` (…, 3) at view cosines
    ``cos_o`` (…): albedo / E (:func:`eevee_lut_scale`), left as it is where E vanishes."""
    scale = np.asarray(eevee_lut_scale(cos_o, roughness))[..., None]
    albedo = np.asarray(albedo, dtype=np.float64)
    return np.where(scale > MIN_SCALE, albedo / np.maximum(scale, MIN_SCALE), albedo)


def table_albedo(data: np.ndarray) -> np.ndarray:
    """The film's directional albedo (T, A, 3) for white light from a bake's table (T, A, K, 3[, 3]):
    the l = 0 entry × √(4π) (Y₀₀ = 1/√(4π)); spectral tables' 3×3 matrices summed over the
    light's channels (white light E, docs/conventions.md)."""
    data = np.asarray(data, dtype=np.float64)
    entry = data[:, :, 0] * math.sqrt(4.0 * math.pi)
    return entry.sum(axis=-1) if entry.ndim == 4 else entry


def white_reflectance_at(film, cos_o: np.ndarray) -> np.ndarray:
    """The film's reflectance of white light (T, A, 3) at view cosines ``cos_o`` (A,), every
    thickness row of ``film`` (:class:`precompute.colour.film_colour.FilmTable`), interpolated linearly
    on its uniform u grid (as the overlay's walls, shading/transmit.white_reflectance)."""
    f = np.asarray(film.reflectance, dtype=np.float64)
    if f.ndim == 4:
        f = f.sum(axis=-1)
    u = np.linspace(0.0, 1.0, f.shape[1])
    c = np.clip(np.asarray(cos_o, dtype=np.float64), 0.0, 1.0)
    out = np.empty((f.shape[0], c.size, 3))
    for row in range(f.shape[0]):
        for ch in range(3):
            out[row, :, ch] = np.interp(c, u, f[row, :, ch])
    return out


@dataclass(frozen=True)
class FilmImage:
    """The pixels of a film's EEVEE image and the axes the node group maps onto them.

    ``pixels``: (H, W, 4) float32 RGBA, row 0 at the bottom (Blender's order), W = view angles
    (θo uniform 0…90°), H = rows × bands; ``rows``: thickness rows per band (T);
    ``thickness_nm``: (lo, hi) of the rows (equal for one row); ``bands``: band name → index;
    ``shadow``: a thin wall's shadow transmittance, (r0 R, G, B, e) of :func:`shadow_fit`, or None.
    """

    pixels: np.ndarray
    rows: int
    thickness_nm: tuple
    bands: dict
    shadow: tuple | None = None

    @property
    def width(self) -> int:
        """View angles: the image's width."""
        return int(self.pixels.shape[1])

    @property
    def height(self) -> int:
        """Rows × bands: the image's height."""
        return int(self.pixels.shape[0])


def film_image(result, film=None, wall=None, base_result=None, base_color=None) -> FilmImage:
    """The EEVEE image of a film from its bake.

    ``result``: the :class:`precompute.bakes.bake.BakeResult` of the film without a diffuse base (any
    SH order: entry 0 does not depend on it). ``base_result``: the bake of the same film with its
    diffuse base ``base_color`` (RGB), or None. ``wall``: (mode, η[, tint r, g, b]) of a transparent film
    (:mod:`precompute.shading.transmit`), with ``film`` its :class:`~precompute.colour.film_colour.FilmTable`;
    None for an opaque film.
    """
    cos_o = np.cos(np.asarray(result.view_angles_rad, dtype=np.float64))
    roughness = float(result.material.roughness)
    shadow = None
    albedo = table_albedo(result.data)  # (T, A, 3)
    t_rows = albedo.shape[0]
    bands = {"specular": albedo}
    if wall is not None:
        if film is None:
            raise ValueError("a transparent film's EEVEE image needs its film table")
        r = white_reflectance_at(film, cos_o)
        if r.shape[0] != t_rows:
            raise ValueError(f"film table has {r.shape[0]} thickness rows, the bake {t_rows}")
        tint = transmit.wall_tint(wall)  # 1 for the extension's own walls
        transmittance, scale = transmit.wall(r, cos_o[None, :], int(wall[0]), float(wall[1]), tint)
        if int(wall[0]) == transmit.WALL_SOLID:
            transmittance = transmittance * tint  # √tint in and √tint out (Cycles' glass)
        bands = {"specular": albedo * scale, "transmission": transmittance}
        if int(wall[0]) != transmit.WALL_SOLID:
            r0, exponent = shadow_fit(transmittance, cos_o)
            shadow = (*(float(x) for x in r0), exponent)
    inverse = glossy_colour(np.ones((1, cos_o.size, 3)), cos_o[None, :], roughness)
    bands["inverse"] = np.broadcast_to(inverse, (t_rows, cos_o.size, 3))
    if base_result is not None:
        base = np.asarray(base_color, dtype=np.float64).reshape(3)
        diffuse = table_albedo(base_result.data) - albedo
        safe = np.where(base > 0.0, base, 1.0)
        bands["diffuse"] = np.where(base > 0.0, diffuse / safe, 0.0)
    order = [name for name in BANDS if name in bands]
    stack = np.concatenate([np.maximum(bands[name], 0.0) for name in order], axis=0)  # (rows, A, 3)
    pixels = np.ones(stack.shape[:2] + (4,), dtype=np.float32)
    pixels[..., :3] = stack
    thick = np.atleast_1d(np.asarray(result.thicknesses_nm, dtype=np.float64))
    return FilmImage(
        pixels=pixels,
        rows=t_rows,
        thickness_nm=(float(thick[0]), float(thick[-1])),
        bands={name: i for i, name in enumerate(order)},
        shadow=shadow,
    )


#: The exponents :func:`shadow_fit` tries.
SHADOW_EXPONENTS = np.linspace(1.0, 10.0, 181)


def shadow_model(r0, exponent: float, cos_i) -> np.ndarray:
    """A thin wall's transmittance (1 − r)/(1 + r) with r = r0 + (1 − r0)(1 − c)^e at the
    cosines ``cos_i`` (..., 1) per channel of ``r0`` (3,): the wall's two faces, each reflecting
    r (a Schlick curve), light passing both with every inter-reflection."""
    p = np.clip(1.0 - np.asarray(cos_i, dtype=np.float64), 0.0, 1.0) ** float(exponent)
    r = np.asarray(r0, dtype=np.float64) * (1.0 - p) + p
    return (1.0 - r) / (1.0 + r)


def shadow_fit(transmittance, cos_o) -> tuple[np.ndarray, float]:
    """(r0 per channel, e) of :func:`shadow_model` nearest (least squares over the view angles) to a
    wall's transmittance averaged over its thickness rows: ``transmittance`` (rows, A, 3) at the
    cosines ``cos_o`` (A,). What a transparent wall lets through for EEVEE's shadow rays, where its
    node group evaluates these few math nodes instead of the image (EEVEE evaluates a wall's nodes
    for every shadow-map sample). Averaged over the rows: a shadow has no thickness of its own
    (the shadow pass drops the thickness source, :mod:`addon.eevee.nodes`), and a film lets
    through nearly the same at any thickness, its colour averaging out."""
    target = np.clip(np.mean(np.asarray(transmittance, dtype=np.float64), axis=0), 0.0, 1.0)  # (A, 3)
    reflect = (1.0 - target) / (1.0 + target)
    cos = np.asarray(cos_o, dtype=np.float64).reshape(-1, 1)
    best = (np.inf, np.zeros(3), 5.0)
    for exponent in SHADOW_EXPONENTS:
        p = np.clip(1.0 - cos, 0.0, 1.0) ** exponent  # r − p = r0 (1 − p): r0 by least squares
        q = 1.0 - p
        r0 = np.clip(np.sum((reflect - p) * q, axis=0) / max(float(np.sum(q * q)), 1e-12), 0.0, 1.0)
        error = float(np.sum((shadow_model(r0, exponent, cos) - target) ** 2))
        if error < best[0]:
            best = (error, r0, float(exponent))
    return best[1], best[2]


def dominant_weight(roughness: float) -> float:
    """How much the film is read at the lobe light's angle θ' rather than the view angle, by
    roughness (:data:`DOMINANT_RAMP`); 0: no dominant-direction image is needed."""
    lo, hi = DOMINANT_RAMP
    return float(min(1.0, max(0.0, (float(roughness) - lo) / (hi - lo))))


@dataclass(frozen=True)
class LobeLights:
    """Light objects as the lobe light's moment sees them from one point (the film's centre):
    K samples, each ``direction`` (K, 3) unit, towards the light, world frame; ``luminance``
    (K,) the Rec.709 luminance of its irradiance E⊥ on a plane facing it (W/m², what
    :func:`precompute.shading.lights.light_samples` gives: a sun's E, a point or spot light's
    I/d² times its cone, an area light's cells); ``rho2`` (K,) the footprint widening its GGX
    lobe (:func:`precompute.shading.lights.footprint`)."""

    direction: np.ndarray
    luminance: np.ndarray
    rho2: np.ndarray

    @classmethod
    def empty(cls) -> LobeLights:
        """No lights."""
        return cls(np.zeros((0, 3)), np.zeros(0), np.zeros(0))

    @property
    def count(self) -> int:
        """K, the number of samples."""
        return int(self.luminance.shape[0])


@functools.lru_cache(maxsize=64)
def lobe_norm(alpha: float) -> float:
    """Z(α) = ∫ D(h)/4 (r·l)₊ dl with n = v = r: the prefilter's normalisation of its GGX lobe
    over reflected directions l (precompute.world.prefilter weighs each sample by n·l over their
    sum). With dl = 4 cos θh dωh it is the mean of (2 cos²θh − 1)₊ over GGX's half-vector CDF."""
    a2 = max(float(alpha), 1e-7) ** 2
    xi = (np.arange(_NORM_NODES) + 0.5) / _NORM_NODES
    cos2 = (1.0 - xi) / (1.0 + (a2 - 1.0) * xi)
    return float(np.mean(np.maximum(2.0 * cos2 - 1.0, 0.0)))


def _lobe(r: np.ndarray, light: np.ndarray, alpha: float) -> np.ndarray:
    """The prefilter's lobe D_α(h)(r·l)₊ / (4 Z(α)) at reflection directions ``r`` (N, 3) for one
    direction ``light`` (3,) (n = v = r, so n·h = l·h)."""
    h = r + light[None, :]
    h_norm = np.linalg.norm(h, axis=-1)
    cos_h = np.where(h_norm > 1e-12, (h @ light) / np.maximum(h_norm, 1e-12), 0.0)
    return brdf.D_ggx(cos_h, alpha) * np.maximum(r @ light, 0.0) / (4.0 * lobe_norm(alpha))


def light_moments(
    directions, roughness: float, lights: LobeLights, level_roughness=None
) -> tuple[np.ndarray, np.ndarray]:
    """(moment (N, 3), luminance (N,)) of ``lights`` in the prefilter's units at reflection
    ``directions`` (N, 3): Σ Y_k k(r, l_k) l_k and Σ Y_k k(r, l_k), k the prefilter's lobe
    D_α'(h)(r·l)₊ / (4 Z(α')) (n = v = r, :func:`lobe_norm`) with each sample's α'² = α² + ρ²
    (a source's size widens the highlight as the overlay's lights do). α = roughness², or, given
    the prefilter's ``level_roughness``, the two levels' lobes blended as its lookup blends them
    (:func:`precompute.shading.split_sum.level_blend`), so a light weighs against the World as
    the same light painted into the panorama would. A sample of irradiance E⊥ is radiance
    integrated over its solid angle: it adds to the prefiltered luminance (∫ Y k dl) what a
    small patch of the panorama with that irradiance adds."""
    from ..shading.split_sum import level_blend

    r = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    if level_roughness is None:
        lobes = [(float(roughness) ** 2, 1.0)]
    else:
        levels = np.asarray(level_roughness, dtype=np.float64)
        lo, frac = level_blend(np.asarray(float(roughness)), levels)
        lo, frac = int(lo), float(frac)
        lobes = [(levels[lo] ** 2, 1.0 - frac), (levels[lo + 1] ** 2, frac)]
    moment, total = np.zeros(r.shape), np.zeros(r.shape[0])
    for l, y, rho2 in zip(lights.direction, lights.luminance, lights.rho2, strict=True):
        if not (np.isfinite(y) and y > 0.0):
            continue
        l = np.asarray(l, dtype=np.float64)
        k = sum(w * _lobe(r, l, math.sqrt(max(a, 1e-7) ** 2 + float(rho2))) for a, w in lobes if w > 0.0)
        total += float(y) * k
        moment += float(y) * k[:, None] * l[None, :]
    return moment, total


def dominant_directions(
    pre, roughness: float, size=DIRECTIONS_SIZE, lights: LobeLights | None = None
) -> np.ndarray:
    """The lobe light's mean direction c per reflection direction: (H, W, 4) float32 RGBA, rows
    bottom first (Blender's pixel order), an equirect grid in Blender's Environment Texture
    mapping (conventions.md), RGB = (ℓ c + 1)/2 (c unit, world frame: stored in [0, 1], as a
    texture read need not keep negative values), A = 1. ℓ = 0.5 + 0.5 s (:data:`SHARE_FLOOR`),
    s the light objects' share of the lobe's luminance: the group reads the film at θ' with
    the weight dominant + (1 − dominant) s (a light object's highlight is always read at its
    half vector; EEVEE shades it per light, with no prefilter's n = v = r).

    ``pre``: a :class:`precompute.world.prefilter.Prefiltered` with moments (its ``rotation`` and
    ``scale`` applied: the World as it is) or None; ``lights``: :class:`LobeLights` or None.
    c = the World's prefiltered luminance × direction moment at ``roughness`` in that direction
    (:func:`precompute.shading.split_sum.lookup`) plus the lights' (:func:`light_moments`),
    normalised; where it vanishes, the direction itself.
    """
    from ..shading.split_sum import lookup
    from ..world.hdri import equirect_directions
    from ..world.prefilter import LUMINANCE

    width, height = int(size[0]), int(size[1])
    directions = equirect_directions(height, width)
    flat = directions.reshape(-1, 3)
    moment = np.zeros(flat.shape)
    world_y = np.zeros(flat.shape[0])
    if pre is not None and pre.moments is not None:
        moment = lookup(pre, flat, float(roughness), moments=True)
        world_y = np.maximum(lookup(pre, flat, float(roughness)) @ np.asarray(LUMINANCE), 0.0)
    share = np.zeros(flat.shape[0])
    if lights is not None and lights.count:
        levels = None if pre is None else pre.roughness
        light_m, light_y = light_moments(flat, roughness, lights, level_roughness=levels)
        moment = moment + light_m
        both = world_y + light_y
        share = np.where(both > 0.0, light_y / np.where(both > 0.0, both, 1.0), 0.0)
    norm2 = np.sum(moment * moment, axis=-1, keepdims=True)
    found = np.where(norm2 > MOMENT_EPS, moment / np.sqrt(np.maximum(norm2, MOMENT_EPS)), flat)
    found = found * (SHARE_FLOOR + (1.0 - SHARE_FLOOR) * np.clip(share, 0.0, 1.0))[:, None]
    pixels = np.ones((height, width, 4), dtype=np.float32)
    pixels[..., :3] = 0.5 * (found.reshape(directions.shape)[::-1] + 1.0)
    return pixels


def decode_directions(pixels) -> tuple[np.ndarray, np.ndarray]:
    """(c (H, W, 3) unit, s (H, W)) of a :func:`dominant_directions` image, rows as stored."""
    v = 2.0 * np.asarray(pixels, dtype=np.float64)[..., :3] - 1.0
    length = np.linalg.norm(v, axis=-1)
    c = v / np.maximum(length, 1e-12)[..., None]
    return c, np.clip((length - SHARE_FLOOR) / (1.0 - SHARE_FLOOR), 0.0, 1.0)
