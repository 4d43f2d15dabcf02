"""The microfacet kernel's fast paths equal the plain dense computation."""

import numpy as np
import pytest

from precompute import brdf
from precompute.bakes import kernel, planner, quadrature
from precompute.sh import harmonics


def _dense_kernel(roughness, l_max, views, degree):
    """K as first written: the full SH basis at every node, times the dense interpolation matrix."""
    alpha = float(brdf.alpha_from_roughness(roughness))
    out = []
    for cos_o in kernel.view_cosines(views):
        u, ty = kernel.transfer_samples(float(cos_o), alpha, l_max)
        out.append(ty.T @ kernel.u_interpolation_matrix(degree, u))
    return np.array(out)


@pytest.mark.parametrize(("roughness", "l_max", "degree"), [(0.05, 12, 16), (0.3, 5, 8), (0.9, 2, 6)])
def test_block_sparse_kernel_equals_the_dense_product(roughness, l_max, degree):
    """Skipping the zero blocks and the dead nodes changes nothing but rounding."""
    fast = kernel.microfacet_kernel(roughness, l_max, 7, degree)
    dense = _dense_kernel(roughness, l_max, 7, degree)
    assert fast.shape == dense.shape
    np.testing.assert_allclose(fast, dense, rtol=0, atol=1e-13 * np.abs(dense).max())
    assert not fast.flags.writeable


@pytest.mark.parametrize("l_max", [0, 1, 2, 7, 12, 16])
def test_nonnegative_m_rows_are_the_basis_columns(l_max):
    """basis_nonnegative_m is basis()'s m ≥ 0 columns, transposed, times the weights."""
    rng = np.random.default_rng(l_max)
    d = rng.normal(size=(300, 3))
    w = rng.random(300)
    full = harmonics.basis(l_max, d)[:, kernel.coefficient_indices(l_max)]
    np.testing.assert_allclose(harmonics.basis_nonnegative_m(l_max, d, w), (full * w[:, None]).T, atol=1e-13)
    np.testing.assert_allclose(harmonics.basis_nonnegative_m(l_max, d), full.T, atol=1e-13)


def test_gauss_legendre_is_cached_read_only_and_exact():
    """One array per order, not writable, integrating x^(2n−1) exactly on (0, 1)."""
    x, w = quadrature.unit_gauss_legendre(24)
    assert quadrature.unit_gauss_legendre(24)[0] is x
    assert not x.flags.writeable and not w.flags.writeable
    assert np.sum(w * x**47) == pytest.approx(1.0 / 48.0, rel=1e-13)
    with pytest.raises(ValueError, match="positive integer"):
        quadrature.gauss_legendre(0)


def test_one_view_of_the_kernel_fits_between_two_checkpoints():
    """A view's block-sparse product at the largest order and node count stays within the budget
    of work between two progress checkpoints (a cancel waits for at most that)."""
    from precompute.bakes import chunks
    from precompute.materials.material import MAX_SH_ORDER

    k = len(kernel.coefficient_indices(MAX_SH_ORDER))
    assert kernel.N_THETA * kernel.N_PHI * k * max(planner.U_DEGREE_LADDER) <= chunks.KERNEL_CHUNK
