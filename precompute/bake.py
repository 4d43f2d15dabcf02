"""Bake SH coefficient tables for a material (Lindsay & Agu 2005, with the design's changes).

For each view angle θo in the view-aligned local frame (z = n, view in the xz-plane) the
transfer function T(ωi) = f(ωi, ωo, λ) cosθi is projected onto real SH; m < 0 coefficients
vanish by mirror symmetry, so only the (L+1)(L+2)/2 coefficients with m ≥ 0 are kept. The
spectral dimension is integrated exactly for linearly upsampled RGB lighting: each coefficient
becomes a 3×3 matrix from lighting RGB to output RGB (``colour_mode="spectral"``), or 3 numbers
for Cycles' per-channel film model (``"per_channel"``).

Fast algorithm (factorised)
---------------------------
The film enters the microfacet BRDF only through R(u, λ) with u = ωi·h ∈ [0, 1]. Interpolating
R in u at Chebyshev nodes u_k with Lagrange polynomials ℓ_k,

    F_i(θo, λ) = Σ_k K_ik(θo) R(u_k, λ),   K_ik(θo) = ∫ D G₂ ℓ_k(u) Y_i(ωi) / (4 cosθo) dωi,

and since the colour integral is linear too, M_i = Σ_k K_ik Σ_λ R(u_k, λ) G(λ). The kernel K
depends only on roughness, SH order, the θo grid and the node count, and is cached; a new film
costs one reflectance sweep on U × W points and one small tensor contraction. The node count
U is chosen per film until the interpolation error is below ``U_TOLERANCE`` (spectral
convergence: R is analytic in u for passive media with an air-like ambient).

:func:`bake_reference` is the brute-force baker: the same quadrature nodes, but the exact film
reflectance at every node's u and every wavelength (no factorisation), for validation.
"""

from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass, field, replace

import numpy as np

from . import brdf, composite, constants, sh, spectra, table_io
from .chunks import (
    CONTRACT_CHUNK,
    ELEMENT_CHUNK,
    chunked_sweep,
    kernel_blocks,
    row_blocks,
    sweep_checkpoints,
)
from .material import AUTO, MAX_SH_ORDER, Material
from .optics import reflectance
from .progress import Phases, checkpoint

#: R(u) is interpolated by piecewise Chebyshev polynomials on intervals graded geometrically
#: toward u = 0: near grazing both interfaces reflect almost fully and the film becomes a
#: Fabry–Pérot cavity whose resonances are about as narrow as u itself, so equal *relative*
#: interval widths keep the work per interval constant.
U_EDGES = (0.0, 0.0125, 0.025, 0.05, 0.1, 0.2, 0.4, 0.7, 1.0)
#: Nodes per interval tried in turn until the interpolation error meets U_TOLERANCE.
U_DEGREE_LADDER = (6, 8, 12, 16, 24, 32, 48, 64)
#: Max |R_interp − R| at test points relative to max R; keeps the factorisation error ≪ 1e-5.
U_TOLERANCE = 1e-6
#: Test points skip u < 0.0125 (half-vectors within 0.7° of grazing): the first interval's
#: resonances are narrower still, and only views within 0.7° of the horizon see them.
U_TEST_MIN = U_EDGES[1]
#: Half-vector quadrature per view angle: Gauss–Legendre nodes in s (ξ = 1 − s²) × φ midpoints
#: over (0, π) (the integrand is even in φ for m ≥ 0). Convergence is measured in the tests.
N_THETA = 96
N_PHI = 48
FORMAT_KIND = "sh_table"
#: The bake's phases and their shares of the progress bar (≈ their share of a cold bake's time).
PHASES = {"planning": 0.10, "reflectance": 0.15, "kernel": 0.60, "contracting": 0.15}


# ----------------------------------------------------------------------------------------------
# Small pieces
# ----------------------------------------------------------------------------------------------
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


def u_nodes(degree: int) -> np.ndarray:
    """All interpolation nodes: ``degree`` Chebyshev points in each interval of U_EDGES, (U,)."""
    return np.concatenate(
        [chebyshev_nodes(degree, a, b)[0] for a, b in zip(U_EDGES[:-1], U_EDGES[1:], strict=False)]
    )


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


def half_vector_nodes(alpha: float, n_theta: int = N_THETA, n_phi: int = N_PHI):
    """Half-vectors and weights w.r.t. D(h) cosθh dωh, φ over (0, π) with weights doubled."""
    s, ws = np.polynomial.legendre.leggauss(n_theta)
    s, ws = 0.5 * (s + 1.0), 0.5 * ws
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


