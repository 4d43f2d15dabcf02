"""Reflectance of a general multilayer stack by Rouard's recursion (transfer-matrix exact).

The stack is [ambient, layer_1 … layer_L, substrate]. Starting at the substrate, the amplitude
reflection seen from the top of each layer is folded in one interface at a time,

    r_j = (ρ_j + r_{j+1} e^{2iδ}) / (1 + ρ_j r_{j+1} e^{2iδ}),   δ = 2π q d / λ,

which is algebraically identical to the product of 2×2 characteristic matrices (Abelès) but
never forms e^{−iδ}: for absorbing or evanescent layers |e^{2iδ}| ≤ 1, so it cannot overflow
however thick the layer is.

References
----------
- Rouard, P. (1937). Ann. Phys. (Paris) 11, 7, 291–384.
- Heavens, O. S. (1955). *Optical Properties of Thin Solid Films*, ch. 4.
- Byrnes, S. J. (2016). Multilayer optical calculations. arXiv:1603.02720.
"""

from __future__ import annotations

import numpy as np

from .fresnel import normal_wavenumber, r_p, r_s


def interface_amplitudes(n_i, n_t, q_i, q_t, polarization: str) -> np.ndarray:
    """Amplitude reflection ρ for one interface in the requested polarisation ("s" or "p")."""
    if polarization == "s":
        return r_s(q_i, q_t)
    return r_p(q_i, q_t, n_i, n_t)


def stack_amplitude(media, thicknesses, wavelengths_nm, cos_theta, polarization: str) -> np.ndarray:
    """Complex amplitude reflection r of the stack, broadcast over (…, angles, wavelengths).

    Parameters
    ----------
    media : sequence of ndarray, complex, shape (W,)
        Indices from ambient to substrate (already resolved; the ambient is real).
    thicknesses : sequence of ndarray or float, nm
        One per layer, each broadcastable against (A, W) (e.g. shape (T, 1, 1) for a sweep).
    wavelengths_nm : ndarray, shape (W,)
    cos_theta : ndarray, shape (A,)
        Incidence cosines in the ambient.
    polarization : {"s", "p"}
    """
    lam = wavelengths_nm[None, :]
    n0 = media[0].real[None, :]
    cos0 = cos_theta[:, None]
    s2 = n0 * n0 * (1.0 - cos0 * cos0)
    q = [n0 * cos0 + 0j] + [normal_wavenumber(n[None, :], s2) for n in media[1:]]
    n = [m[None, :] for m in media]
    last = len(media) - 1
    r = interface_amplitudes(n[last - 1], n[last], q[last - 1], q[last], polarization)
    for j in range(last - 2, -1, -1):
        rho = interface_amplitudes(n[j], n[j + 1], q[j], q[j + 1], polarization)
        phase = np.exp((4j * np.pi / lam) * q[j + 1] * np.asarray(thicknesses[j]))
        x = r * phase
        r = (rho + x) / (1.0 + rho * x)
    return r


def stack_reflectance(media, thicknesses, wavelengths_nm, cos_theta, polarization: str) -> np.ndarray:
    """Power reflectance |r|² for "s", "p" or "unpolarized" (the mean of the two).

    Clamped to [0, 1]: passive media cannot reflect more than arrives, and rounding in the
    recursion near |r| = 1 (grazing incidence on thick stacks) can exceed 1 by ~1e-10.
    """
    if polarization == "unpolarized":
        rs = stack_amplitude(media, thicknesses, wavelengths_nm, cos_theta, "s")
        rp = stack_amplitude(media, thicknesses, wavelengths_nm, cos_theta, "p")
        return np.clip(0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2), 0.0, 1.0)
    return np.clip(
        np.abs(stack_amplitude(media, thicknesses, wavelengths_nm, cos_theta, polarization)) ** 2, 0.0, 1.0
    )
