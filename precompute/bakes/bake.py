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

import math
import time
from dataclasses import dataclass, field

import numpy as np

from .. import brdf, constants
from ..colour import film_channels, rgb_spaces, spectra
from ..materials.material import Material
from ..optics import reflectance
from ..sh import harmonics
from .chunks import CONTRACT_CHUNK, ELEMENT_CHUNK, chunked_sweep, row_blocks, sweep_checkpoints
from .kernel import (
    N_PHI,
    N_THETA,
    U_EDGES,
    coefficient_indices,
    diffuse_kernel,
    microfacet_kernel,
    u_interpolation_matrix,
    u_nodes,
    view_angles,
    view_cosines,
)
from .planner import U_DEGREE_LADDER, active_stack, choose_u_degree, plan, table_material
from .progress import Phases, checkpoint
from .quadrature import spectral_quadrature, unit_gauss_legendre

FORMAT_KIND = "sh_table"
#: The bake's phases and their shares of the progress bar (≈ their share of a cold bake's time).
PHASES = {"planning": 0.10, "reflectance": 0.15, "kernel": 0.60, "contracting": 0.15}


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
    #: The spectral reflectance R (T, U, W) at the bake's u nodes, kept by a fresh spectral bake
    #: so its film table is interpolated from it (:func:`.film_colour.film_table`) instead of a
    #: second sweep; None for a table read from a file and in the per-channel mode. Not saved.
    node_reflectance: np.ndarray | None = field(default=None, repr=False, compare=False)

    @classmethod
    def planned(cls, data, material: Material, p, thicknesses_nm, wavelengths_nm, **fields) -> BakeResult:
        """The result of a bake of ``material`` as planned by ``p`` (:class:`.planner.Plan`): its SH
        order and view angles; ``fields`` the rest (u nodes, reasons, timings, …)."""
        return cls(
            data=data,
            material=material,
            sh_order=p.sh_order,
            view_angles_rad=view_angles(p.view_samples),
            thicknesses_nm=thicknesses_nm,
            wavelengths_nm=wavelengths_nm,
            **fields,
        )

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


def _method(material: Material) -> str:
    return "glassner2000" if material.model == "glassner2000" else "exact"


def cycles_fresnel_average(material: Material):
    """The F_avg Cycles' Multiscatter GGX compensates a Principled thin film with: the film-free
    substrate's. A dielectric's hemispherical Fresnel average; Blender's F82-tint metal's, per
    channel, mix(F0, 1, 1/21) − B/126 (``fresnel_f82_Fss``, B its F82 term); any other conductor 1.
    """
    spec = material.substrate
    if isinstance(spec, dict) and "f82_tint" in spec:
        f0 = np.clip(np.asarray(spec["f82_tint"]["f0"], dtype=float), 0.0, 1.0)
        tint = np.clip(np.asarray(spec["f82_tint"]["tint"], dtype=float), 0.0, 1.0)
        s82 = 6.0 / 7.0
        b = (f0 + (1.0 - f0) * s82**5) * 7.0 / s82**6 * (1.0 - tint)
        return np.clip(f0 + (1.0 - f0) / 21.0 - b / 126.0, 0.0, 1.0)
    substrate = material.indices()[-1].index(np.array([550.0]))[0]
    return brdf.fresnel_average_dielectric(float(substrate.real)) if substrate.imag == 0 else 1.0


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
        f_avg = np.broadcast_to(cycles_fresnel_average(material), (3,))
        scale = brdf.multiscatter_scale(cos_o, material.roughness, f_avg)  # (A, 3)
    else:
        e = brdf.ggx_E(float(material.roughness), tuple(np.clip(cos_o, constants.MIN_COS, 1.0).tolist()))
        albedo = data[:, :, 0] @ np.full(3, math.sqrt(4 * math.pi))  # (T, A, 3) white-light response
        mu_w = np.gradient(cos_o)  # quadrature weights over μ on the table's own samples
        weights = np.abs(mu_w) * 2.0 * cos_o
        f_avg = np.clip(np.einsum("tak,a->tk", albedo / e[None, :, None], weights) / weights.sum(), 0.0, 1.0)
        scale = np.moveaxis(brdf.multiscatter_scale(cos_o, material.roughness, f_avg), 0, 1)  # (T, A, 3)
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
    spd = np.asarray(material.base_color) @ rgb_spaces.rgb_basis(grid, material.colour_space)
    return np.interp(wavelengths_nm, grid, spd)


def _diffuse_term(material, l_max, cos_o, r_nodes, nodes_u, g, wl) -> np.ndarray:
    """(T, A, K, 3, 3) contribution of the diffuse base (m = 0 entries only), spectral mode.

    The base sees the light through the film both ways: (1 − R(θo, λ)) ∫ L (1 − R(θi, λ)) cos θi.
    """
    kd = diffuse_kernel(l_max, nodes_u)  # (L+1, U)
    base = base_spectrum(material, wl)  # (W,)
    trans = 1.0 - r_nodes  # (T, U, W)
    z = np.einsum("lu,tuw->tlw", kd, trans)  # (T, L+1, W)
    r_o = np.einsum("au,tuw->taw", u_interpolation_matrix(nodes_u, cos_o), r_nodes)  # (T, A, W)
    zonal = np.einsum("taw,tlw,w,wkc->talkc", 1.0 - r_o, z, base / np.pi, g)
    return _zonal_entries(zonal, l_max)