def transfer_samples(cos_o: float, alpha: float, l_max: int, n_theta: int = N_THETA, n_phi: int = N_PHI):
    """For one view: u = ωo·h at each node and the Fresnel-free weight × Y_i(ωi), shape (N, K).

    f cosθi dωi = D G₂ R(u) (ωo·h) / cosθo dωh; with nodes weighted by D cosθh dωh the
    per-node factor is G₂ (ωo·h) / (cosθo cosθh).
    """
    h, w = half_vector_nodes(alpha, n_theta, n_phi)
    wo = np.array([math.sqrt(max(0.0, 1.0 - cos_o * cos_o)), 0.0, cos_o])
    u = h @ wo
    wi = 2.0 * u[:, None] * h - wo[None, :]
    ok = (u > 0.0) & (wi[:, 2] > 0.0)
    g2 = brdf.G2_smith_height_correlated(np.maximum(wi[:, 2], constants.MIN_COS), cos_o, alpha)
    scalar = np.where(ok, g2 * u / (cos_o * h[:, 2]), 0.0) * w
    y = sh.basis(l_max, wi)[:, coefficient_indices(l_max)]
    return np.clip(u, 0.0, 1.0), scalar[:, None] * y


@functools.lru_cache(maxsize=32)
def microfacet_kernel(
    roughness: float, l_max: int, view_samples: int, u_degree: int, n_theta: int = N_THETA, n_phi: int = N_PHI
) -> np.ndarray:
    """K (A, K_coeffs, U): SH projection of D G₂ ℓ_k(u) cos / (4 cos cos) per view angle. Cached."""
    alpha = float(brdf.alpha_from_roughness(roughness))
    out = []
    for cos_o in view_cosines(view_samples):
        u, ty = transfer_samples(float(cos_o), alpha, l_max, n_theta, n_phi)
        checkpoint()  # progress and cancellation points: ≤ KERNEL_CHUNK multiply-adds apart
        interp = u_interpolation_matrix(u_degree, u)
        row = np.empty((ty.shape[1], interp.shape[1]))
        for cols in kernel_blocks(ty.shape[0], ty.shape[1], interp.shape[1]):
            row[:, cols] = ty.T @ interp[:, cols]
            checkpoint()
        out.append(row)
    kernel = np.array(out)
    kernel.setflags(write=False)
    return kernel


@functools.lru_cache(maxsize=32)
def diffuse_kernel(l_max: int, u_degree: int, n_mu: int = 128) -> np.ndarray:
    """Kd (L+1, U): 2π ∫₀¹ μ Y_l0(μ) ℓ_k(μ) dμ — the zonal projection of the film-filtered cosine."""
    mu, wmu = np.polynomial.legendre.leggauss(n_mu)
    mu, wmu = 0.5 * (mu + 1.0), 0.5 * wmu
    dirs = np.stack([np.sqrt(1.0 - mu * mu), np.zeros_like(mu), mu], axis=-1)
    zonal = sh.basis(l_max, dirs)[:, [l * (l + 1) for l in range(l_max + 1)]]
    return 2.0 * np.pi * (zonal * (mu * wmu)[:, None]).T @ u_interpolation_matrix(u_degree, mu)


# ----------------------------------------------------------------------------------------------
# Spectral quadrature: λ → (output RGB k, lighting RGB c)
# ----------------------------------------------------------------------------------------------
def is_line_spectrum(illuminant: str) -> bool:
    """Fluorescent lamps (FL1–FL12 / F1–F12) have emission lines: the Composite Model applies."""
    return illuminant.upper().startswith("F")


@functools.lru_cache(maxsize=16)
def _illuminant_composite(illuminant: str):
    wl, values = spectra.illuminant_table(illuminant)
    return composite.fit_composite(wl, values)


