"""Single thin film in closed form (Airy summation), in real arithmetic as the shader uses it.

For one film (ambient 0, film 1, substrate 2) write the interface amplitudes in polar form,
r₀₁ = ρ₁ e^{iφ₁}, r₁₂ = ρ₂ e^{iφ₂}, and the round-trip factor e^{2iδ} = e^{−2 Im δ} e^{2i Re δ}
with δ = 2π q₁ d / λ. With a = ρ₂ e^{−2 Im δ} the Airy sum gives

    R = (ρ₁² + a² + 2ρ₁a cos(2 Re δ + φ₂ − φ₁)) / (1 + ρ₁²a² + 2ρ₁a cos(2 Re δ + φ₂ + φ₁)).

References
----------
- Airy, G. B. (1833). Phil. Mag. 2, 20–30.
- Born, M. & Wolf, E. (1999). *Principles of Optics*, 7th ed., §7.6.1, eq. (14)–(16).
- Belcour, L. & Barla, P. (2017). A practical extension to microfacet theory for the modeling
  of varying iridescence. ACM TOG 36(4), eq. (2) — the same form, used in real time.
"""

from __future__ import annotations

import numpy as np

from .fresnel import normal_wavenumber
from .stack import interface_amplitudes


def _airy_terms(r01, r12) -> tuple[np.ndarray, ...]:
    """The thickness-free factors of the Airy sum at one polarisation, each shaped like r₀₁:
    (ρ₁², ρ₂², conj(r₀₁) r₁₂ and r₀₁ r₁₂ as real and imaginary parts)."""
    p = np.conj(r01) * r12
    q = r01 * r12
    return np.abs(r01) ** 2, np.abs(r12) ** 2, p.real, p.imag, q.real, q.imag


def _airy_intensity(terms, phasor) -> np.ndarray:
    """Airy sum R = |r₀₁ + x|² / |1 + r₀₁ x|² with x = r₁₂ z, z = e^{2iδ}.

    The module docstring's real form with the moduli expanded: |r₀₁ + x|² = ρ₁² + ρ₂²|z|² +
    2 Re(r̄₀₁ r₁₂ z) and |1 + r₀₁ x|² = 1 + ρ₁²ρ₂²|z|² + 2 Re(r₀₁ r₁₂ z). The factors of r
    (``terms``, :func:`_airy_terms`) do not depend on the thickness, so a sweep over T
    thicknesses needs only z per element (``phasor``: its real part, its imaginary part or None
    where every r is real and Im z drops out — a dielectric film on a dielectric without total
    reflection, the common case — and |z|² or None for a lossless film, |z| = 1; shared by both
    polarisations) and a few in-place products: 4–8× less than a complex exponential and two
    complex moduli.
    """
    rho1, rho2, pr, pi, qr, qi = terms
    zr, zi, z2 = phasor
    shape = np.broadcast_shapes(np.shape(zr), np.shape(pr))
    num, den = np.empty(shape), np.empty(shape)
    tmp = np.empty(shape) if zi is not None or z2 is not None else None
    for out, re, im, one, a2 in ((num, pr, pi, rho1, rho2), (den, qr, qi, 1.0, rho1 * rho2)):
        np.multiply(zr, 2.0 * re, out=out)
        if zi is not None:
            np.multiply(zi, 2.0 * im, out=tmp)
            out -= tmp
        if z2 is None:
            out += one + a2
        else:
            np.multiply(z2, a2, out=tmp)
            out += tmp
            out += one
    num /= den
    # Passive media reflect at most what arrives; near ρ₁ = a = 1 (grazing, thick film) the
    # ratio of two nearly equal sums rounds up to ~1e-10 above 1, so clamp.
    return np.clip(num, 0.0, 1.0, out=num)


#: Fewest evenly spaced thickness rows for which :func:`_phasor` steps the phase by recurrence.
RECURRENCE_MIN_ROWS = 3


