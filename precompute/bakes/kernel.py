"""The microfacet kernel of the factorised bake: the film-free angular integral, per roughness.

For each view angle θo (view-aligned frame: z = n, view in the xz-plane) the bake needs

    K_ik(θo) = ∫ D G₂ ℓ_k(u) Y_i(ωi) / (4 cosθo) dωi,   u = ωi·h,

with ℓ_k the piecewise-Chebyshev Lagrange polynomials of R(u) (:data:`U_EDGES`) and Y_i the
m ≥ 0 real SH (:mod:`precompute.bakes.bake` explains the factorisation). It depends only on the
roughness, the SH order, the θo grid and the node count, and is cached.

How it is computed (the same sums as the dense product Y·W of (K × N)(N × U), less work):

- the half-vector rule's Gauss–Legendre nodes come from :func:`quadrature.unit_gauss_legendre`
  (computed once per process, read-only);
- the SH rows are evaluated only for m ≥ 0 and only at nodes of non-zero weight, as contiguous
  rows with the weight folded into the recurrence's seed (:func:`sh.basis_nonnegative_m`);
- the u interpolation matrix W is block-sparse (a node has weights only on its interval's
  ``degree`` columns), so each interval's columns are one small product of its own nodes:
  1/8 of the dense multiply-adds (:func:`view_kernel`).

The brute-force reference (:mod:`precompute.bakes.bake_reference`) uses :func:`transfer_samples`: the
same quadrature nodes, every node, the full (N, K) weights.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from .. import brdf, constants
from ..sh import harmonics
from .progress import checkpoint
from .quadrature import unit_gauss_legendre

#: Multiply-adds of one matrix product of :func:`view_kernel`: OpenBLAS runs a product of fewer
#: than 4 × 65536 multiply-adds on one thread (``GEMM_MULTITHREAD_THRESHOLD``). The kernel's
#: products are many and small; threaded, on a shared two-core machine, they cost 3× the CPU
#: time and more wall time than on one thread (docs/bake-speed.md), so they are cut below it.
SMALL_PRODUCT = 240_000

__all__ = [
    "N_PHI",
    "N_THETA",
    "U_EDGES",
    "chebyshev_nodes",
    "coefficient_indices",
    "diffuse_kernel",
    "half_vector_nodes",
    "lagrange_matrix",
    "microfacet_kernel",
    "transfer_samples",
    "u_interpolation_matrix",
    "u_nodes",
    "view_angles",
    "view_cosines",
    "view_kernel",
    "view_weights",
]

#: R(u) is interpolated by piecewise Chebyshev polynomials on intervals graded geometrically
#: toward u = 0: near grazing both interfaces reflect almost fully and the film becomes a
#: Fabry–Pérot cavity whose resonances are about as narrow as u itself, so equal *relative*
#: interval widths keep the work per interval constant.
U_EDGES = (0.0, 0.0125, 0.025, 0.05, 0.1, 0.2, 0.4, 0.7, 1.0)

#: Half-vector quadrature per view angle: Gauss–Legendre nodes in s (ξ = 1 − s²) × φ midpoints
#: over (0, π) (the integrand is even in φ for m ≥ 0). Convergence is measured in the tests.
N_THETA = 96
N_PHI = 48


def coefficient_indices(l_max: int) -> np.ndarray:
    """Indices l(l+1)+m of the kept coefficients (m ≥ 0), ordered by l then m."""
    return np.array([l * (l + 1) + m for l in range(l_max + 1) for m in range(l + 1)])


def view_angles(count: int) -> np.ndarray:
    """θo samples uniform in angle from 0 to 90° inclusive (radians)."""
    return np.linspace(0.0, 0.5 * np.pi, count)


def view_cosines(count: int) -> np.ndarray:
    """cos θo of :func:`view_angles`, clamped to ``MIN_COS`` at grazing."""
    return np.maximum(np.cos(view_angles(count)), constants.MIN_COS)


def chebyshev_nodes(count: int, lo: float = 0.0, hi: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Chebyshev points of the first kind on [lo, hi] and barycentric weights (Berrut & Trefethen 2004)."""
    k = np.arange(count)
    angle = (2 * k + 1) * np.pi / (2 * count)
    return lo + (hi - lo) * 0.5 * (1.0 + np.cos(angle)), (-1.0) ** k * np.sin(angle)


