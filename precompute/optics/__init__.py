"""Spectral thin-film optics: reflectance of film stacks with complex, dispersive indices.

Public entry points
-------------------
- :func:`reflectance` — the validated dispatcher (signature fixed by external validation).
- :func:`reflectance_sweep` — the same over a batch of thickness sets, for table baking.
- :func:`band_averaged_reflectance` (in :mod:`.antialias`) — spectral anti-aliasing.

Methods: ``"exact"`` (default: the closed-form Airy film for one layer that is a material,
Rouard's recursion for stacks and for the rest — both exact), ``"airy"``, ``"stack"`` and
``"glassner2000"`` (the paper's eq. 4).
"""

from __future__ import annotations

import numpy as np

from .. import _checks
from .airy import airy_film_reflectance, incoherent_film_reflectance
from .dispersion import (
    FUSED_SILICA,
    CauchyIndex,
    ConstantIndex,
    SellmeierIndex,
    TabulatedIndex,
    is_dispersive,
    resolve_index,
)
from .glassner2000 import glassner_film_reflectance
from .stack import stack_reflectance

__all__ = [
    "FUSED_SILICA",
    "CauchyIndex",
    "ConstantIndex",
    "SellmeierIndex",
    "TabulatedIndex",
    "airy_is_exact",
    "METHODS",
    "POLARIZATIONS",
    "incoherent_film_reflectance",
    "is_dispersive",
    "prepare",
    "reflectance",
    "reflectance_sweep",
]

POLARIZATIONS = ("s", "p", "unpolarized")
METHODS = ("exact", "airy", "stack", "glassner2000")


def prepare(indices, thicknesses_nm, wavelengths_nm, cos_theta, polarization="unpolarized", method="exact"):
    """Validate and normalise the arguments of :func:`reflectance`.

    Returns ``(media, thicknesses, wavelengths, cos_theta)`` with media a list of complex (W,)
    arrays and thicknesses a float (L,) array. Raises ``ValueError`` naming the bad parameter.
    """
    _checks.choice("polarization", polarization, POLARIZATIONS)
    _checks.choice("method", method, METHODS)
    wl = _checks.finite_array("wavelengths_nm", wavelengths_nm)
    if wl.ndim != 1:
        raise ValueError(f"wavelengths_nm must be 1-D, got shape {wl.shape}")
    _checks.in_range("wavelengths_nm", wl, lo=0.0, lo_open=True)
    cos = _checks.finite_array("cos_theta", cos_theta)
    if cos.ndim > 1:
        raise ValueError(f"cos_theta must be a scalar or 1-D, got shape {cos.shape}")
    cos = np.atleast_1d(cos)
    if np.any(np.abs(cos) > 1.0):
        raise ValueError(f"cos_theta must satisfy |cos θ| ≤ 1, got {cos[np.abs(cos) > 1][0]!r}")
    if np.any(cos < 0.0):
        raise ValueError(
            f"cos_theta must be ≥ 0 (light arrives from the ambient side), got {cos[cos < 0][0]!r}"
        )
    if isinstance(indices, (str, bytes)) or not hasattr(indices, "__len__"):
        raise ValueError(
            f"indices must be a sequence of media [ambient, layers…, substrate], got {indices!r}"
        )
    if len(indices) < 2:
        raise ValueError(f"indices needs at least an ambient and a substrate, got {len(indices)} media")
    media = [resolve_index(f"indices[{i}]", value, wl) for i, value in enumerate(indices)]
    if np.any(media[0].imag != 0):
        raise ValueError(
            "indices[0] (the ambient) must be non-absorbing (k = 0) for an incidence angle to exist"
        )
    d = np.atleast_1d(np.asarray(thicknesses_nm if thicknesses_nm is not None else [], dtype=float))
    if d.ndim != 1 or d.shape[0] != len(media) - 2:
        raise ValueError(
            f"thicknesses_nm needs one value per layer: {len(media) - 2} for {len(media)} media, "
            f"got shape {d.shape}"
        )
    if d.size:
        _checks.finite_array("thicknesses_nm", d)
        _checks.in_range("thicknesses_nm", d, lo=0.0)
    if method in ("airy", "glassner2000") and len(media) != 3:
        raise ValueError(f"method {method!r} models a single film: indices needs 3 media, got {len(media)}")
    return media, d, wl, cos


