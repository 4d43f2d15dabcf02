"""Tests for precompute.sh: basis, projection, rotation, windowing, irradiance.

Tolerances: quantities that are exact in exact arithmetic (orthonormality under an exact
quadrature, rotation identities, closed forms) are checked at 1e-10…1e-12: float64 rounding
in sums of ~(l_max+1)² ≤ 81 terms of size ≤ ~3 accumulates to ~1e-14, so these leave a
100× margin while still catching any wrong sign, index or normalisation (errors ≥ 1e-3).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.special import sph_harm_y

from precompute.sh import harmonics, projection, rotations, windows
from precompute.sh import zonal as sh_zonal
from precompute.world import hdri

L_MAX = 8
RNG_SEED = 20240601


# ----------------------------------------------------------------------------------------------
# Helpers
# ----------------------------------------------------------------------------------------------


def gauss_sphere(degree: int) -> tuple[np.ndarray, np.ndarray]:
    """Product rule exact for polynomials of total degree ≤ ``degree`` on the sphere.

    Gauss–Legendre in cos θ with n nodes is exact for degree ≤ 2n − 1; the uniform φ rule with
    M points is exact for trigonometric degree ≤ M − 1.
    """
    n_z = degree // 2 + 1
    n_phi = degree + 1
    z, wz = np.polynomial.legendre.leggauss(n_z)
    phi = 2.0 * np.pi * (np.arange(n_phi) + 0.5) / n_phi
    zz, pp = np.meshgrid(z, phi, indexing="ij")
    rho = np.sqrt(1.0 - zz * zz)
    dirs = np.stack([rho * np.cos(pp), rho * np.sin(pp), zz], axis=-1).reshape(-1, 3)
    weights = (wz[:, None] * np.full(n_phi, 2.0 * np.pi / n_phi)[None, :]).reshape(-1)
    return dirs, weights


def axis_angle(axis, angle: float) -> np.ndarray:
    """Rodrigues rotation matrix (right-handed, column vectors)."""
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    k = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    return np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k)


def quaternion_matrix(q) -> np.ndarray:
    w, x, y, z = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def random_directions(rng, count: int) -> np.ndarray:
    d = rng.normal(size=(count, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def rotated_projection_error(l_max: int, rot: np.ndarray, seed: int = 0) -> float:
    """max |project(f∘R⁻¹) − rotation(R) project(f)| for a random band-limited f.

    f = Σ c_i Y_i, so (f∘R⁻¹)(d) = basis(R⁻¹ d)·c; the product with Y_j has degree ≤ 2 l_max,
    which :func:`gauss_sphere` integrates exactly.
    """
    rng = np.random.default_rng(seed)
    c = rng.normal(size=(l_max + 1) ** 2)
    dirs, weights = gauss_sphere(2 * l_max)
    # Row vectors: (R⁻¹ d)ᵀ = dᵀ R for orthogonal R.
    f_turned = harmonics.basis(l_max, dirs @ rot) @ c
    projected = projection.project(l_max, dirs, f_turned, weights)
    return float(np.max(np.abs(projected - rotations.rotation(l_max, rot) @ c)))


def ir_general_path(l_max: int, rot: np.ndarray) -> np.ndarray:
    """The Ivanic–Ruedenberg recurrence forced, bypassing the z fast path."""
    r1 = rotations._band1_ivanic_ruedenberg(rot)
    bands = [np.ones((1, 1)), r1]
    for l in range(2, l_max + 1):
        bands.append(rotations._ivanic_ruedenberg_band(l, r1, bands[-1]))
    return rotations._block_diagonal(bands[: l_max + 1])


def real_sh_from_scipy(l: int, m: int, theta, phi) -> np.ndarray:
    """Our real, no-Condon–Shortley basis from scipy's complex Y_l^m (which includes (−1)^m).

    Y_l^{|m|} (scipy) = (−1)^|m| K P_l^|m| e^{i|m|φ} with our P_l^m, so
    m > 0: √2 (−1)^m Re Y_l^m;  m < 0: √2 (−1)^|m| Im Y_l^|m|;  m = 0: Re Y_l^0.
    """
    y = sph_harm_y(l, abs(m), theta, phi) * (-1.0) ** abs(m)
    if m == 0:
        return y.real
    return math.sqrt(2.0) * (y.real if m > 0 else y.imag)


# ----------------------------------------------------------------------------------------------
# Basis
# ----------------------------------------------------------------------------------------------


@pytest.mark.parametrize("l_max", [0, 1, 2, 8, 16])
def test_orthonormality_by_exact_quadrature(l_max):
    """The real SH basis is orthonormal under an exact quadrature (1e-10): every projection and product
    relies on it."""
    dirs, weights = gauss_sphere(2 * l_max)
    y = harmonics.basis(l_max, dirs)
    gram = y.T @ (weights[:, None] * y)
    # Exact in exact arithmetic; 1e-10 covers float64 rounding over ≤ 289×289 sums (measured
    # ~3e-15 at l = 8, ~1e-14 at l = 16).
    assert np.max(np.abs(gram - np.eye(gram.shape[0]))) <= 1e-10


def test_matches_scipy_without_condon_shortley():
    rng = np.random.default_rng(RNG_SEED)
    poles_and_axes = np.array(
        [[0, 0, 1], [0, 0, -1], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [1, 1, 1], [1e-9, 0, 1]]
    )
    dirs = np.vstack(
        [random_directions(rng, 200), poles_and_axes / np.linalg.norm(poles_and_axes, axis=1)[:, None]]
    )
    # atan2 form: arccos(z) loses θ ≈ 1e-9 entirely (z rounds to 1) near the poles.
    theta = np.arctan2(np.hypot(dirs[:, 0], dirs[:, 1]), dirs[:, 2])
    phi = np.mod(np.arctan2(dirs[:, 1], dirs[:, 0]), 2.0 * np.pi)  # scipy wants φ ∈ [0, 2π]
    ours = harmonics.basis(L_MAX, dirs)
    worst = 0.0
    for l in range(L_MAX + 1):
        for m in range(-l, l + 1):
            ref = real_sh_from_scipy(l, m, theta, phi)
            worst = max(worst, float(np.max(np.abs(ours[:, l * (l + 1) + m] - ref))))
    # Two independent float64 evaluations of values ≤ ~1.3: agreement to 1e-12 (measured ~3e-15).
    assert worst <= 1e-12


def test_band_closed_forms():
    """Bands 0–2 equal their closed forms: our
    coefficients mean what the papers' formulas mean."""
    rng = np.random.default_rng(1)
    d = random_directions(rng, 50)
    x, y, z = d.T
    b = harmonics.basis(2, d)
    c0 = 0.5 / math.sqrt(math.pi)
    c1 = math.sqrt(3.0 / (4.0 * math.pi))
    c2 = 0.5 * math.sqrt(15.0 / math.pi)
    expected = np.stack(
        [
            np.full_like(x, c0),
            c1 * y,
            c1 * z,
            c1 * x,
            c2 * x * y,
            c2 * y * z,
            0.25 * math.sqrt(5.0 / math.pi) * (3 * z * z - 1),
            c2 * x * z,
            0.5 * c2 * (x * x - y * y),
        ],
        axis=-1,
    )
    assert np.max(np.abs(b - expected)) <= 1e-14 * 10  # closed forms, a few ulps apart


