"""GGX microfacet BRDF with the film as Fresnel term: normalisation, furnace, reciprocity."""

import numpy as np
import pytest
from scipy import integrate

from precompute import brdf
from precompute.optics import reflectance

WL = np.linspace(380, 780, 9)


def soap_film(cos):
    return reflectance([1.0, 1.33, 1.0], [380.0], WL, cos)


def ones(cos):
    return np.ones((np.size(cos), 1))


@pytest.mark.parametrize("alpha", [1e-3, 0.01, 0.1, 0.5, 1.0])
def test_ggx_distribution_projects_to_unit_area(alpha):
    # ∫ D(h) cosθh dωh = 1 (Walter et al. 2007, eq. 4), by adaptive quadrature in θh.
    # For tiny α the integrand is a spike at θh = 0: integrate in t = tanθh / α instead.
    def integrand(t):
        theta = np.arctan(alpha * t)
        jac = alpha / (1.0 + (alpha * t) ** 2)
        return brdf.D_ggx(np.cos(theta), alpha) * np.cos(theta) * np.sin(theta) * 2 * np.pi * jac

    total, err = integrate.quad(integrand, 0, np.inf, limit=400)
    assert total == pytest.approx(1.0, abs=1e-7)


@pytest.mark.parametrize("alpha", [0.05, 0.3, 1.0])
@pytest.mark.parametrize("cos_o", [1.0, 0.5, 0.05])
def test_weak_white_furnace_smith_masking(alpha, cos_o):
    # Heitz 2014, eq. (2): ∫ G1(ωo) ⟨ωo·h⟩ D(h) dωh = cosθo, with G1 = 1/(1 + Λ(ωo)).
    h, w = brdf.ggx_importance_grid(alpha, 256, 128)
    wo = np.array([np.sqrt(1 - cos_o**2), 0.0, cos_o])
    g1 = 1.0 / (1.0 + brdf.lambda_ggx(cos_o, alpha))
    projected = np.sum(w * np.maximum(0.0, h @ wo) / h[:, 2]) * g1
    # Gauss–Legendre in s (ξ = 1 − s²) converges spectrally: measured ≤ 1.4e-6 relative at
    # 256×128 nodes for these lobes, so 1e-5 leaves margin yet catches any error in Λ or D.
    assert projected == pytest.approx(cos_o, rel=1e-5)


@pytest.mark.parametrize("roughness", [0.05, 0.1, 0.3, 0.6, 1.0])
def test_white_furnace_albedo_at_most_one(roughness):
    cos_o = np.array([1.0, 0.7, 0.3, 0.05])
    perfect = brdf.directional_albedo(cos_o, roughness, ones)[:, 0]
    # Single-scattering GGX loses energy (no multiple bounces), never gains: ≤ 1 up to the
    # quadrature's ~1e-5 error (see the weak furnace test).
    assert np.all(perfect <= 1.0 + 1e-5)
    if roughness <= 0.3:
        assert np.all(perfect[:3] >= 0.93)  # nearly lossless when the lobe is narrow
    film = brdf.directional_albedo(cos_o, roughness, soap_film)
    assert np.all(film >= 0.0) and np.all(film <= perfect[:, None] + 1e-12)


def test_importance_quadrature_matches_brute_force_hemisphere():
    # Independent check of directional_albedo: plain Gauss–Legendre over (cosθi, φi).
    roughness, cos_o = 0.7, 0.6
    mu, wmu = np.polynomial.legendre.leggauss(200)
    mu, wmu = 0.5 * (mu + 1), 0.5 * wmu
    phi = 2 * np.pi * (np.arange(400) + 0.5) / 400
    s = np.sqrt(1 - mu**2)
    wi = np.stack(np.broadcast_arrays(s[:, None] * np.cos(phi), s[:, None] * np.sin(phi), mu[:, None]), -1)
    wo = np.broadcast_to([np.sqrt(1 - cos_o**2), 0, cos_o], wi.shape)
    f = brdf.film_brdf(wi, wo, roughness, soap_film)
    brute = np.einsum("ijw,i->w", f * mu[:, None, None], wmu) * (2 * np.pi / 400)
    fast = brdf.directional_albedo([cos_o], roughness, soap_film, 512, 256)[0]
    # The brute-force side is the less accurate one (400×200 nodes on a lobe of α = 0.49);
    # 1e-4 relative to the peak bounds its error, measured 2e-6.
    assert np.max(np.abs(fast - brute)) <= 1e-4 * np.max(brute)


