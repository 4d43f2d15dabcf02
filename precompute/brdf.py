"""Microfacet BRDF whose Fresnel term is the thin-film reflectance (as in Cycles).

All directions are unit vectors in the local shading frame (z = normal). Roughness follows
Blender: α = roughness². Spectral quantities keep the wavelength on the last axis.

    f(ωi, ωo, λ) = D(h) G₂(ωi, ωo) R(ωi·h, λ) / (4 cosθi cosθo)  +  f_diffuse

References
----------
- Walter, B., Marschner, S., Li, H. & Torrance, K. (2007). Microfacet models for refraction
  through rough surfaces. EGSR 2007, eq. (33) (GGX D).
- Heitz, E. (2014). Understanding the masking-shadowing function in microfacet-based BRDFs.
  JCGT 3(2), eq. (72) (Λ for GGX) and eq. (99) (height-correlated G₂).
- Blender Cycles, ``intern/cycles/kernel/closure/bsdf_microfacet.h``: the thin film enters as
  the Fresnel term evaluated at the microfacet normal; α = roughness².
"""

from __future__ import annotations

import functools

import numpy as np

from . import _checks, constants
from .bakes.progress import checkpoint
from .bakes.quadrature import unit_gauss_legendre
from .optics.fresnel import fresnel_dielectric


def alpha_from_roughness(roughness) -> np.ndarray:
    """Blender's perceptual roughness → GGX α = roughness², clamped to ``MIN_ALPHA``."""
    r = _checks.finite_array("roughness", roughness)
    _checks.in_range("roughness", r, 0.0, 1.0)
    return np.maximum(r * r, constants.MIN_ALPHA)


def D_ggx(n_dot_h, alpha) -> np.ndarray:
    """GGX / Trowbridge–Reitz normal distribution (Walter et al. 2007, eq. 33).

    D(h) = α² / (π (cos²θh (α² − 1) + 1)²), zero below the surface.
    """
    c = np.asarray(n_dot_h, dtype=float)
    a2 = np.asarray(alpha, dtype=float) ** 2
    t = c * c * (a2 - 1.0) + 1.0
    return np.where(c > 0.0, a2 / (np.pi * t * t), 0.0)


def lambda_ggx(cos_theta, alpha) -> np.ndarray:
    """Smith Λ for GGX (Heitz 2014, eq. 72): Λ = (−1 + √(1 + α² tan²θ)) / 2."""
    c = np.clip(np.asarray(cos_theta, dtype=float), constants.MIN_COS, 1.0)
    tan2 = (1.0 - c * c) / (c * c)
    return 0.5 * (np.sqrt(1.0 + np.asarray(alpha, dtype=float) ** 2 * tan2) - 1.0)


def G2_smith_height_correlated(cos_i, cos_o, alpha) -> np.ndarray:
    """Height-correlated masking-shadowing G₂ = 1 / (1 + Λ(ωi) + Λ(ωo)) (Heitz 2014, eq. 99)."""
    return 1.0 / (1.0 + lambda_ggx(cos_i, alpha) + lambda_ggx(cos_o, alpha))


def half_vector(wi, wo) -> np.ndarray:
    """Normalised ωi + ωo; for exactly opposite directions returns the normal (0, 0, 1)."""
    h = np.asarray(wi, dtype=float) + np.asarray(wo, dtype=float)
    norm = np.linalg.norm(h, axis=-1, keepdims=True)
    return np.where(norm > 0, h / np.where(norm > 0, norm, 1.0), np.array([0.0, 0.0, 1.0]))


def reflect(wo, h) -> np.ndarray:
    """Mirror ωo about h: ωi = 2 (ωo·h) h − ωo."""
    return 2.0 * np.sum(wo * h, axis=-1, keepdims=True) * h - wo


def specular_weight(wi, wo, alpha) -> tuple[np.ndarray, np.ndarray]:
    """The Fresnel-free part D G₂ / (4 cosθi cosθo) and the Fresnel cosine u = ωi·h.

    Returns ``(w, u)`` with shapes (…); w is 0 where either direction is below the surface.
    """
    wi = np.asarray(wi, dtype=float)
    wo = np.asarray(wo, dtype=float)
    cos_i, cos_o = wi[..., 2], wo[..., 2]
    h = half_vector(wi, wo)
    u = np.clip(np.sum(wi * h, axis=-1), 0.0, 1.0)
    above = (cos_i > 0.0) & (cos_o > 0.0)
    ci = np.maximum(cos_i, constants.MIN_COS)
    co = np.maximum(cos_o, constants.MIN_COS)
    w = D_ggx(h[..., 2], alpha) * G2_smith_height_correlated(ci, co, alpha) / (4.0 * ci * co)
    return np.where(above, w, 0.0), u