def test_basis_normalises_and_broadcasts():
    """The basis normalises unnormalised directions and broadcasts over leading axes, so callers need no
    reshaping."""
    rng = np.random.default_rng(2)
    d = random_directions(rng, 12).reshape(3, 4, 3)
    assert harmonics.basis(3, 5.0 * d).shape == (3, 4, 16)
    assert np.allclose(harmonics.basis(3, 5.0 * d), harmonics.basis(3, d), atol=1e-14, rtol=0)


def test_poles_are_exact():
    """At +z only m = 0 survives with √((2l+1)/4π): the pole, where an atan2 could misbehave, is exact."""
    up = harmonics.basis(L_MAX, [0.0, 0.0, 1.0])
    for l in range(L_MAX + 1):
        # At +z only m = 0 survives, with value √((2l+1)/4π) exactly (P_l(1) = 1).
        band = up[l * l : (l + 1) ** 2]
        assert band[l] == pytest.approx(math.sqrt((2 * l + 1) / (4 * math.pi)), rel=1e-14)
        assert np.all(np.delete(band, l) == 0.0)


def test_basis_from_angles_matches_basis():
    rng = np.random.default_rng(3)
    cos_t = rng.uniform(-1, 1, 40)
    phi = rng.uniform(-np.pi, 3 * np.pi, 40)
    s = np.sqrt(1 - cos_t**2)
    d = np.stack([s * np.cos(phi), s * np.sin(phi), cos_t], axis=-1)
    assert np.max(np.abs(harmonics.basis_from_angles(L_MAX, cos_t, phi) - harmonics.basis(L_MAX, d))) <= 1e-13


