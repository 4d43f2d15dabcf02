"""A single film per colour channel in Fourier space: Belcour & Barla (2017), as Cycles uses it.

For one film (ambient η₁ | film η₂, thickness d | substrate N₃) and one polarisation, the Airy
sum of the reflected intensity is a cosine series in the round-trip phase (Belcour & Barla
2017, eq. 10):

    R(λ) = C₀ + Σ_{m≥1} 2 C_m cos(m (2π·OPD/λ + φ)),
    C₀ = R₁₂ + R_s,   C_m = (R_s − T₁₂₁) (R₁₂ R₂₃)^{m/2},   R_s = T₁₂₁² R₂₃ / (1 − R₁₂ R₂₃),

with T₁₂₁ = 1 − R₁₂, OPD = 2 η₂ d cos θ₂ the optical path difference and φ the phase of
r₂₁ r₂₃ (the two reflections of one round trip). When the Fresnel terms do not depend on λ,
a channel of sensitivity s(λ) integrates each term in closed form through the Fourier
transform of s over frequency f = 1/λ:

    ∫ R s dλ / ∫ s dλ = C₀ + Σ_m 2 C_m Re(e^{imφ} S*(m·OPD)),   S(t) = ∫ s e^{−2πi f t} dλ / ∫ s dλ.

:class:`FourierSensitivity` tabulates S(t) for three channels (uniform samples in f with the
Jacobian dλ = df/f², an FFT, :data:`TABLE_SIZE` entries up to :data:`OPD_MAX_NM`, linearly
interpolated, clamped beyond); :func:`film_reflectance` sums the series to
:data:`AIRY_ORDERS` and averages the polarisations. The bottom interface is a dielectric, a
conductor (complex N₃) or a conductor whose reflectance follows the F82-tint model
(:func:`fresnel_f82`, with the phase of the complex index): the three cases of Blender's
Principled and Metallic BSDFs.

References
----------
- Belcour, L. & Barla, P. (2017). A practical extension to microfacet theory for the modeling
  of varying iridescence. ACM TOG 36(4), §4 and eq. (10).
- Kutz, A. et al. (2021). Novel aspects of the Adobe Standard Material (the F82-tint model).
- Blender's Cycles, ``kernel/closure/bsdf_util.h`` (fresnel_iridescence) and
  ``scene/shader.cpp`` (compute_thin_film_table): the method's parameters matched here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .fresnel import normal_wavenumber, r_p, r_s

__all__ = [
    "AIRY_ORDERS",
    "BLEND_BELOW_NM",
    "CUTOFF_NM",
    "OPD_MAX_NM",
    "TABLE_SIZE",
    "FilmStack",
    "FourierSensitivity",
    "airy_series",
    "bare_reflectance",
    "film_reflectance",
    "fresnel_f82",
    "natural_cubic_spline",
]

#: Orders of the Airy series kept: Cycles truncates after m = 3 ("higher differences have barely
#: any impact"; they do for strongly reflecting interfaces, e.g. a film on a metal).
AIRY_ORDERS = 3
#: Complex entries of the sensitivity table (Cycles' THIN_FILM_TABLE_SIZE).
TABLE_SIZE = 512
#: OPD of the table's last entry, nm: the lookup maps 2π·OPD/60 µm onto [0, 1], so the table
#: ends at 60 µm / 2π ≈ 9.55 µm — the Nyquist limit of its frequency sampling. Longer paths
#: read the last entry (a thick film's higher orders are incoherent there anyway).
OPD_MAX_NM = 60000.0 / (2.0 * np.pi)
#: Real samples in frequency: 2 (TABLE_SIZE − 1), whose real FFT has TABLE_SIZE entries.
FREQUENCY_SAMPLES = 2 * (TABLE_SIZE - 1)
#: Films at most this thick (nm) are no film: the bare interface (Cycles' thin-film cutoff).
CUTOFF_NM = 0.1
#: Below this thickness (nm) the film's index is blended toward the ambient's with a smoothstep
#: of d / 1 nm: the wave-optics sum no longer applies to sub-nanometre films.
BLEND_BELOW_NM = 1.0
#: cos θ of the F82 angle (θ ≈ 81.8°) of the F82-tint model.
F82_COS = 1.0 / 7.0


# ----------------------------------------------------------------------------------------------
# The channel sensitivities in Fourier space
# ----------------------------------------------------------------------------------------------
def natural_cubic_spline(x: np.ndarray, y: np.ndarray):
    """The natural cubic spline through (x, y) (zero second derivative at the ends), as a function
    evaluating it at any points (NaN outside [x₀, x_last]); ``y`` of shape (N, C).

    Second derivatives M from the tridiagonal system h_{i−1} M_{i−1} + 2(h_{i−1} + h_i) M_i +
    h_i M_{i+1} = 6 (Δy_i/h_i − Δy_{i−1}/h_{i−1}) (de Boor, *A Practical Guide to Splines*, ch. IV).
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    h = np.diff(x)
    n = x.size
    a = np.zeros((n, n))
    rhs = np.zeros((n,) + y.shape[1:])
    a[0, 0] = a[-1, -1] = 1.0
    i = np.arange(1, n - 1)
    a[i, i - 1] = h[:-1]
    a[i, i] = 2.0 * (h[:-1] + h[1:])
    a[i, i + 1] = h[1:]
    slope = np.diff(y, axis=0) / h[:, None]
    rhs[1:-1] = 6.0 * (slope[1:] - slope[:-1])
    m = np.linalg.solve(a, rhs)

    def evaluate(points):
        p = np.asarray(points, dtype=float)
        k = np.clip(np.searchsorted(x, p, side="right") - 1, 0, n - 2)
        t0, t1 = (p - x[k])[..., None], (x[k + 1] - p)[..., None]
        hk = h[k][..., None]
        out = (
            m[k] * t1**3 / (6 * hk)
            + m[k + 1] * t0**3 / (6 * hk)
            + (y[k] / hk - m[k] * hk / 6) * t1
            + (y[k + 1] / hk - m[k + 1] * hk / 6) * t0
        )
        outside = (p < x[0]) | (p > x[-1])
        return np.where(outside[..., None], np.nan, out)

    return evaluate