def _zonal_entries(zonal: np.ndarray, l_max: int) -> np.ndarray:
    """(T, A, L+1, …) per band → (T, A, K, …) with each band at its m = 0 coefficient."""
    out = np.zeros(zonal.shape[:2] + (len(coefficient_indices(l_max)),) + zonal.shape[3:])
    ci = coefficient_indices(l_max).tolist()
    for l in range(l_max + 1):
        out[:, :, ci.index(l * (l + 1))] = zonal[:, :, l]
    return out


def cosine_zonal(l_max: int, n_mu: int = 128) -> np.ndarray:
    """(L+1,): 2π ∫₀¹ μ Y_l0(μ) dμ, the zonal SH of the clamped cosine (the Lambertian kernel)."""
    mu, wmu = unit_gauss_legendre(n_mu)
    dirs = np.stack([np.sqrt(1.0 - mu * mu), np.zeros_like(mu), mu], axis=-1)
    zonal = harmonics.basis(l_max, dirs)[:, [l * (l + 1) for l in range(l_max + 1)]]
    return 2.0 * np.pi * (zonal * (mu * wmu)[:, None]).sum(axis=0)


def layering_weight(material: Material, film_o: np.ndarray, cos_o: np.ndarray) -> np.ndarray:
    """Cycles' weight of the diffuse base under the film at the view angle, (T, A).

    Cycles' Principled BSDF attenuates the layers under its specular layer by
    1 − max_c(albedo_c) (``closure_layering_weight``), where the albedo is the film's reflectance
    per channel at the view angle F_c(θo) (its estimate for thin films) times the multiple-
    scattering "darkening" E(θo) + F_ms (1 − E(θo)) of Multiscatter GGX (Kulla & Conty with the
    film-free dielectric's F_avg; 1 without multiple scattering or at roughness 0).
    ``film_o``: (T, A, 3), the film per channel at ``cos_o``.
    """
    darkening = np.ones((cos_o.size, 1))
    if material.multiscatter != "none" and material.roughness > 0.0:
        e = brdf.ggx_E(float(material.roughness), tuple(np.clip(cos_o, constants.MIN_COS, 1.0).tolist()))
        f_avg = np.broadcast_to(cycles_fresnel_average(material), (3,))
        darkening = e[:, None] * brdf.multiscatter_scale(cos_o, material.roughness, f_avg)
    return np.clip(1.0 - np.max(film_o * darkening[None], axis=-1), 0.0, 1.0)


def _channel_diffuse_term(material, l_max, cos_o, film_o) -> np.ndarray:
    """(T, A, K, 3, 3) diffuse base in the per-channel mode, layered as Cycles' Principled BSDF:
    Lambertian with albedo Base Color × :func:`layering_weight` (no film on the light's way in)."""
    weight = layering_weight(material, film_o, cos_o)  # (T, A)
    base = np.asarray(material.base_color, dtype=float) / np.pi
    zonal = np.einsum("ta,l,k,kc->talkc", weight, cosine_zonal(l_max), base, np.eye(3))
    return _zonal_entries(zonal, l_max)


def channel_film(material: Material, indices, sets, wavelengths_nm, g, u, method: str) -> np.ndarray:
    """The film per colour channel (T, U, 3) at cosines ``u`` for thickness sets (T, L), clamped.

    Cycles' Fourier-space film where its model expresses the material
    (:func:`film_channels.cycles_stack`), else the exact reflectance integrated against the
    channel weights ``g`` (the per-channel :func:`spectral_quadrature`).
    """
    u = np.asarray(u, dtype=float)
    stack = film_channels.cycles_stack(material)
    if stack is not None:
        d = sets[:, 0] if sets.shape[1] else np.zeros(sets.shape[0])
        return film_channels.fourier_reflectance(material, stack, d[:, None], u[None, :])
    if sets.shape[1] == 0:
        r = np.broadcast_to(
            reflectance(indices, [], wavelengths_nm, u), (sets.shape[0], u.size, wavelengths_nm.size)
        )
    else:
        r = chunked_sweep(indices, sets, wavelengths_nm, u, method)
    return clamp_film_rgb(np.einsum("tuw,wkk->tuk", r, g), "per_channel")


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


#: Interpolation tolerance of the per-channel film in u (relative to its peak): Cycles' film
#: reads its sensitivity table with linear interpolation, so R(u) has kinks of ≈ 1e-4 where
#: the OPD crosses a table entry, and Chebyshev interpolation stalls there. 1e-3 keeps the
#: table within the per-channel bake's accuracy (tests/bake/test_bake.py).
U_TOLERANCE_CHANNELS = 1e-3