def test_project_and_evaluate_round_trip_shapes():
    rng = np.random.default_rng(4)
    dirs, weights = gauss_sphere(2 * 4)
    c = rng.normal(size=(25, 3))
    vals = harmonics.evaluate(c, dirs)
    assert vals.shape == (dirs.shape[0], 3)
    assert np.max(np.abs(projection.project(4, dirs, vals, weights) - c)) <= 1e-12
    one = projection.project(4, dirs, vals[:, 0], weights)
    assert one.shape == (25,)
    assert np.max(np.abs(one - c[:, 0])) <= 1e-12


# ----------------------------------------------------------------------------------------------
# Rotation
# ----------------------------------------------------------------------------------------------

NAMED_ROTATIONS = {
    "identity": np.eye(3),
    "x180": axis_angle([1, 0, 0], np.pi),
    "y180": axis_angle([0, 1, 0], np.pi),
    "z180": axis_angle([0, 0, 1], np.pi),
    "diag180": axis_angle([1, 1, 1], np.pi),
    "y+90": axis_angle([0, 1, 0], np.pi / 2),
    "y-90": axis_angle([0, 1, 0], -np.pi / 2),
    "gimbal_y90_then_z": axis_angle([0, 0, 1], 0.7) @ axis_angle([0, 1, 0], np.pi / 2),
    "gimbal_z_y-90_x": (
        axis_angle([0, 0, 1], -1.1) @ axis_angle([0, 1, 0], -np.pi / 2) @ axis_angle([1, 0, 0], 0.4)
    ),
    "x90": axis_angle([1, 0, 0], np.pi / 2),
    "z37": axis_angle([0, 0, 1], math.radians(37)),
    "generic": axis_angle([0.3, -0.5, 0.8], 2.1),
}


@pytest.mark.parametrize("name", sorted(NAMED_ROTATIONS))
def test_rotation_identity_named(name):
    """Rotating coefficients equals projecting the rotated function (1e-10) for named rotations, gimbal-lock
    cases included."""
    # Exact quadrature of band-limited integrands: only rounding remains (measured ~1e-14).
    assert rotated_projection_error(L_MAX, NAMED_ROTATIONS[name]) <= 1e-10


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4).filter(lambda q: np.linalg.norm(q) > 0.1))
def test_rotation_identity_random(q):
    """Rotating coefficients equals projecting the rotated function (1e-10) for random rotations."""
    assert rotated_projection_error(L_MAX, quaternion_matrix(q), seed=7) <= 1e-10


@pytest.mark.parametrize("name", sorted(NAMED_ROTATIONS))
def test_rotation_matrices_orthogonal(name):
    """SH rotation matrices are orthogonal (1e-12): rotation keeps the lighting's energy."""
    m = rotations.rotation(L_MAX, NAMED_ROTATIONS[name])
    assert np.max(np.abs(m @ m.T - np.eye(m.shape[0]))) <= 1e-12