def spectral_quadrature(count: int, colour_space: str, illuminant: str, colour_mode: str):
    """Wavelength nodes (W′,) and weights G (W′, 3, 3) with M[k, c] = Σ_λ F(λ) G[λ, k, c].

    spectral: G[λ, k, c] = Σ_j M_xyz→rgb[k, j] · X_j(λ) · S(λ) · B_c(λ) — lighting channel c
    upsampled with the linear basis B (Mallett & Yuksel 2019), times the illuminant S, integrated
    against the CMFs (X includes dλ and the E normalisation) and taken to the working space.
    per_channel (Cycles): the film's RGB reflectance R_k = (M X)_k · F multiplies light channel k:
    G[λ, k, c] = δ_kc (M X)_k(λ) S(λ).

    Line illuminants follow the Composite Model (Sun, Drew & Fracchia 1999): the smooth part is
    integrated on the grid, and each emission line becomes one more node at its exact wavelength
    with weight P_j c̄(λ_j) / ∫c̄, so the film is evaluated exactly where the lamp emits.
    """
    wl = spectra.wavelength_grid(count)
    m = spectra.xyz_to_rgb_matrix(colour_space)
    basis = spectra.rgb_basis(wl, colour_space)  # (3, W)
    if is_line_spectrum(illuminant):
        comp = _illuminant_composite(illuminant)
        scale = 1.0 / comp.to_xyz()[1]  # Y = 1, as illuminant_spd
        smooth = comp.evaluate_smooth(wl) * scale
        lines = np.asarray(comp.spike_wavelengths_nm, dtype=float)
        line_xyz = (
            spectra.cmfs(lines) * (np.asarray(comp.spike_powers) * scale)[:, None] / spectra.cmf_integrals()
        )
        rgb_w = np.concatenate([(spectra.xyz_weights(wl) @ m.T) * smooth[:, None], line_xyz @ m.T])
        line_basis = np.stack([np.interp(lines, wl, b) for b in basis])
        basis = np.concatenate([basis, line_basis], axis=1)
        wl = np.concatenate([wl, lines])
    else:
        rgb_w = (spectra.xyz_weights(wl) @ m.T) * spectra.illuminant_spd(illuminant, wl)[:, None]
    if colour_mode == "per_channel":
        return wl, rgb_w[:, :, None] * np.eye(3)[None, :, :]
    return wl, rgb_w[:, :, None] * basis.T[:, None, :]


# ----------------------------------------------------------------------------------------------
# Automatic choices
# ----------------------------------------------------------------------------------------------
def optical_path_nm(material: Material) -> float:
    """Upper bound of the round-trip optical path 2 Σ |N_j| d_j over the film (nm), at max thickness.

    A varying top layer counts at the top of its range (the thickest row of the table), never at
    its own ``thickness_nm``, which the table does not use (:func:`table_material`).
    """
    wl = np.array(
        [spectra.WAVELENGTH_MIN_NM if hasattr(spectra, "WAVELENGTH_MIN_NM") else constants.WAVELENGTH_MIN_NM]
    )
    total = 0.0
    for model, d in zip(material.indices()[1:-1], table_material(material).thicknesses(), strict=False):
        total += float(np.abs(model.index(wl))[0]) * d
    return 2.0 * total


def auto_wavelength_count(material: Material) -> tuple[int, str]:
    """Enough samples that one spans ≤ MAX_PHASE_STEP of fringe phase (Nyquist in wavenumber)."""
    opd = optical_path_nm(material)
    span = 2.0 * np.pi * opd * (1.0 / constants.WAVELENGTH_MIN_NM - 1.0 / constants.WAVELENGTH_MAX_NM)
    count = int(min(4096, max(48, math.ceil(span / constants.MAX_PHASE_STEP))))
    return (
        count,
        f"optical path {opd:.0f} nm → {span / (2 * np.pi):.1f} fringes over 360–830 nm → {count} samples",
    )


def auto_thickness_samples(material: Material) -> tuple[int, str]:
    """Eight samples per fringe at 360 nm across the thickness range (lerp error ≤ 8 % of a fringe)."""
    if not material.varies:
        return 1, "constant thickness: no thickness axis"
    lo, hi = material.thickness_range_nm
    n_top = float(np.abs(material.indices()[1].index(np.array([constants.WAVELENGTH_MIN_NM])))[0])
    fringes = 2.0 * n_top * (hi - lo) / constants.WAVELENGTH_MIN_NM
    count = int(min(128, max(8, math.ceil(8 * fringes) + 1)))
    return count, f"{fringes:.1f} fringes across {lo:g}–{hi:g} nm → {count} samples"


def auto_view_samples(material: Material) -> tuple[int, str]:
    """Narrow lobes change faster with θo: 48 below roughness 0.15, 32 below 0.5, else 16."""
    r = material.roughness
    count = 48 if r < 0.15 else 32 if r < 0.5 else 16
    return count, f"roughness {r:g} → {count} view angles"


#: View angles at which the SH truncation is judged: normal incidence, where the lobe is
#: narrowest around its peak, and 80°, where the horizon cuts the lobe — measured against Cycles,
#: the rim of a rough sphere is where a low order fails (ΔE 7.6 at l = 5 vs 4.3 at l = 8,
#: roughness 0.6, studio HDRI), although the normal-view lobe alone would accept l = 5.
TRUNCATION_VIEWS_DEG = (0.0, 80.0)


