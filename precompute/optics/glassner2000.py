"""The paper's eq. 4: Glassner's two-beam approximation of a thin film.

Lindsay & Agu (2005) eq. 4, from Glassner (2000):  I(λ) = 4 R_f sin²(2π η d cosθ_t / λ),
where R_f is the Fresnel reflectance of the ambient/film interface and θ_t the refraction angle
inside the film. It keeps only the first two reflected beams and assumes the film sits in the
same medium on both sides (r₁₂ = −r₀₁), so it ignores the substrate and multiple reflections.
Kept as a named model for comparison with the exact optics.

References
----------
- Glassner, A. (2000). Soap Bubbles: Part 2. IEEE CG&A 20(6), 99–109.
- Lindsay, C. & Agu, E. (2005). Spherical Harmonic Lighting of Wavelength-Dependent Phenomena.
  Eurographics 2005 short papers, eq. (4).
"""

from __future__ import annotations

import numpy as np

from .fresnel import normal_wavenumber
from .stack import interface_amplitudes


def glassner_film_reflectance(media, thickness, wavelengths_nm, cos_theta, polarization: str) -> np.ndarray:
    """4 R_f sin²(δ), δ = 2π Re(q₁) d / λ; the substrate (media[2]) is ignored by construction.

    Not bounded by 1 when R_f > 1/4 — a property of the approximation, not a bug.
    """
    if polarization == "unpolarized":
        return 0.5 * (
            glassner_film_reflectance(media, thickness, wavelengths_nm, cos_theta, "s")
            + glassner_film_reflectance(media, thickness, wavelengths_nm, cos_theta, "p")
        )
    n0, n1 = media[0][None, :], media[1][None, :]
    cos0 = cos_theta[:, None]
    s2 = n0.real**2 * (1.0 - cos0 * cos0)
    q0 = n0.real * cos0 + 0j
    q1 = normal_wavenumber(n1, s2)
    r_f = np.abs(interface_amplitudes(n0, n1, q0, q1, polarization)) ** 2
    delta = (2.0 * np.pi / wavelengths_nm) * q1.real * np.asarray(thickness)
    return 4.0 * r_f * np.sin(delta) ** 2