def test_rotation_orthogonal_at_high_band():
    # The recurrence accumulates rounding band by band; at l = 16 it is still ~1e-14.
    m = rotations.rotation(16, NAMED_ROTATIONS["generic"])
    assert np.max(np.abs(m @ m.T - np.eye(m.shape[0]))) <= 1e-10
    assert rotated_projection_error(12, NAMED_ROTATIONS["gimbal_z_y-90_x"]) <= 1e-10


def test_rotation_composition():
    """SH rotation is a homomorphism: R(r1 r2) = R(r1) R(r2) and R(rᵀ) = R(r)ᵀ (1e-12)."""
    r1 = NAMED_ROTATIONS["generic"]
    r2 = NAMED_ROTATIONS["gimbal_z_y-90_x"]
    lhs = rotations.rotation(L_MAX, r1 @ r2)
    rhs = rotations.rotation(L_MAX, r1) @ rotations.rotation(L_MAX, r2)
    assert np.max(np.abs(lhs - rhs)) <= 1e-12
    inverse = rotations.rotation(L_MAX, r1.T)
    assert np.max(np.abs(inverse - rotations.rotation(L_MAX, r1).T)) <= 1e-12


def test_rotation_is_block_diagonal():
    """SH rotation never mixes bands: the matrix is block diagonal, one block per band."""
    m = rotations.rotation(L_MAX, NAMED_ROTATIONS["generic"])
    bands = rotations.rotation_bands(L_MAX, NAMED_ROTATIONS["generic"])
    for l, block in enumerate(bands):
        assert block.shape == (2 * l + 1, 2 * l + 1)
        sl = slice(l * l, (l + 1) ** 2)
        assert np.array_equal(m[sl, sl], block)
        off = m[sl].copy()
        off[:, sl] = 0.0
        assert np.all(off == 0.0)


@pytest.mark.parametrize("angle", [0.0, 0.3, -1.2, np.pi, 2.5 * np.pi])
def test_z_fast_path_equals_general_path(angle):
    rz = axis_angle([0, 0, 1], angle)
    fast = rotations.rotation_z(L_MAX, angle)
    assert np.max(np.abs(fast - ir_general_path(L_MAX, rz))) <= 1e-12
    # rotation() dispatches to the fast path for pure z turns and gives the same matrix.
    assert np.max(np.abs(rotations.rotation(L_MAX, rz) - fast)) <= 1e-14
    assert rotated_projection_error(L_MAX, rz) <= 1e-10


def test_rotate_applies_band_by_band():
    rng = np.random.default_rng(5)
    c = rng.normal(size=((L_MAX + 1) ** 2, 3))
    r = NAMED_ROTATIONS["generic"]
    assert np.max(np.abs(rotations.rotate(c, r) - rotations.rotation(L_MAX, r) @ c)) <= 1e-12
    assert np.max(np.abs(rotations.rotate(c[:, 0], r) - rotations.rotation(L_MAX, r) @ c[:, 0])) <= 1e-12


def test_rotating_a_lobe_moves_it():
    # A zonal lobe about +z turned by R points along R e_z (checks the f∘R⁻¹ direction).
    zonal = np.array([1.0, 0.8, 0.5, 0.2])
    r = NAMED_ROTATIONS["generic"]
    turned = rotations.rotate(sh_zonal.zonal_rotation(zonal, [0, 0, 1]), r)
    assert np.max(np.abs(turned - sh_zonal.zonal_rotation(zonal, r @ [0.0, 0.0, 1.0]))) <= 1e-12


# ----------------------------------------------------------------------------------------------
# Irradiance and zonal convolution
# ----------------------------------------------------------------------------------------------


def test_constant_environment_gives_pi():
    """A constant unit environment gives irradiance π in every direction (1e-12), the closed form."""
    c = np.zeros((L_MAX + 1) ** 2)
    c[0] = math.sqrt(4.0 * math.pi)  # L ≡ 1: L_00 = ∫ Y_00 dω = 4π/√(4π)
    rng = np.random.default_rng(6)
    e = harmonics.evaluate(sh_zonal.irradiance_coefficients(c), random_directions(rng, 100))
    assert np.max(np.abs(e - math.pi)) <= 1e-12