def lagrange_matrix(nodes: np.ndarray, weights: np.ndarray, x: np.ndarray) -> np.ndarray:
    """ℓ_k(x_n) for all n, k by the barycentric formula (Berrut & Trefethen 2004, eq. 4.2)."""
    diff = x[:, None] - nodes[None, :]
    exact = diff == 0.0
    safe = np.where(exact, 1.0, diff)
    terms = weights[None, :] / safe
    out = terms / terms.sum(axis=1, keepdims=True)
    hit = exact.any(axis=1)
    out[hit] = exact[hit].astype(float)
    return out


@functools.lru_cache(maxsize=16)
def u_nodes(degree: int) -> np.ndarray:
    """All interpolation nodes: ``degree`` Chebyshev points in each interval of U_EDGES, (U,).
    Cached, read-only."""
    nodes = np.concatenate(
        [chebyshev_nodes(degree, a, b)[0] for a, b in zip(U_EDGES[:-1], U_EDGES[1:], strict=False)]
    )
    nodes.flags.writeable = False
    return nodes


def u_interpolation_matrix(degree: int, u: np.ndarray) -> np.ndarray:
    """(N, U) piecewise-Chebyshev interpolation weights: R(u_n) ≈ Σ_k W[n, k] R(node_k)."""
    u = np.clip(np.asarray(u, dtype=float), 0.0, 1.0)
    out = np.zeros((u.size, degree * (len(U_EDGES) - 1)))
    piece = np.clip(np.searchsorted(U_EDGES, u, side="right") - 1, 0, len(U_EDGES) - 2)
    for j, (a, b) in enumerate(zip(U_EDGES[:-1], U_EDGES[1:], strict=False)):
        sel = piece == j
        if np.any(sel):
            nodes, bw = chebyshev_nodes(degree, a, b)
            out[np.ix_(sel, np.arange(j * degree, (j + 1) * degree))] = lagrange_matrix(nodes, bw, u[sel])
    return out


@functools.lru_cache(maxsize=16)
def uniform_interpolation_matrix(degree: int, samples: int) -> np.ndarray:
    """:func:`u_interpolation_matrix` at ``samples`` evenly spaced u in [0, 1] (the film
    table's grid). Cached, read-only."""
    weights = u_interpolation_matrix(degree, np.linspace(0.0, 1.0, samples))
    weights.flags.writeable = False
    return weights


def half_vector_nodes(alpha: float, n_theta: int = N_THETA, n_phi: int = N_PHI):
    """Half-vectors and weights w.r.t. D(h) cosθh dωh, φ over (0, π) with weights doubled."""
    s, ws = unit_gauss_legendre(n_theta)
    xi = 1.0 - s * s
    tan2 = alpha * alpha * xi / np.maximum(1.0 - xi, 1e-300)
    cos_h = 1.0 / np.sqrt(1.0 + tan2)
    sin_h = np.sqrt(np.maximum(0.0, 1.0 - cos_h * cos_h))
    phi = np.pi * (np.arange(n_phi) + 0.5) / n_phi
    h = np.stack(
        [
            sin_h[:, None] * np.cos(phi),
            sin_h[:, None] * np.sin(phi),
            np.broadcast_to(cos_h[:, None], (n_theta, n_phi)),
        ],
        axis=-1,
    ).reshape(-1, 3)
    w = np.repeat(2.0 * s * ws, n_phi) / n_phi  # ∫ over φ ∈ (0, 2π) = 2 × ∫ over (0, π), /2π·2π
    return h, w


def view_weights(cos_o: float, alpha: float, h: np.ndarray, w: np.ndarray):
    """For one view: u = ωo·h clipped to [0, 1], the reflected ωi (N, 3) and the per-node
    Fresnel-free weight (N,), zero where u ≤ 0 or ωi is below the horizon.

    f cosθi dωi = D G₂ R(u) (ωo·h) / cosθo dωh; with nodes weighted by D cosθh dωh the
    per-node factor is G₂ (ωo·h) / (cosθo cosθh).
    """
    wo = np.array([math.sqrt(max(0.0, 1.0 - cos_o * cos_o)), 0.0, cos_o])
    u = h @ wo
    wi = 2.0 * u[:, None] * h - wo[None, :]
    ok = (u > 0.0) & (wi[:, 2] > 0.0)
    g2 = brdf.G2_smith_height_correlated(np.maximum(wi[:, 2], constants.MIN_COS), cos_o, alpha)
    scalar = np.where(ok, g2 * u / (cos_o * h[:, 2]), 0.0) * w
    return np.clip(u, 0.0, 1.0), wi, scalar