def lobe_truncation_error(roughness: float, l_max: int) -> float:
    """Relative L2 error of the R ≡ 1 transfer function truncated at band l_max (worst judged view)."""
    kernel = microfacet_kernel(float(roughness), 16, 10, U_DEGREE_LADDER[0])  # views every 10°
    bands = np.array([l for l in range(17) for _ in range(l + 1)])  # band of each kept coefficient
    worst = 0.0
    for deg in TRUNCATION_VIEWS_DEG:
        coeffs = kernel[int(round(deg / 10.0))].sum(axis=1)  # Σ over u nodes ⇔ R ≡ 1
        energy = coeffs**2
        kept = energy[bands <= l_max].sum()
        worst = max(worst, math.sqrt(max(0.0, 1.0 - kept / energy.sum())))
    return worst


def auto_sh_order(material: Material, target: float = 0.10) -> tuple[int, str]:
    """Smallest l_max in 2…:data:`MAX_SH_ORDER` whose lobe truncation error is ≤ ``target``; the
    highest if none is.

    The cap is 12: against Cycles (benchmarks/cycles_compare.py cases, combined path, mean
    ΔE2000) l = 8 / 10 / 12 gave courtyard r 0.5: 2.74 / 2.06 / 1.5, studio r 0.6: 3.72 / 2.93 /
    2.5, forest r 0.5: 1.26 / 0.97 / 0.9; the error sits at grazing views, where the clipped lobe
    needs many bands.
    """
    top = MAX_SH_ORDER
    for l_max in range(2, top + 1):
        err = lobe_truncation_error(material.roughness, l_max)
        if err <= target:
            return (
                l_max,
                f"roughness {material.roughness:g}: band-{l_max} truncation error {err:.3f} ≤ {target}",
            )
    err = lobe_truncation_error(material.roughness, top)
    return (
        top,
        f"roughness {material.roughness:g}: lobe needs more than band {top} (error {err:.3f} at {top})",
    )


def choose_u_degree(indices, thickness_sets, wavelengths_nm, method: str):
    """Smallest nodes-per-interval whose interpolation of R(u) meets ``U_TOLERANCE``.

    Checked on four thickness rows including the thickest (R oscillates fastest in u there) at
    test points interleaved with the nodes (the Chebyshev points of one degree more), for
    u ≥ ``U_TEST_MIN``; then R is evaluated at the chosen nodes for every row, once.
    The search always starts at the bottom of the ladder (a probe step costs 4 rows only), so a
    material's table never depends on what was baked before it.
    Returns (degree, measured relative error, R at the nodes (T, U, W)).
    """
    rows = np.unique(np.linspace(0, thickness_sets.shape[0] - 1, 4).round().astype(int))
    probe = thickness_sets[rows]
    err = math.inf
    degree = U_DEGREE_LADDER[-1]
    for candidate in U_DEGREE_LADDER:
        nodes = u_nodes(candidate)
        test = u_nodes(candidate + 1)
        test = test[test >= U_TEST_MIN]
        both = chunked_sweep(indices, probe, wavelengths_nm, np.concatenate([nodes, test]), method)
        at_nodes, exact = both[:, : nodes.size], both[:, nodes.size :]
        interp = np.matmul(u_interpolation_matrix(candidate, test), at_nodes)
        err = float(np.max(np.abs(interp - exact))) / max(float(exact.max()), 1e-6)
        if err <= U_TOLERANCE:
            degree = candidate
            break
    return (
        degree,
        err,
        chunked_sweep(indices, thickness_sets, wavelengths_nm, u_nodes(degree), method),
    )