def test_clamped_cosine_closed_forms_and_quadrature():
    a = sh_zonal.clamped_cosine_zh(10)
    assert a[:5] == pytest.approx([math.pi, 2 * math.pi / 3, math.pi / 4, 0.0, -math.pi / 24], abs=1e-15)
    assert np.all(a[3::2] == 0.0)
    # Â_l = √(4π/(2l+1)) · 2π ∫_0^1 z Y_l^0(z) dz; the integrand is a polynomial on [0, 1], so
    # 8 Gauss–Legendre nodes there are exact (degree ≤ 11).
    x, w = np.polynomial.legendre.leggauss(8)
    z, wz = 0.5 * (x + 1.0), 0.5 * w
    y0 = harmonics.basis_from_angles(10, z, 0.0)[:, [l * (l + 1) for l in range(11)]]
    zh = 2 * np.pi * (wz * z) @ y0
    numeric = np.sqrt(4 * np.pi / (2 * np.arange(11) + 1)) * zh
    assert np.max(np.abs(numeric - a)) <= 1e-13


def test_convolve_zonal_matches_irradiance():
    """Convolving with the clamped-cosine zonal kernel equals the irradiance coefficients (1e-13): two
    routes, one result."""
    rng = np.random.default_rng(8)
    c = rng.normal(size=((L_MAX + 1) ** 2, 2))
    l = np.arange(L_MAX + 1)
    zonal = sh_zonal.clamped_cosine_zh(L_MAX) / np.sqrt(4 * np.pi / (2 * l + 1))
    assert np.max(np.abs(sh_zonal.convolve_zonal(c, zonal) - sh_zonal.irradiance_coefficients(c))) <= 1e-13


def test_irradiance_of_point_light_converges():
    # A unit delta light along d: L_lm = Y_lm(d), so E(n) ≈ max(0, n·d); the band-limited
    # error at l = 8 is ≤ 3.4 % of the peak (max of the truncated kernel, computed in
    # benchmarks.sh_projection.point_light_truncation_error), so 0.05 is a safe bound.
    d = np.array([0.2, -0.4, 0.9])
    d /= np.linalg.norm(d)
    rng = np.random.default_rng(9)
    n = random_directions(rng, 300)
    e = harmonics.evaluate(sh_zonal.irradiance_coefficients(harmonics.basis(L_MAX, d)), n)
    assert np.max(np.abs(e - np.maximum(0.0, n @ d))) <= 0.05


# ----------------------------------------------------------------------------------------------
# Equirect projection
# ----------------------------------------------------------------------------------------------


def synthesised_equirect(c: np.ndarray, height: int) -> np.ndarray:
    return harmonics.evaluate(c, hdri.equirect_directions(height, 2 * height))


def test_project_equirect_recovers_coefficients():
    """Projecting an equirect image synthesised from known coefficients recovers them, with second-order
    convergence in the resolution."""
    rng = np.random.default_rng(10)
    c = rng.normal(size=((L_MAX + 1) ** 2, 3))
    err128 = np.max(np.abs(projection.project_equirect(synthesised_equirect(c, 128), L_MAX) - c))
    err256 = np.max(np.abs(projection.project_equirect(synthesised_equirect(c, 256), L_MAX) - c))
    # In φ the uniform column rule is exact for trigonometric degree ≤ 2 l_max = 16 < W. In θ the
    # rule (centre value × exact row solid angle) is a midpoint-type rule with error
    # ≈ Δθ²/24 · |∂²(f Y sin θ)/∂θ²| per unit length; products of degree ≤ 16 give
    # |∂²| ≲ 16² · |f Y|, i.e. ≲ (π/H)² · 256/24 · |f|_max · |Y|_max · 4π ≈ 1e-2 at H = 128 for
    # |f| ~ 10, |Y| ~ 1.3 (measured 9.6e-4). Gate at 2e-3 and demand second-order convergence.
    assert err128 <= 2e-3
    assert err256 <= 5e-4
    assert 3.5 <= err128 / err256 <= 4.5