def test_reciprocity_with_film_and_diffuse_base():
    rng = np.random.default_rng(3)
    v = rng.normal(size=(2, 500, 3))
    v[..., 2] = np.abs(v[..., 2])
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    base = np.linspace(0.2, 0.8, WL.size)
    f_io = brdf.film_brdf(v[0], v[1], 0.4, soap_film, base)
    f_oi = brdf.film_brdf(v[1], v[0], 0.4, soap_film, base)
    assert np.max(np.abs(f_io - f_oi)) <= 1e-12 * np.max(f_io)


def test_smooth_limit_albedo_is_the_film_reflectance():
    cos_o = np.array([0.9, 0.5])
    albedo = brdf.directional_albedo(cos_o, 0.02, soap_film, 512, 64)
    # Roughness 0.02 → α = 4e-4: the lobe spans < 0.1°, so the albedo equals R(cosθo) times
    # the nearly-1 masking term; 1 % covers G₂ < 1 and the lobe's spread of R.
    assert np.allclose(albedo, soap_film(cos_o), rtol=1e-2)


def test_bad_roughness_raises():
    """A roughness outside [0, 1] or NaN is refused with the parameter named, never turned into a NaN BRDF."""
    for bad in (-0.1, 1.5, float("nan")):
        with pytest.raises(ValueError, match="roughness"):
            brdf.alpha_from_roughness(bad)


def test_ggx_albedo_closed_form_at_alpha_one():
    # α = 1: D = 1/π, and the normal-view single-scattering albedo is exactly 1 − ln 2.
    # ggx_E's 256×128 half-vector rule is off by 8.2e-6 here (the horizon cut converges slowest).
    assert brdf.ggx_E(1.0, (1.0,))[0] == pytest.approx(1.0 - np.log(2.0), abs=2e-5)


def test_multiscatter_scale_restores_the_white_furnace():
    # With F ≡ 1 the compensated albedo E·(1 + (1 − E)/E) is exactly 1 (Kulla & Conty 2017).
    cos = np.array([1.0, 0.5, 0.1])
    for r in (0.3, 0.7, 1.0):
        e = brdf.ggx_E(r, tuple(cos))
        assert np.allclose(e * brdf.multiscatter_scale(cos, r, 1.0), 1.0, atol=1e-12)
    assert brdf.fresnel_average_dielectric(1.0) == pytest.approx(0.0, abs=1e-15)
    assert 0.09 < brdf.fresnel_average_dielectric(1.5) < 0.095  # 0.0918 (Kulla & Conty fit: 0.092)


@pytest.mark.parametrize("roughness", [0.0, 0.05, 0.3, 0.6, 1.0])
def test_ggx_albedo_on_its_grid_equals_the_general_directional_albedo(roughness):
    """ggx_E's fast path (1-D factors, folded azimuth pairs) is the general integral with R ≡ 1."""
    cos = np.concatenate([[1e-4, 1e-3, 0.03], np.linspace(0.1, 1.0, 19)])
    general = brdf.directional_albedo(cos, roughness, lambda u: np.ones((np.size(u), 1)), 256, 128)[:, 0]
    np.testing.assert_allclose(brdf.ggx_E(roughness, tuple(cos)), general, rtol=0, atol=1e-13)