def _phasor(
    twice_k, thickness, imaginary: bool = True
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """z = e^{i 2k d} for the round-trip wavenumber ``twice_k`` (2k = 4π q₁/λ, complex in an
    absorbing or evanescent film) and ``thickness`` d, broadcast: (Re z, Im z or None when not
    ``imaginary``, |z|² or None when 2k is real and |z| = 1).

    A sweep's thickness column (T, 1, 1) of evenly spaced rows (a bake's thickness axis) is
    stepped by the recurrence z(d₀ + (t+1)Δ) = z(d₀ + tΔ) · e^{i 2k Δ}: one complex product per
    element instead of a complex exponential (a float64 cosine and sine cost ≈ 36 ns per element
    in numpy without SIMD), with a rounding error that grows by ~1e-16 per row. Anything else is
    evaluated directly (a cosine alone when Im z is not wanted and |z| = 1).
    """
    k = np.asarray(twice_k, dtype=complex)
    d = np.asarray(thickness, dtype=float)
    rows = d.reshape(-1)
    lossless = not np.any(k.imag != 0.0)
    z = None
    if d.ndim == 3 and d.shape[1:] == (1, 1) and rows.size >= RECURRENCE_MIN_ROWS:
        step = np.diff(rows)
        if np.all(np.abs(step - step[0]) <= 1e-12 * max(abs(rows).max(), 1.0)):
            z = np.empty((rows.size,) + k.shape, dtype=complex)
            z[0] = np.exp(1j * k * rows[0])
            turn = np.exp(1j * k * step[0])
            for t in range(1, rows.size):
                np.multiply(z[t - 1], turn, out=z[t])
    if z is None and lossless and not imaginary:
        return np.cos(k.real * d), None, None
    if z is None:
        z = np.exp(1j * (k * d))
    zr = np.ascontiguousarray(z.real)  # unit-stride products
    zi = np.ascontiguousarray(z.imag) if imaginary or not lossless else None
    return zr, zi if imaginary else None, None if lossless else zr * zr + zi * zi


def _film_wavenumbers(media, cos_theta) -> tuple:
    """(n0, n1, n2, q0, q1, q2) of a single film: the three indices (1, W) and their normal
    wavenumbers q = N cos θ in each medium (A, W), from the ambient's cos θ (A,)."""
    n0, n1, n2 = (m[None, :] for m in media)
    cos0 = cos_theta[:, None]
    s2 = n0.real**2 * (1.0 - cos0 * cos0)
    q0 = n0.real * cos0 + 0j
    return n0, n1, n2, q0, normal_wavenumber(n1, s2), normal_wavenumber(n2, s2)


def airy_film_reflectance(media, thickness, wavelengths_nm, cos_theta, polarization: str) -> np.ndarray:
    """Reflectance of a single film, shape broadcast of (…, A, W); polarisation "s"/"p"/"unpolarized"."""
    n0, n1, n2, q0, q1, q2 = _film_wavenumbers(media, cos_theta)
    pols = ("s", "p") if polarization == "unpolarized" else (polarization,)
    terms = [
        _airy_terms(interface_amplitudes(n0, n1, q0, q1, pol), interface_amplitudes(n1, n2, q1, q2, pol))
        for pol in pols
    ]
    imaginary = any(np.any(t[3] != 0.0) or np.any(t[5] != 0.0) for t in terms)
    phasor = _phasor((4.0 * np.pi / wavelengths_nm) * q1, thickness, imaginary)  # z = e^{2iδ}
    total = _airy_intensity(terms[0], phasor)
    for more in terms[1:]:
        total += _airy_intensity(more, phasor)
    return total / len(pols) if len(pols) > 1 else total


def incoherent_film_reflectance(media, wavelengths_nm, cos_theta) -> np.ndarray:
    """Incoherent (thick-film) limit of a lossless single film, unpolarised, shape (A, W).

    Summing intensities instead of amplitudes, per polarisation,
    R = R₀₁ + (1 − R₀₁)² R₁₂ / (1 − R₀₁ R₁₂)   (Heavens 1955, §4.7 for a non-absorbing film),
    which is also the mean of the Airy function over one period of its phase.
    """
    if any(np.any(m.imag != 0) for m in media[:2]):
        raise ValueError("incoherent_film_reflectance needs a lossless ambient and film (k = 0)")
    out = 0.0
    n0, n1, n2, q0, q1, q2 = _film_wavenumbers(media, cos_theta)
    for pol in ("s", "p"):
        r01 = np.abs(interface_amplitudes(n0, n1, q0, q1, pol)) ** 2
        r12 = np.abs(interface_amplitudes(n1, n2, q1, q2, pol)) ** 2
        out = out + 0.5 * (r01 + (1.0 - r01) ** 2 * r12 / np.maximum(1.0 - r01 * r12, 1e-300))
    return out