def test_project_equirect_equals_generic_quadrature():
    # The separable path must equal project() with pixel-centre directions and exact pixel
    # solid angles (same sum, different order: rounding only).
    rng = np.random.default_rng(11)
    img = rng.lognormal(size=(32, 64, 3))
    dirs = hdri.equirect_directions(32, 64).reshape(-1, 3)
    weights = hdri.equirect_solid_angles(32, 64).reshape(-1)
    generic = projection.project(L_MAX, dirs, img.reshape(-1, 3), weights)
    assert np.max(np.abs(projection.project_equirect(img, L_MAX) - generic)) <= 1e-12
    assert projection.project_equirect(img[..., 0], L_MAX).shape == ((L_MAX + 1) ** 2,)


def test_pixel_solid_angles_sum_to_four_pi():
    assert hdri.equirect_solid_angles(37, 64).sum() == pytest.approx(4 * np.pi, rel=1e-13)


def test_project_equirect_rejects_and_counts_nonfinite():
    rng = np.random.default_rng(12)
    img = rng.lognormal(size=(16, 32, 3))
    bad = img.copy()
    bad[3, 4, 1] = np.nan
    bad[5, 6, 0] = np.inf
    bad[7, 8, :] = -np.inf
    coeffs, info = projection.project_equirect(bad, 4, return_info=True)
    assert info["rejected_pixels"] == 3
    assert np.all(np.isfinite(coeffs))
    zeroed = img.copy()
    zeroed[3, 4] = zeroed[5, 6] = zeroed[7, 8] = 0.0
    assert np.max(np.abs(coeffs - projection.project_equirect(zeroed, 4))) <= 1e-13
    _, clean = projection.project_equirect(img, 4, return_info=True)
    assert clean["rejected_pixels"] == 0


def _spot_image(rows, col: int, height: int = 64, width: int = 128) -> np.ndarray:
    img = np.zeros((height, width))
    img[rows, col] = 1.0
    return img


def test_equirect_convention_centre_column_is_plus_x():
    c = projection.project_equirect(_spot_image([31, 32], 64), 1)  # u = 0.5 at the horizon
    assert c[3] > 0 and abs(c[3]) > 10 * max(abs(c[1]), abs(c[2]))


def test_equirect_convention_quarter_column_is_plus_y():
    c = projection.project_equirect(_spot_image([31, 32], 32), 1)  # u = 0.25 at the horizon
    assert c[1] > 0 and abs(c[1]) > 10 * max(abs(c[2]), abs(c[3]))
    c = projection.project_equirect(_spot_image([31, 32], 96), 1)  # u = 0.75 → −y
    assert c[1] < 0


def test_equirect_convention_top_rows_are_plus_z():
    img = np.zeros((64, 128))
    img[:4] = 1.0
    c = projection.project_equirect(img, 1)
    assert c[2] > 0 and abs(c[2]) > 1e6 * max(abs(c[1]), abs(c[3]))


# ----------------------------------------------------------------------------------------------
# Windowing
# ----------------------------------------------------------------------------------------------


def test_window_values():
    """The SH windows (Hanning, Lanczos, none) have their defining values: the ringing control behaves as
    documented."""
    h = windows.window(L_MAX, "hanning")
    assert h.shape == ((L_MAX + 1) ** 2,)
    assert h[0] == 1.0
    assert np.all(np.diff(h[[l * (l + 1) for l in range(L_MAX + 1)]]) < 0)  # strictly decreasing
    assert h[-1] > 0  # default width l_max + 1 keeps the top band
    assert np.all(windows.window(L_MAX, "none") == 1.0)
    lz = windows.window(4, "lanczos", width=5)
    assert lz[0] == 1.0 and lz[-1] == pytest.approx(math.sin(math.pi * 4 / 5) / (math.pi * 4 / 5))