@dataclass(frozen=True)
class FourierSensitivity:
    """S_c(t) = ∫ s_c e^{−2πi t/λ} dλ / ∫ s_c dλ of three channel sensitivities, tabulated in t.

    ``table``: complex (TABLE_SIZE, 3), entry j at OPD t_j = j · OPD_MAX_NM / (TABLE_SIZE − 1);
    entry 0 is 1 in every channel (each channel normalised so that white reflects 1).
    """

    table: np.ndarray

    @classmethod
    def from_sensitivities(cls, wavelengths_nm, values) -> FourierSensitivity:
        """Tabulate channels given on a wavelength grid (values (W, 3), zero outside the grid).

        The sensitivities are interpolated by a natural cubic spline, sampled at
        FREQUENCY_SAMPLES uniform frequencies f_n = n Δf (Δf = 1 / (2 OPD_MAX_NM), so the table's
        last entry is the Nyquist limit) with the Jacobian dλ = df / f², and Fourier-transformed
        (a real FFT: entry j is the sum at t_j = j / (N Δf)).
        """
        spline = natural_cubic_spline(wavelengths_nm, values)
        df = 1.0 / (2.0 * OPD_MAX_NM)  # nm⁻¹
        f = np.arange(FREQUENCY_SAMPLES) * df
        wl = np.where(f > 0.0, 1.0 / np.where(f > 0.0, f, 1.0), -1.0)  # f = 0: no wavelength
        samples = np.nan_to_num(spline(wl)) / np.where(f > 0.0, f * f, np.inf)[:, None]
        spectrum = np.fft.rfft(samples, axis=0)  # (TABLE_SIZE, 3)
        table = spectrum / spectrum[0].real
        table.setflags(write=False)
        return cls(table)

    def __call__(self, opd_nm) -> np.ndarray:
        """S(t) at optical path differences ``opd_nm`` (any shape) → complex (…, 3), linear in t."""
        x = np.clip(np.asarray(opd_nm, dtype=float) / OPD_MAX_NM, 0.0, 1.0) * (TABLE_SIZE - 1)
        j = np.minimum(x.astype(int), TABLE_SIZE - 1)
        j1 = np.minimum(j + 1, TABLE_SIZE - 1)
        t = (x - j)[..., None]
        return (1.0 - t) * self.table[j] + t * self.table[j1]