def diffuse_under_film(cos_i, cos_o, film_r_i, film_r_o, base_color) -> np.ndarray:
    """Lambertian base seen through the film: ρ/π · (1 − R(cosθi)) (1 − R(cosθo)).

    Light crosses the film twice; the product of the two macro-surface transmittances keeps the
    term reciprocal and below the energy the film lets through. An approximation (it ignores
    the microfacet transmission lobe and inter-reflection between base and film), documented as
    such; ``film_r_*`` broadcast over wavelengths, ``base_color`` is a spectral albedo in [0, 1].
    """
    above = (np.asarray(cos_i) > 0) & (np.asarray(cos_o) > 0)
    f = np.asarray(base_color) / np.pi * (1.0 - film_r_i) * (1.0 - film_r_o)
    return np.where(above[..., None], f, 0.0)


def film_brdf(wi, wo, roughness, film_reflectance, base_color=None) -> np.ndarray:
    """Spectral BRDF value, shape (…, W).

    Parameters
    ----------
    wi, wo : ndarray (…, 3)
        Incident and outgoing directions in the local frame (z = normal).
    roughness : float
        Blender roughness in [0, 1] (α = roughness²).
    film_reflectance : callable
        ``R(cos) -> (N, W)`` for a 1-D array of N cosines, e.g. a closure over
        :func:`precompute.optics.reflectance`.
    base_color : None or array (W,)
        Spectral albedo of an optional diffuse base under the film.
    """
    alpha = alpha_from_roughness(roughness)
    w, u = specular_weight(wi, wo, alpha)
    shape = w.shape
    f = w.reshape(-1, 1) * film_reflectance(u.reshape(-1))
    if base_color is not None:
        ci = np.clip(np.asarray(wi)[..., 2].reshape(-1), 0.0, 1.0)
        co = np.clip(np.asarray(wo)[..., 2].reshape(-1), 0.0, 1.0)
        f = f + diffuse_under_film(ci, co, film_reflectance(ci), film_reflectance(co), base_color)
    return f.reshape(*shape, -1)


def ggx_importance_grid(alpha: float, n_theta: int = 256, n_phi: int = 128):
    """Deterministic half-vectors and weights for integrals against the measure D(h) cosθh dωh.

    The GGX CDF in tan²θh is ξ = t/(α² + t), so tan²θh = α² ξ / (1 − ξ) (Walter et al. 2007,
    eq. 35). Integrands with a 1/cosθh factor (as in half-vector albedo integrals) behave like
    1/√(1 − ξ) at grazing half-vectors, so ξ = 1 − s² is substituted (dξ = 2s ds, smooth) and s
    takes Gauss–Legendre nodes; φ takes midpoints. Weights sum to 1.
    """
    s, ws = unit_gauss_legendre(n_theta)
    xi = 1.0 - s * s
    w_theta = 2.0 * s * ws
    phi = 2.0 * np.pi * (np.arange(n_phi) + 0.5) / n_phi
    tan2 = alpha * alpha * xi / np.maximum(1.0 - xi, 1e-300)
    cos_h = 1.0 / np.sqrt(1.0 + tan2)
    sin_h = np.sqrt(np.maximum(0.0, 1.0 - cos_h * cos_h))
    h = np.stack(
        np.broadcast_arrays(
            sin_h[:, None] * np.cos(phi)[None, :],
            sin_h[:, None] * np.sin(phi)[None, :],
            cos_h[:, None] + 0 * phi[None, :],
        ),
        axis=-1,
    )
    w = (w_theta[:, None] * np.full(n_phi, 1.0 / n_phi)[None, :]).reshape(-1)
    return h.reshape(-1, 3), w


def directional_albedo(
    cos_o, roughness, film_reflectance, n_theta: int = 256, n_phi: int = 128
) -> np.ndarray:
    """∫ f_spec(ωi, ωo) cosθi dωi over the hemisphere for each view cosine, shape (len(cos_o), W).

    Integrated in half-vector space: f cosθi dωi = D G₂ R(ωo·h) (ωo·h) / cosθo dωh, so with
    samples distributed as D cosθh the estimator is G₂ R (ωo·h) / (cosθo cosθh).
    """
    alpha = float(alpha_from_roughness(roughness))
    cos_o = np.clip(np.atleast_1d(np.asarray(cos_o, dtype=float)), constants.MIN_COS, 1.0)
    h, wgt = ggx_importance_grid(alpha, n_theta, n_phi)
    checkpoint()
    out = []
    for co in cos_o:
        wo = np.array([np.sqrt(max(0.0, 1.0 - co * co)), 0.0, co])
        u = h @ wo
        wi = reflect(wo[None, :], h)
        ok = (u > 0) & (wi[:, 2] > 0)
        g2 = G2_smith_height_correlated(np.maximum(wi[:, 2], constants.MIN_COS), co, alpha)
        scalar = np.where(ok, g2 * u / (co * h[:, 2]), 0.0) * wgt
        r = film_reflectance(np.clip(u, 0.0, 1.0))
        out.append(scalar @ r)
        checkpoint()  # one view cosine (a bake's progress and cancellation point)
    return np.array(out)


# ----------------------------------------------------------------------------------------------
# Multiple scattering: energy compensation (Kulla & Conty 2017, as Cycles applies it)
# ----------------------------------------------------------------------------------------------
def _ones(cos):
    return np.ones((np.size(cos), 1))