@pytest.mark.parametrize("kind", ["hanning", "lanczos"])
def test_window_reduces_ringing_of_delta_light(kind):
    d = np.array([0.0, 0.0, 1.0])
    c = harmonics.basis(L_MAX, d)  # projection of a unit delta light along +z
    dirs, _ = gauss_sphere(40)
    raw = harmonics.evaluate(c, dirs)
    windowed = harmonics.evaluate(windows.apply_window(c, kind), dirs)
    assert windows.apply_window(c, kind)[0] == c[0]  # l = 0 (the mean) unchanged
    # Negative lobes: both in absolute terms and relative to the (also reduced) peak.
    assert windowed.min() > raw.min()
    assert windowed.min() / windowed.max() > raw.min() / raw.max()


# ----------------------------------------------------------------------------------------------
# Bad input
# ----------------------------------------------------------------------------------------------


@pytest.mark.parametrize("l_max", [-1, 1.5, "2", True, None, harmonics.MAX_L_MAX + 1])
def test_bad_l_max(l_max):
    """A bad l_max is refused with the argument named."""
    with pytest.raises(ValueError, match="l_max"):
        harmonics.basis(l_max, [0, 0, 1])


@pytest.mark.parametrize(
    "directions",
    [[0.0, 0.0, 0.0], [np.nan, 0.0, 1.0], [np.inf, 0.0, 0.0], [[1.0, 0.0]], "up", [[1, 0, 0], [0, 0, 0]]],
)
def test_bad_directions(directions):
    """Directions of a wrong shape or zero length are refused with the argument named."""
    with pytest.raises(ValueError, match="directions"):
        harmonics.basis(2, directions)


@pytest.mark.parametrize(
    "matrix",
    [
        np.eye(3) * 1.01,  # scaled
        np.diag([1.0, 1.0, -1.0]),  # reflection, det −1
        np.eye(2),  # wrong shape
        np.full((3, 3), np.nan),
        np.array([[1.0, 1e-3, 0], [0, 1, 0], [0, 0, 1]]),  # shear
    ],
)
def test_bad_rotation(matrix):
    """A matrix that is not a rotation is refused with the argument named, not silently applied."""
    with pytest.raises(ValueError, match="R"):
        rotations.rotation(2, matrix)
    with pytest.raises(ValueError, match="R"):
        rotations.rotate(np.zeros(9), matrix)


def test_rotation_accepts_float32_level_rounding():
    r = NAMED_ROTATIONS["generic"].astype(np.float32).astype(np.float64)
    assert rotations.rotation(2, r).shape == (9, 9)


def test_bad_window_and_coefficients():
    """Bad window kinds, widths and coefficient shapes are refused with the argument named."""
    with pytest.raises(ValueError, match="kind"):
        windows.window(4, "hamming")
    with pytest.raises(ValueError, match="width"):
        windows.window(4, "hanning", width=0.0)
    with pytest.raises(ValueError, match="coeffs"):
        windows.apply_window(np.zeros(10))
    with pytest.raises(ValueError, match="radiance_coeffs"):
        sh_zonal.irradiance_coefficients(np.zeros(5))
    with pytest.raises(ValueError, match="zonal"):
        sh_zonal.convolve_zonal(np.zeros(9), [1.0, 2.0])


def test_bad_projection_inputs():
    """Projection refuses mismatched values, weights, images and cosines with the argument named."""
    dirs, weights = gauss_sphere(4)
    with pytest.raises(ValueError, match="values"):
        projection.project(2, dirs, np.zeros(len(dirs) + 1), weights)
    with pytest.raises(ValueError, match="weights"):
        projection.project(2, dirs, np.zeros(len(dirs)), weights[:-1])
    with pytest.raises(ValueError, match="image"):
        projection.project_equirect(np.zeros((4, 8, 3, 2)), 2)
    with pytest.raises(ValueError, match="cos_theta"):
        harmonics.basis_from_angles(2, 1.5, 0.0)
    with pytest.raises(ValueError, match="angle"):
        rotations.rotation_z(2, [0.1, 0.2])
