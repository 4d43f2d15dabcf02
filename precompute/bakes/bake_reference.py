"""The brute-force reference bake: the exact film at every quadrature node, no factorisation.

:func:`bake_reference` uses the same plan and quadrature nodes as :func:`.bake.bake`, so the
two differ only by the factorisation (tests/bake/test_bake.py checks the difference;
benchmarks/bake_speed.py times both). Slow by design; never used by the product's draw.
"""

from __future__ import annotations

import time

import numpy as np

from .. import brdf
from ..materials.material import Material
from ..optics import reflectance
from ..sh import harmonics
from .bake import (
    BakeResult,
    _channel_diffuse_term,
    _method,
    apply_multiscatter,
    base_spectrum,
    channel_film,
    clamp_film_rgb,
    spectral_quadrature,
)
from .kernel import N_PHI, N_THETA, coefficient_indices, transfer_samples, view_cosines
from .planner import active_stack, plan, table_material

__all__ = ["bake_reference"]


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
        zon = harmonics.basis(p.sh_order, np.stack([np.sqrt(1 - mu * mu), 0 * mu, mu], -1))
    per_channel = material.colour_mode == "per_channel"
    out = np.zeros((sets.shape[0], cos_os.size, len(ci), 3, 3))
    diffuse = np.zeros_like(out)
    if per_channel and base is not None:
        film_o = channel_film(material, indices, sets, wl, g, cos_os, method)
        diffuse = _channel_diffuse_term(material, p.sh_order, cos_os, film_o)
    for t, row in enumerate(sets):
        for a, cos_o in enumerate(cos_os):
            u, ty = transfer_samples(float(cos_o), alpha, p.sh_order, n_theta, n_phi)
            if per_channel:  # the film per channel, exact at every node
                rgb = channel_film(material, indices, row[None], wl, g, u, method)[0][..., None] * np.eye(3)
                out[t, a] = np.einsum("ni,nkc->ikc", ty, rgb)
                continue
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
    if per_channel:
        out = np.einsum("taikk->taik", out)
    return BakeResult.planned(
        out,
        material,
        p,
        axis,
        wl,
        u_nodes=0,
        reasons=p.reasons,
        timings_s={"total": time.perf_counter() - t0},
    )