# ----------------------------------------------------------------------------------------------
# The bake
# ----------------------------------------------------------------------------------------------
@dataclass
class BakeResult:
    """A baked table and how it was made.

    ``data`` has shape (T, A, K, 3, 3) for spectral colour (T = 1 when the thickness is constant)
    or (T, A, K, 3) per channel; K = (L+1)(L+2)/2 coefficients with m ≥ 0, ordered by l then m.
    Output radiance = Σ_i data[t, a, i] @ L_i with L_i the RGB radiance SH coefficient
    l(l+1)+m in the view-aligned frame (orthonormal real SH, no Condon–Shortley phase).
    """

    data: np.ndarray
    material: Material
    sh_order: int
    view_angles_rad: np.ndarray
    thicknesses_nm: np.ndarray
    wavelengths_nm: np.ndarray
    u_nodes: int
    reasons: dict = field(default_factory=dict)
    timings_s: dict = field(default_factory=dict)

    def attributes(self) -> dict:
        """Everything that describes the table, for the EXR header."""
        return {
            "kind": FORMAT_KIND,
            "material": self.material.to_dict(),
            "sh_order": self.sh_order,
            "sh_convention": "real orthonormal, index l(l+1)+m, no Condon-Shortley phase, m>=0 kept",
            "frame": "view-aligned: z = normal, x = normalise(v - n(n.v))",
            "folded": "nothing: out = sum_i M_i @ L_i with orthonormal radiance coefficients L_i",
            "colour_mode": self.material.colour_mode,
            "colour_space": self.material.colour_space,
            "illuminant": self.material.illuminant,
            "view_axis": "theta_o uniform 0..90 deg inclusive",
            "view_samples": int(self.view_angles_rad.size),
            "thickness_axis_nm": [float(self.thicknesses_nm[0]), float(self.thicknesses_nm[-1])],
            "thickness_samples": int(self.thicknesses_nm.size),
            "wavelength_grid_nm": [
                float(self.wavelengths_nm[0]),
                float(self.wavelengths_nm[-1]),
                int(self.wavelengths_nm.size),
            ],
            "u_nodes": self.u_nodes,
            "quadrature": [N_THETA, N_PHI],
        }

    def summary(self) -> dict:
        """JSON-ready summary of the table: shape, size, sample counts, reasons and timings."""
        return {
            "shape": list(self.data.shape),
            "bytes_float32": int(self.data.size * 4),
            "sh_order": self.sh_order,
            "view_samples": int(self.view_angles_rad.size),
            "thickness_samples": int(self.thicknesses_nm.size),
            "wavelengths": int(self.wavelengths_nm.size),
            "u_nodes": self.u_nodes,
            "reasons": self.reasons,
            "timings_s": self.timings_s,
        }


@dataclass(frozen=True)
class Plan:
    """Resolved quality choices for a material, with the reason for each."""

    sh_order: int
    view_samples: int
    thickness_samples: int
    wavelength_count: int
    reasons: dict


def plan(material: Material) -> Plan:
    """Resolve every ``"auto"`` quality setting of ``material``."""
    q = material.quality
    reasons = {}

    def pick(name, auto_fn):
        value = getattr(q, name)
        if value == AUTO:
            value, reasons[name] = auto_fn(material)
        else:
            reasons[name] = "set explicitly"
        return int(value)

    sh_order = pick("sh_order", auto_sh_order)
    views = pick("view_samples", auto_view_samples)
    t = pick("thickness_samples", auto_thickness_samples) if material.varies else 1
    if not material.varies:
        reasons["thickness_samples"] = "constant thickness: no thickness axis"
    w = pick("wavelength_count", auto_wavelength_count)
    return Plan(sh_order, views, t, w, reasons)


def thickness_sets(material: Material, count: int) -> tuple[np.ndarray, np.ndarray]:
    """(T, L) thickness sets and the top-layer thickness axis (T,)."""
    base = np.array(material.thicknesses(), dtype=float)
    if not material.varies:
        return base[None, :], base[:1] if base.size else np.zeros(1)
    axis = np.linspace(*material.thickness_range_nm, count)
    sets = np.repeat(base[None, :], count, axis=0)
    sets[:, 0] = axis
    return sets, axis


def active_stack(material: Material, count: int):
    """(indices, thickness sets (T, L'), thickness axis) with constant 0 nm layers removed.

    A layer of thickness exactly 0 that does not vary is optically absent, so it costs nothing:
    a film whose every layer is 0 nm takes the bare-interface path.
    """
    indices = material.indices()
    sets, axis = thickness_sets(material, count)
    keep = [j for j in range(sets.shape[1]) if np.any(sets[:, j] != 0.0)]
    if len(keep) < sets.shape[1]:
        indices = [indices[0]] + [indices[j + 1] for j in keep] + [indices[-1]]
        sets = sets[:, keep]
    return indices, sets, axis


def _method(material: Material) -> str:
    return "glassner2000" if material.model == "glassner2000" else "exact"