def contract(kernel: np.ndarray, rg: np.ndarray, wavelengths: int = 0) -> np.ndarray:
    """The table (T, A, K, 3, 3): M[t, a, i] = Σ_k K[a, i, k] RG[t, k], RG (T, U, 9) the film's
    clamped RGB matrices at the u nodes.

    In blocks of thickness rows of ≤ :data:`CONTRACT_CHUNK` multiply-adds (counting the
    ``wavelengths`` that made RG, as the progress plan does), a progress :func:`checkpoint`
    after each; every row is contracted on its own, so the blocks change nothing but the
    checkpoints.
    """
    a, k, u = kernel.shape
    flat = kernel.reshape(a * k, u)
    t = rg.shape[0]
    rows = max(1, CONTRACT_CHUNK // (9 * u * (a * k + wavelengths)))
    out = np.empty((t, a, k, 3, 3))
    for lo in range(0, t, rows):
        block = rg[lo : lo + rows]
        n = block.shape[0]
        out[lo : lo + n] = (
            (flat @ block.transpose(1, 0, 2).reshape(u, -1)).reshape(a, k, n, 3, 3).transpose(2, 0, 1, 3, 4)
        )
        checkpoint()
    return out


def _film_nodes(material, indices, sets, wl, g, method) -> tuple[int, float, np.ndarray, np.ndarray | None]:
    """(u nodes per interval, interpolation error, the film's clamped RGB (T, U, 9) at the nodes,
    the spectral reflectance (T, U, W) at the nodes or None in the per-channel mode)."""
    if material.colour_mode == "per_channel":

        def evaluate(rows, u):
            return channel_film(material, indices, rows, wl, g, u, method)

        u_count, u_err, film_nodes = choose_u_degree(
            indices, sets, wl, method, evaluate=evaluate, tolerance=U_TOLERANCE_CHANNELS
        )
        rg = (film_nodes[..., None] * np.eye(3)).reshape(*film_nodes.shape[:2], 9)  # diagonal
        return u_count, u_err, rg, None
    if sets.shape[1] == 0:
        u_count, u_err = U_DEGREE_LADDER[0], 0.0
        r_nodes = reflectance(indices, [], wl, u_nodes(u_count))[None]
    else:
        u_count, u_err, r_nodes = choose_u_degree(indices, sets, wl, method)
    rg = clamp_film_rgb(r_nodes @ g.reshape(g.shape[0], -1), material.colour_mode)  # (T, U, 9)
    return u_count, u_err, rg, r_nodes


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
        per_channel = material.colour_mode == "per_channel"
        phases.start("planning", "planning", expected=1)
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
        u_count, u_err, rg, r_nodes = _film_nodes(material, indices, sets, wl, g, method)
        t2 = time.perf_counter()
        phases.start("kernel", "microfacet kernel", expected=2 * p.view_samples)
        kernel = microfacet_kernel(float(material.roughness), p.sh_order, p.view_samples, u_count)
        t3 = time.perf_counter()
        a, k, u = kernel.shape
        t = rg.shape[0]
        diffuse_blocks = (
            row_blocks(t, 9 * a * (p.sh_order + 1) * wl.size)
            if material.base_color is not None and not per_channel
            else []
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
            + (len(diffuse_blocks) if not per_channel or material.base_color is None else 1),
        )
        data = contract(kernel, rg, g.shape[0])
        cos_o = view_cosines(p.view_samples)
        data = apply_multiscatter(data, material, cos_o)
        if per_channel and material.base_color is not None:
            film_o = channel_film(material, indices, sets, wl, g, cos_o, method)
            data = data + _channel_diffuse_term(material, p.sh_order, cos_o, film_o)
            checkpoint()
        for rows in diffuse_blocks:
            data[rows] += _diffuse_term(material, p.sh_order, cos_o, r_nodes[rows], u_count, g, wl)
            checkpoint()
        if per_channel:
            data = np.einsum("taikk->taik", data)
        t4 = time.perf_counter()
        phases.done()
    reasons = dict(
        p.reasons,
        u_nodes=f"{u_count} Chebyshev nodes in each of {len(U_EDGES) - 1} graded intervals: "
        f"interpolation error {u_err:.1e} (relative)",
    )
    if per_channel:
        reasons["colour_pipeline"] = (
            "Cycles' Fourier-space film (Airy series to m = 3, per-channel sensitivities)"
            if film_channels.cycles_stack(material) is not None
            else "exact film integrated against Cycles' channel sensitivities (Cycles' film model "
            "cannot express this stack)"
        )
    return BakeResult.planned(
        data,
        material,
        p,
        axis,
        wl,
        u_nodes=u_count,
        reasons=reasons,
        timings_s={"reflectance": t2 - t1, "kernel": t3 - t2, "contract": t4 - t3, "total": t4 - t0},
        node_reflectance=r_nodes,
    )