def airy_is_exact(film) -> bool:
    """Whether the Airy sum's real form (:mod:`.airy`) is exact for a film of complex index
    ``film`` (W,): where it is a material at every wavelength, n ≥ 1 or k ≥ 1 (a metal's n < 1
    comes with k > 1). Below both, the form takes ρ₁² + a² − 2ρ₁a over a vanishing 1 − ρ₁²a² at
    grazing incidence: a film of 0.08 between two media of 1 at 89.99° (p) gives 1.1e-5 where
    the stack and tmm give ≈ 1e-20 (tests/optics/test_optics.py)."""
    n = np.asarray(film)
    return bool(np.all((n.real >= 1.0) | (n.imag >= 1.0)))


def _dispatch(media, thicknesses, wl, cos, polarization, method):
    """Evaluate on already validated inputs; thicknesses is a list of per-layer arrays."""
    if method == "glassner2000":
        return glassner_film_reflectance(media, thicknesses[0], wl, cos, polarization)
    if method == "stack":
        return stack_reflectance(media, thicknesses, wl, cos, polarization)
    if len(media) == 3 and (method == "airy" or airy_is_exact(media[1])):
        return airy_film_reflectance(media, thicknesses[0], wl, cos, polarization)
    return stack_reflectance(media, thicknesses, wl, cos, polarization)


def reflectance(
    indices, thicknesses_nm, wavelengths_nm, cos_theta, polarization="unpolarized", method="exact"
):
    """Specular reflectance of a film stack, shape (len(cos_theta), len(wavelengths_nm)).

    Parameters
    ----------
    indices : sequence
        Media from the ambient to the substrate. Each is a real or complex scalar N = n + ik
        (k ≥ 0), an array over ``wavelengths_nm``, or a dispersion model (``.index(λ)``).
        The ambient must be non-absorbing.
    thicknesses_nm : sequence of float, nm
        One thickness d ≥ 0 per layer (``len(indices) − 2`` values; empty for a bare interface).
    wavelengths_nm : array_like, shape (W,), nm
    cos_theta : array_like, shape (A,)
        Incidence cosines in the ambient, 0 (grazing) … 1 (normal).
    polarization : {"s", "p", "unpolarized"}
    method : {"exact", "airy", "stack", "glassner2000"}
        "exact" uses the Airy closed form for one film and Rouard's recursion otherwise.

    Returns
    -------
    ndarray, float64, shape (A, W)
        Power reflectance. Lossless stacks give values in [0, 1]. A layer of thickness exactly
        0 is removed, so it equals the bare interface exactly.
    """
    media, d, wl, cos = prepare(indices, thicknesses_nm, wavelengths_nm, cos_theta, polarization, method)
    if method == "exact":
        keep = [i for i in range(d.size) if d[i] != 0.0]
        media = [media[0]] + [media[i + 1] for i in keep] + [media[-1]]
        d = d[keep]
        if not d.size:
            return stack_reflectance(media, [], wl, cos, polarization)
    return _dispatch(media, list(d), wl, cos, polarization, method)


def reflectance_sweep(
    indices, thickness_sets_nm, wavelengths_nm, cos_theta, polarization="unpolarized", method="exact"
):
    """Reflectance for a batch of thickness sets, shape (T, len(cos_theta), len(wavelengths_nm)).

    ``thickness_sets_nm`` has shape (T, L): row t gives every layer's thickness for entry t
    (e.g. one film swept over T thicknesses is shape (T, 1)). Media are resolved once.
    """
    sets = _checks.finite_array("thickness_sets_nm", thickness_sets_nm)
    if sets.ndim == 1:
        sets = sets[:, None]
    if sets.ndim != 2:
        raise ValueError(f"thickness_sets_nm must have shape (T, layers), got {sets.shape}")
    _checks.in_range("thickness_sets_nm", sets, lo=0.0)
    media, _, wl, cos = prepare(indices, sets[0], wavelengths_nm, cos_theta, polarization, method)
    thicknesses = [sets[:, j, None, None] for j in range(sets.shape[1])]
    if not thicknesses:
        return np.broadcast_to(
            stack_reflectance(media, [], wl, cos, polarization), (sets.shape[0], cos.size, wl.size)
        )
    return _dispatch(media, thicknesses, wl, cos, polarization, method)