def apply_multiscatter(data: np.ndarray, material: Material, cos_o: np.ndarray) -> np.ndarray:
    """Scale the specular table (T, A, K, 3, 3) for multiple scattering (``material.multiscatter``).

    The factor 1 + F_ms (1 − E)/E (:func:`brdf.multiscatter_scale`) multiplies the output of each
    view angle. "cycles": F_avg is the bare dielectric's hemispherical Fresnel average (film-free,
    as Cycles feeds its energy preservation). "film": F_avg per output channel is the film's
    white-light albedo divided by E, averaged over the hemisphere with weight 2μ.
    """
    if material.multiscatter == "none" or material.roughness <= 0.0:
        return data
    if material.multiscatter == "cycles":
        substrate = material.indices()[-1].index(np.array([550.0]))[0]
        f_avg = brdf.fresnel_average_dielectric(float(substrate.real)) if substrate.imag == 0 else 1.0
        scale = np.repeat(brdf.multiscatter_scale(cos_o, material.roughness, f_avg)[:, None], 3, axis=1)
    else:
        e = brdf.ggx_E(float(material.roughness), tuple(np.clip(cos_o, constants.MIN_COS, 1.0).tolist()))
        albedo = data[:, :, 0] @ np.full(3, math.sqrt(4 * math.pi))  # (T, A, 3) white-light response
        mu_w = np.gradient(cos_o)  # quadrature weights over μ on the table's own samples
        weights = np.abs(mu_w) * 2.0 * cos_o
        f_avg = np.clip(np.einsum("tak,a->tk", albedo / e[None, :, None], weights) / weights.sum(), 0.0, 1.0)
        scale = np.stack([brdf.multiscatter_scale(cos_o, material.roughness, f) for f in f_avg])  # (T, A, 3)
    if scale.ndim == 2:
        scale = np.broadcast_to(scale[None], (data.shape[0],) + scale.shape)
    out = np.empty(np.broadcast_shapes(data.shape, scale[:, :, None, :, None].shape))
    for rows in row_blocks(data.shape[0], data[0].size, ELEMENT_CHUNK):
        np.multiply(data[rows], scale[rows, :, None, :, None], out=out[rows])
        checkpoint()
    return out


def base_spectrum(material: Material, wavelengths_nm: np.ndarray) -> np.ndarray:
    """Spectral albedo of the diffuse base: its RGB through the linear basis (≤ 1 for RGB ≤ 1)."""
    grid = spectra.wavelength_grid(256)
    spd = np.asarray(material.base_color) @ spectra.rgb_basis(grid, material.colour_space)
    return np.interp(wavelengths_nm, grid, spd)


def _diffuse_term(material, l_max, cos_o, r_nodes, nodes_u, g, wl) -> np.ndarray:
    """(T, A, K, 3, 3) contribution of the diffuse base (m = 0 entries only)."""
    kd = diffuse_kernel(l_max, nodes_u)  # (L+1, U)
    base = base_spectrum(material, wl)  # (W,)
    trans = 1.0 - r_nodes  # (T, U, W)
    z = np.einsum("lu,tuw->tlw", kd, trans)  # (T, L+1, W)
    r_o = np.einsum("au,tuw->taw", u_interpolation_matrix(nodes_u, cos_o), r_nodes)  # (T, A, W)
    zonal = np.einsum("taw,tlw,w,wkc->talkc", 1.0 - r_o, z, base / np.pi, g)
    out = np.zeros(zonal.shape[:2] + (len(coefficient_indices(l_max)),) + zonal.shape[3:])
    ci = coefficient_indices(l_max).tolist()
    for l in range(l_max + 1):
        out[:, :, ci.index(l * (l + 1))] = zonal[:, :, l]
    return out


def clamp_film_rgb(rgb, colour_mode: str):
    """The film's RGB reflectance Σ_λ F(λ) G[λ] with Cycles' per-channel clamp applied.

    per_channel (Cycles' film model): each channel's reflectance is clamped to [0, 1] as Cycles
    does (``saturate`` of the film's RGB): a saturated film colour has negative Rec.709
    components, which Cycles drops instead of letting them subtract light. Measured on a
    500 nm soap film in air at roughness 0.15 under the studio HDRI: without the clamp the red
    channel reaches −0.023 (of a 0.07 peak) and the preview is off by a mean ΔE2000 of 10 in
    the dark half of the sphere. spectral: unchanged (the 3×3 model keeps signed entries).
    Off-diagonal entries are zero in per_channel mode and stay zero.
    """
    if colour_mode != "per_channel":
        return rgb
    return np.clip(rgb, 0.0, 1.0)


#: Version of the automatic choices and the bake's maths, part of every table's cache key
#: (:func:`table_key`). Bump it when a material's table would come out different: cached tables
#: of the old version are then not reused (they would be stale, not corrupt, so the checks on
#: load cannot see it). 2: SH order up to 12 (was 8).
PLANNER_VERSION = 2


