"""Fresnel amplitude coefficients at one planar interface, for complex indices.

Everything is written with the normal component of the wave vector, q = N·cosθ, which by
Snell's law is q_j = √(N_j² − (n₀ sinθ₀)²) in every medium j. Using q avoids complex angles
and makes total internal reflection (q imaginary) and absorption (q complex) the same case.

References
----------
- Born, M. & Wolf, E. (1999). *Principles of Optics*, 7th ed., §1.5.2, eqs. (20a, 21a).
- Byrnes, S. J. (2016). Multilayer optical calculations. arXiv:1603.02720, §3 (branch of q).
"""

from __future__ import annotations

import numpy as np


def normal_wavenumber(index: np.ndarray, s2: np.ndarray) -> np.ndarray:
    """q = N cosθ = √(N² − s²) on the branch of a forward wave (Byrnes 2016, §3).

    A forward wave decays or propagates into the medium: Im q > 0, or Im q = 0 and Re q ≥ 0.
    The principal square root already satisfies this for N = n + ik with k ≥ 0, except for a
    signed-zero imaginary part (−0.0) on the branch cut, which the final flip repairs.
    """
    q = np.sqrt(index * index - s2 + 0j)
    return np.where(q.imag < 0, -q, q)


def r_s(q_i: np.ndarray, q_t: np.ndarray) -> np.ndarray:
    """s-polarised amplitude reflection r_s = (q_i − q_t) / (q_i + q_t) (Born & Wolf 1.5 (21a)).

    Identical media (q_i = q_t, including two media at exact grazing incidence) give r = 0.
    """
    same = q_i == q_t
    return np.where(same, 0.0, (q_i - q_t) / np.where(same, 1.0, q_i + q_t))


def r_p(q_i: np.ndarray, q_t: np.ndarray, n_i: np.ndarray, n_t: np.ndarray) -> np.ndarray:
    """p-polarised amplitude reflection (Born & Wolf 1.5 (21a), multiplied through by N_i N_t).

    r_p = (N_t² q_i − N_i² q_t) / (N_t² q_i + N_i² q_t); the sign convention matches ``tmm``
    (r_p = +r_s at normal incidence) and r_ji = −r_ij, which the stack recursion relies on.
    """
    num = n_t * n_t * q_i - n_i * n_i * q_t
    den = n_t * n_t * q_i + n_i * n_i * q_t
    zero = den == 0
    return np.where(zero, 0.0, num / np.where(zero, 1.0, den))


def fresnel_dielectric(cos_i, eta) -> np.ndarray:
    """Unpolarised reflectance of a bare interface, ambient n = 1 into index ``eta`` (real or complex).

    Convenience closed form used by tests and the BRDF; total internal reflection returns 1.
    """
    cos_i = np.asarray(cos_i, dtype=float)
    eta = np.asarray(eta, dtype=complex)
    s2 = 1.0 - cos_i * cos_i
    q_i = cos_i + 0j
    q_t = normal_wavenumber(eta, s2)
    rs = r_s(q_i, q_t)
    rp = r_p(q_i, q_t, np.ones_like(eta), eta)
    return 0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2)