# ----------------------------------------------------------------------------------------------
# The interfaces
# ----------------------------------------------------------------------------------------------
def fresnel_f82(cos_i, f0, f82) -> np.ndarray:
    """The F82 model: Schlick's F₀ + (1 − F₀)(1 − μ)⁵ minus b μ (1 − μ)⁶, clamped to [0, 1].

    b is chosen so that the model equals ``f82`` at μ = 1/7 (Kutz et al. 2021, "F82"):
    b = (Schlick(F₀, 1/7) − F82) · 7 / (6/7)⁶. Broadcasting.
    """
    mu = np.asarray(cos_i, dtype=float)
    f0 = np.asarray(f0, dtype=float)
    s82 = 1.0 - F82_COS
    b = (f0 + (1.0 - f0) * s82**5 - np.asarray(f82, dtype=float)) / (F82_COS * s82**6)
    s = np.clip(1.0 - mu, 0.0, 1.0)
    return np.clip(f0 + (1.0 - f0) * s**5 - b * mu * s**6, 0.0, 1.0)


@dataclass(frozen=True)
class FilmStack:
    """One film on a substrate, per colour channel (arrays broadcast against each other).

    ``ambient``, ``film``: real indices; ``substrate``: complex index N₃ = n + ik (k ≥ 0) per
    channel; ``f82``: None, or the F82-model reflectance at cos θ = 1/7 from the ambient per
    channel — then the substrate's reflectance follows the F82 model (its F₀ from N₃ relative
    to the film) and only the phase comes from N₃ (Blender's metallic Principled BSDF).
    """

    ambient: float
    film: float
    substrate: np.ndarray
    f82: np.ndarray | None = None


def _interfaces(stack: FilmStack, cos1, thickness_nm):
    """R₁₂, R₂₃ and the round-trip phasor e^{iφ} (…, C, 2: channel, then s and p), the OPD (…, C)
    and where the film reflects everything (…, C: total internal reflection), for the broadcast
    of the inputs; C is the substrate's channel count (1 for one index)."""
    cos1 = np.asarray(cos1, dtype=float)[..., None]
    d = np.asarray(thickness_nm, dtype=float)[..., None]
    eta1 = float(stack.ambient)
    film = np.where(
        d < BLEND_BELOW_NM,
        eta1 + (stack.film - eta1) * _smoothstep(d / BLEND_BELOW_NM),
        float(stack.film),
    )
    n3 = np.asarray(stack.substrate, dtype=complex)
    s2 = eta1 * eta1 * (1.0 - cos1 * cos1)
    q1 = eta1 * cos1 + 0j
    q2 = normal_wavenumber(film + 0j, s2)
    q3 = normal_wavenumber(n3, s2)
    tir = q2.imag > 0.0  # the film's wave is evanescent: the top interface reflects everything
    amb, film_c = eta1 + 0j, film + 0j
    r12 = np.stack([r_s(q1, q2), r_p(q1, q2, amb, film_c)], axis=-1)
    r23 = np.stack([r_s(q2, q3), r_p(q2, q3, film_c, n3)], axis=-1)
    R12 = np.abs(r12) ** 2
    R23 = np.abs(r23) ** 2
    dielectric = np.all(n3.imag == 0.0) if stack.f82 is None else False
    if dielectric:
        tir = tir | (q3.imag > 0.0)  # …or the bottom one does (a dielectric substrate)
    if stack.f82 is not None:
        rel = n3 / film
        f0 = (np.abs(rel - 1.0) ** 2) / (np.abs(rel + 1.0) ** 2)
        R23 = np.broadcast_to(fresnel_f82(q2.real / film, f0, stack.f82)[..., None], R23.shape)
    pair = -r12 * r23  # r₂₁ r₂₃ with r₂₁ = −r₁₂
    size = np.abs(pair)
    phasor = np.where(size > 0.0, pair / np.where(size > 0.0, size, 1.0), 1.0 + 0j)
    opd = 2.0 * d * q2.real  # 2 η₂ d cos θ₂
    return R12, R23, phasor, opd, tir