def transfer_samples(cos_o: float, alpha: float, l_max: int, n_theta: int = N_THETA, n_phi: int = N_PHI):
    """For one view: u = ωo·h at each node and the Fresnel-free weight × Y_i(ωi), shape (N, K)."""
    h, w = half_vector_nodes(alpha, n_theta, n_phi)
    u, wi, scalar = view_weights(cos_o, alpha, h, w)
    return u, harmonics.basis_nonnegative_m(l_max, wi, scalar).T


def view_kernel(cos_o: float, alpha: float, l_max: int, degree: int, h: np.ndarray, w: np.ndarray):
    """One view's kernel rows (K, U): Σ_n w_n Y_i(ωi,n) ℓ_k(u_n) over the half-vector nodes.

    The u interpolation matrix is block-sparse: a node with u in interval j of U_EDGES has
    weights only on that interval's ``degree`` columns, so the nodes are sorted by interval and
    each interval's columns are the product of its own nodes' SH rows with their Lagrange
    weights — 1/8 of the dense product's multiply-adds (8 intervals), the same sums. Nodes of
    zero weight (u ≤ 0 or ωi below the horizon) are dropped before the SH basis is evaluated.
    """
    u, wi, scalar = view_weights(cos_o, alpha, h, w)
    piece = np.clip(np.searchsorted(U_EDGES, u, side="right") - 1, 0, len(U_EDGES) - 2)
    live = np.flatnonzero(scalar)
    live = live[np.argsort(piece[live], kind="stable")]
    rows = harmonics.basis_nonnegative_m(l_max, wi[live], scalar[live])
    checkpoint()  # progress and cancellation point between the basis and the product
    bounds = np.searchsorted(piece[live], np.arange(len(U_EDGES)))
    out = np.zeros((rows.shape[0], degree * (len(U_EDGES) - 1)))
    for j, (a, b) in enumerate(zip(U_EDGES[:-1], U_EDGES[1:], strict=False)):
        lo, hi = bounds[j], bounds[j + 1]
        if hi > lo:
            nodes, bw = chebyshev_nodes(degree, a, b)
            weights = lagrange_matrix(nodes, bw, u[live[lo:hi]])
            cols = slice(j * degree, (j + 1) * degree)
            step = max(1, SMALL_PRODUCT // (rows.shape[0] * degree))
            for start in range(lo, hi, step):  # products small enough for one BLAS thread
                stop = min(hi, start + step)
                out[:, cols] += rows[:, start:stop] @ weights[start - lo : stop - lo]
    return out


@functools.lru_cache(maxsize=32)
def microfacet_kernel(
    roughness: float, l_max: int, view_samples: int, u_degree: int, n_theta: int = N_THETA, n_phi: int = N_PHI
) -> np.ndarray:
    """K (A, K_coeffs, U): SH projection of D G₂ ℓ_k(u) cos / (4 cos cos) per view angle. Cached.

    One :func:`view_kernel` per view, with a progress :func:`checkpoint` inside it and one after
    it (a view's block-sparse product is ≤ K·N·degree ≤ 27 M multiply-adds at l = 12 with 64
    nodes per interval, within ``chunks.KERNEL_CHUNK``).
    """
    alpha = float(brdf.alpha_from_roughness(roughness))
    h, w = half_vector_nodes(alpha, n_theta, n_phi)
    cosines = view_cosines(view_samples)
    kernel = np.empty((cosines.size, len(coefficient_indices(l_max)), u_degree * (len(U_EDGES) - 1)))
    for a, cos_o in enumerate(cosines):
        kernel[a] = view_kernel(float(cos_o), alpha, l_max, u_degree, h, w)
        checkpoint()
    kernel.setflags(write=False)
    return kernel


@functools.lru_cache(maxsize=32)
def diffuse_kernel(l_max: int, u_degree: int, n_mu: int = 128) -> np.ndarray:
    """Kd (L+1, U): 2π ∫₀¹ μ Y_l0(μ) ℓ_k(μ) dμ — the zonal projection of the film-filtered cosine."""
    mu, wmu = unit_gauss_legendre(n_mu)
    dirs = np.stack([np.sqrt(1.0 - mu * mu), np.zeros_like(mu), mu], axis=-1)
    zonal = harmonics.basis(l_max, dirs)[:, [l * (l + 1) for l in range(l_max + 1)]]
    return 2.0 * np.pi * (zonal * (mu * wmu)[:, None]).T @ u_interpolation_matrix(u_degree, mu)