#: The GGX albedo's rule: Gauss–Legendre elevations × azimuth midpoints (:func:`ggx_importance_grid`).
E_THETA = 256
E_PHI = 128
#: View cosines integrated together between two progress checkpoints (≈ 2 M nodes).
E_BATCH = 16


def ggx_albedo(cos_o, alpha: float) -> np.ndarray:
    """Single-scattering GGX albedo E(μo) with F ≡ 1, shape (len(cos_o),): :func:`directional_albedo`
    with R ≡ 1 on its E_THETA × E_PHI rule, evaluated on the rule's grid.

    The same nodes, weights and estimator G₂ (ωo·h) / (cosθo cosθh), but as (views, θh, φh)
    arrays built from 1-D factors: u = sinθh cosφh sinθo + cosθh cosθo, cosθi = 2u cosθh − cosθo,
    and only φh ∈ (0, π) with doubled weights — ωo lies in the xz-plane, so the integrand is even
    in φh and the midpoints come in mirror pairs. Equal to the general path to rounding
    (tests/optics/test_brdf.py), ≈ 15× less work.
    """
    co = np.clip(np.atleast_1d(np.asarray(cos_o, dtype=float)), constants.MIN_COS, 1.0)
    s, ws = unit_gauss_legendre(E_THETA)
    xi = 1.0 - s * s
    tan2 = alpha * alpha * xi / np.maximum(1.0 - xi, 1e-300)
    cos_h = 1.0 / np.sqrt(1.0 + tan2)
    sin_h = np.sqrt(np.maximum(0.0, 1.0 - cos_h * cos_h))
    cos_phi = np.cos(2.0 * np.pi * (np.arange(E_PHI // 2) + 0.5) / E_PHI)
    weight = (2.0 * s * ws)[:, None] * np.full(E_PHI // 2, 2.0 / E_PHI)  # (θh, φh), pairs folded
    sin_cos = (sin_h[:, None] * cos_phi)[None]  # sinθh cosφh
    cos_h3 = cos_h[None, :, None]
    out = np.empty(co.size)
    for lo in range(0, co.size, E_BATCH):
        c = co[lo : lo + E_BATCH, None, None]
        u = sin_cos * np.sqrt(np.maximum(0.0, 1.0 - c * c)) + cos_h3 * c
        cos_i = 2.0 * u * cos_h3 - c
        g2 = G2_smith_height_correlated(np.maximum(cos_i, constants.MIN_COS), c, alpha)
        f = np.where((u > 0.0) & (cos_i > 0.0), g2 * u / (c * cos_h3), 0.0)
        out[lo : lo + E_BATCH] = np.einsum("vtp,tp->v", f, weight)
        checkpoint()  # a bake's progress and cancellation point
    return out


@functools.lru_cache(maxsize=64)
def ggx_E(roughness: float, cos_key: tuple) -> np.ndarray:
    """Single-scattering GGX albedo E(μo) with F ≡ 1 at the given view cosines (cached)."""
    return ggx_albedo(np.array(cos_key), float(alpha_from_roughness(roughness)))


@functools.lru_cache(maxsize=64)
def ggx_E_avg(roughness: float) -> float:
    """Hemispherical average E_avg = 2 ∫₀¹ E(μ) μ dμ (Kulla & Conty 2017, eq. 4)."""
    mu, w = unit_gauss_legendre(32)
    return float(2.0 * np.sum(ggx_E(roughness, tuple(mu)) * mu * w))


def fresnel_average_dielectric(eta: float) -> float:
    """Hemispherical average of the unpolarised dielectric Fresnel, F_avg = 2 ∫₀¹ F(μ) μ dμ."""
    mu, w = unit_gauss_legendre(64)
    return float(2.0 * np.sum(fresnel_dielectric(mu, eta) * mu * w))


def multiscatter_scale(cos_o, roughness: float, f_avg) -> np.ndarray:
    """Factor 1 + F_ms (1 − E)/E on the single-scattering lobe, shape (len(cos_o), …f_avg).

    F_ms = F_avg E_avg / (1 − F_avg (1 − E_avg)) is Kulla & Conty's (2017, appendix) multiple-
    bounce Fresnel with one F_avg cancelled, because the single-scattering lobe already carries
    one Fresnel bounce — the form Cycles' ``microfacet_ggx_preserve_energy`` uses.

    References
    ----------
    Kulla, C. & Conty, A. (2017). Revisiting Physically Based Shading at Imageworks. SIGGRAPH
    course "Physically Based Shading in Theory and Practice".
    """
    cos_o = np.clip(np.atleast_1d(np.asarray(cos_o, dtype=float)), constants.MIN_COS, 1.0)
    e = ggx_E(float(roughness), tuple(cos_o.tolist()))
    e_avg = ggx_E_avg(float(roughness))
    f = np.asarray(f_avg, dtype=float)
    f_ms = f * e_avg / (1.0 - f * (1.0 - e_avg))
    missing = (1.0 - e) / np.maximum(e, 1e-6)
    return 1.0 + np.multiply.outer(missing, f_ms)