def table_material(material: Material) -> Material:
    """``material`` as its table sees it: what the table does not depend on set to one value.

    With a thickness range the top layer's thickness at each table row is the row's value, so
    the layer's own ``thickness_nm`` is unused; it is set to the top of the range (the thickest
    row, where the wavelength count and the u nodes are planned). Two materials that differ only
    in that unused value then share one plan, one key and one table. Other materials are
    returned unchanged (the same object).
    """
    if not material.varies:
        return material
    top = material.layers[0]
    hi = float(material.thickness_range_nm[1])
    if float(top.thickness_nm) == hi:
        return material
    return material.with_(layers=(replace(top, thickness_nm=hi), *material.layers[1:]))


def table_key(material: Material) -> str:
    """Cache key of a material's table: the parameters it uses (:func:`table_material`) and
    :data:`PLANNER_VERSION`."""
    return table_io.content_key({"material": table_material(material).to_dict(), "planner": PLANNER_VERSION})


def contract(kernel: np.ndarray, r_nodes: np.ndarray, g: np.ndarray, colour_mode: str) -> np.ndarray:
    """The table (T, A, K, 3, 3): M[t, a, i] = Σ_k K[a, i, k] clamp(Σ_λ R[t, k, λ] G[λ]).

    In blocks of thickness rows of ≤ :data:`CONTRACT_CHUNK` multiply-adds, a progress
    :func:`checkpoint` after each; every row is contracted on its own, so the blocks change
    nothing but the checkpoints.
    """
    a, k, u = kernel.shape
    flat = kernel.reshape(a * k, u)
    g2 = g.reshape(g.shape[0], -1)
    t = r_nodes.shape[0]
    rows = max(1, CONTRACT_CHUNK // (9 * u * (a * k + g2.shape[0])))
    out = np.empty((t, a, k, 3, 3))
    for lo in range(0, t, rows):
        rg = clamp_film_rgb(r_nodes[lo : lo + rows] @ g2, colour_mode)  # (t', U, 9)
        n = rg.shape[0]
        rg = rg.transpose(1, 0, 2).reshape(u, -1)  # (U, t'·9)
        out[lo : lo + n] = (flat @ rg).reshape(a, k, n, 3, 3).transpose(2, 0, 1, 3, 4)
        checkpoint()
    return out


def bake(material: Material, progress=None) -> BakeResult:
    """Fast factorised bake of ``material`` (see the module docstring). ``progress(fraction, text)``.

    ``progress`` is called at every step of ≲ 0.1 s (:mod:`.progress`: the fraction moves by
    ≤ 5 % per call and reaches 1.0 at the end); an exception it raises stops the bake there
    and propagates (nothing half-made is cached). The result's ``material`` is
    :func:`table_material` of ``material`` (what the table depends on), so equal keys give
    equal tables and equal header attributes.
    """
    t0 = time.perf_counter()
    phases = Phases(progress or (lambda fraction, text: None), PHASES)
    with phases.reporting():
        material = table_material(material)
        auto_order = material.quality.sh_order == AUTO
        phases.start("planning", "planning", expected=21 if auto_order else 1)
        p = plan(material)
        wl, g = spectral_quadrature(
            p.wavelength_count, material.colour_space, material.illuminant, material.colour_mode
        )
        indices, sets, axis = active_stack(material, p.thickness_samples)
        method = _method(material)
        guess = U_DEGREE_LADDER[1] * (len(U_EDGES) - 1)
        phases.start(
            "reflectance",
            "choosing reflectance nodes",
            expected=2 + sweep_checkpoints(sets.shape[0], sets.shape[1], guess, wl.size),
        )
        t1 = time.perf_counter()
        if sets.shape[1] == 0:
            u_count, u_err = U_DEGREE_LADDER[0], 0.0
            r_nodes = reflectance(indices, [], wl, u_nodes(u_count))[None]
        else:
            u_count, u_err, r_nodes = choose_u_degree(indices, sets, wl, method)
        t2 = time.perf_counter()
        blocks = len(
            kernel_blocks(N_THETA * N_PHI, len(coefficient_indices(p.sh_order)), u_count * (len(U_EDGES) - 1))
        )
        phases.start("kernel", "microfacet kernel", expected=(1 + blocks) * p.view_samples)
        kernel = microfacet_kernel(float(material.roughness), p.sh_order, p.view_samples, u_count)
        t3 = time.perf_counter()
        a, k, u = kernel.shape
        t = r_nodes.shape[0]
        diffuse_blocks = (
            row_blocks(t, 9 * a * (p.sh_order + 1) * wl.size) if material.base_color is not None else []
        )
        phases.start(
            "contracting",
            "contracting",
            expected=len(row_blocks(t, 9 * u * (a * k + g.shape[0])))
            + (
                a + 34 + len(row_blocks(t, a * k * 9, ELEMENT_CHUNK))
                if material.multiscatter != "none"
                else 0
            )
            + len(diffuse_blocks),
        )
        data = contract(kernel, r_nodes, g, material.colour_mode)
        data = apply_multiscatter(data, material, view_cosines(p.view_samples))
        cos_o = view_cosines(p.view_samples)
        for rows in diffuse_blocks:
            data[rows] += _diffuse_term(material, p.sh_order, cos_o, r_nodes[rows], u_count, g, wl)
            checkpoint()
        if material.colour_mode == "per_channel":
            data = np.einsum("taikk->taik", data)
        t4 = time.perf_counter()
        phases.done()
    reasons = dict(
        p.reasons,
        u_nodes=f"{u_count} Chebyshev nodes in each of {len(U_EDGES) - 1} graded intervals: "
        f"interpolation error {u_err:.1e} (relative)",
    )
    return BakeResult(
        data=data,
        material=material,
        sh_order=p.sh_order,
        view_angles_rad=view_angles(p.view_samples),
        thicknesses_nm=axis,
        wavelengths_nm=wl,
        u_nodes=u_count,
        reasons=reasons,
        timings_s={"reflectance": t2 - t1, "kernel": t3 - t2, "contract": t4 - t3, "total": t4 - t0},
    )


def bake_reference(material: Material, n_theta: int = N_THETA, n_phi: int = N_PHI) -> BakeResult:
    """Brute-force reference: exact film reflectance at every quadrature node and wavelength.

    No Chebyshev factorisation and no kernel cache: for each view angle and thickness, every
    hemisphere node ωi is evaluated with the full spectral BRDF and projected on the SH basis.
    Same plan and quadrature nodes as :func:`bake`, so the two differ only by the factorisation.
    """
    t0 = time.perf_counter()
    material = table_material(material)
    p = plan(material)
    wl, g = spectral_quadrature(
        p.wavelength_count, material.colour_space, material.illuminant, material.colour_mode
    )
    indices, sets, axis = active_stack(material, p.thickness_samples)
    method = _method(material)
    alpha = float(brdf.alpha_from_roughness(material.roughness))
    cos_os = view_cosines(p.view_samples)
    ci = coefficient_indices(p.sh_order).tolist()
    base = None
    if material.base_color is not None:
        base = base_spectrum(material, wl)
        mu, wmu = np.polynomial.legendre.leggauss(128)
        mu, wmu = 0.5 * (mu + 1.0), 0.5 * wmu
        zon = sh.basis(p.sh_order, np.stack([np.sqrt(1 - mu * mu), 0 * mu, mu], -1))
    out = np.zeros((sets.shape[0], cos_os.size, len(ci), 3, 3))
    diffuse = np.zeros_like(out)
    for t, row in enumerate(sets):
        for a, cos_o in enumerate(cos_os):
            u, ty = transfer_samples(float(cos_o), alpha, p.sh_order, n_theta, n_phi)
            r = reflectance(indices, row, wl, u, method=method)  # (N, W) exact at every node
            rgb = clamp_film_rgb(np.einsum("nw,wkc->nkc", r, g), material.colour_mode)  # (N, 3, 3)
            f = ty.T @ r  # (K, W), for the diffuse term's shape
            if base is not None:
                r_o = reflectance(indices, row, wl, [cos_o], method=method)[0]
                r_mu = reflectance(indices, row, wl, mu, method=method)
                fd = np.zeros_like(f)
                for l in range(p.sh_order + 1):
                    zl = 2 * np.pi * np.sum((1 - r_mu) * (mu * wmu * zon[:, l * (l + 1)])[:, None], axis=0)
                    fd[ci.index(l * (l + 1))] = base / np.pi * (1 - r_o) * zl
                diffuse[t, a] = np.einsum("iw,wkc->ikc", fd, g)
            out[t, a] = np.einsum("ni,nkc->ikc", ty, rgb)
    out = apply_multiscatter(out, material, cos_os) + diffuse
    if material.colour_mode == "per_channel":
        out = np.einsum("taikk->taik", out)
    return BakeResult(
        data=out,
        material=material,
        sh_order=p.sh_order,
        view_angles_rad=view_angles(p.view_samples),
        thicknesses_nm=axis,
        wavelengths_nm=wl,
        u_nodes=0,
        reasons=p.reasons,
        timings_s={"total": time.perf_counter() - t0},
    )