def _smoothstep(x):
    t = np.clip(x, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def airy_series(R12, R23, phasor, terms, orders: int = AIRY_ORDERS):
    """C₀ + Σ_{m=1}^{orders} 2 C_m Re(e^{imφ} · terms(m)) for one polarisation (module docstring).

    ``terms(m)`` gives the m-th harmonic's spectral factor: conj S(m·OPD) of a channel, or
    e^{im·2π·OPD/λ} at one wavelength (then ``orders`` → ∞ is the exact Airy sum).
    """
    T121 = 1.0 - R12
    R123 = R12 * R23
    rs = T121 * T121 * R23 / np.maximum(1.0 - R123, 1e-300)
    out = R12 + rs
    c = rs - T121
    root = np.sqrt(R123)
    power = np.ones_like(phasor)
    for m in range(1, orders + 1):
        c = c * root
        power = power * phasor
        out = out + 2.0 * c * np.real(power * terms(m))
    return out


def film_reflectance(
    stack: FilmStack, cos_theta, thickness_nm, sensitivity: FourierSensitivity, orders: int = AIRY_ORDERS
) -> np.ndarray:
    """The film's reflectance per channel, (…, 3): the series to ``orders`` in Fourier space,
    the polarisations averaged and the result clamped to [0, 1] (Cycles' ``saturate``).

    ``cos_theta`` (incidence cosine in the ambient) and ``thickness_nm`` broadcast; the stack's
    per-channel substrate (and F82) broadcast against the channel axis. Films of at most
    :data:`CUTOFF_NM` are the bare interface (:func:`bare_reflectance`); total internal reflection
    at either interface of a dielectric film reflects everything.
    """
    cos1 = np.asarray(cos_theta, dtype=float)
    d = np.asarray(thickness_nm, dtype=float)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):  # TIR rows: replaced below
        R12, R23, phasor, opd, tir = _interfaces(stack, cos1, d)
    path = opd[..., 0]  # the OPD does not depend on the channel
    total = 0.0
    with np.errstate(over="ignore", invalid="ignore"):
        for pol in (0, 1):
            total = total + 0.5 * airy_series(
                R12[..., pol],
                R23[..., pol],
                phasor[..., pol],
                lambda m: np.conj(sensitivity(m * path)),
                orders,
            )
    film = np.where(tir, 1.0, total)
    out = np.where((d > CUTOFF_NM)[..., None], film, bare_reflectance(stack, cos1))
    return np.clip(out, 0.0, 1.0)


def bare_reflectance(stack: FilmStack, cos_theta) -> np.ndarray:
    """The substrate without a film, per channel (…, 3): the F82 model when ``stack.f82`` is set,
    else the unpolarised Fresnel reflectance from the ambient."""
    cos1 = np.asarray(cos_theta, dtype=float)[..., None]
    n3 = np.asarray(stack.substrate, dtype=complex)
    eta1 = float(stack.ambient)
    if stack.f82 is not None:
        rel = n3 / eta1
        f0 = np.abs(rel - 1.0) ** 2 / np.abs(rel + 1.0) ** 2
        return fresnel_f82(cos1, f0, stack.f82)
    s2 = eta1 * eta1 * (1.0 - cos1 * cos1)
    q1 = eta1 * cos1 + 0j
    q3 = normal_wavenumber(n3, s2)
    amb = eta1 + 0j
    return 0.5 * (np.abs(r_s(q1, q3)) ** 2 + np.abs(r_p(q1, q3, amb, n3)) ** 2)
