"""Working RGB spaces: XYZ(E) ↔ linear RGB, Blender's scene-linear matrix, the channel
sensitivities, and linear RGB → spectrum (Mallett & Yuksel 2019).

XYZ(E) → working RGB is a Bradford adaptation from E to the space's white followed by the
space's XYZ → RGB matrix, so a flat spectrum is RGB (1, 1, 1) in every space. The spaces'
primaries, whites and matrices are colour-science's, shipped as data (:mod:`.colour_tables`);
the spectral side (CMFs, grids, XYZ weights) is :mod:`.spectra`.

References
----------
- Lam, K. M. (1985). Metamerism and colour constancy. PhD thesis, Univ. of Bradford (the
  Bradford cone matrix); used as in Lindbloom, B. *Chromatic Adaptation*, brucelindbloom.com.
- ITU-R BT.709-6 (2015), ITU-R BT.2020-2 (2015); Academy S-2014-004 (ACEScg).
- Mallett, I. & Yuksel, C. (2019). Spectral Primary Decomposition for Rendering with sRGB
  Reflectance. EGSR 2019 (Eurographics Symposium on Rendering), DL-only track.
"""

from __future__ import annotations

import functools

import numpy as np

from .. import _checks
from ..constants import WAVELENGTH_MAX_NM, WAVELENGTH_MIN_NM
from . import colour_tables
from .spectra import (
    cell_edges,
    cmf_cell_integrals,
    cmf_integrals,
    cmf_table,
    integrate_piecewise_linear,
    read_only,
    wavelength_axis,
    xyz_weights,
)

__all__ = [
    "DEFAULT_SPACE",
    "WORKING_SPACES",
    "bradford_matrix",
    "channel_sensitivities",
    "channel_weights",
    "rgb_basis",
    "rgb_basis_roundtrip_matrix",
    "rgb_to_rgb_matrix",
    "rgb_to_xyz_matrix",
    "scene_linear_matrix",
    "xyz_to_rgb_matrix",
]

#: Working-space name (as Blender's OCIO config spells it) → colour-science RGB colourspace.
WORKING_SPACES = {
    "Linear Rec.709": "ITU-R BT.709",
    "Linear Rec.2020": "ITU-R BT.2020",
    "ACEScg": "ACEScg",
}

DEFAULT_SPACE = "Linear Rec.709"


def _space_name(space) -> str:
    return _checks.choice("space", space, set(WORKING_SPACES))


def bradford_matrix(source_white_xyz, target_white_xyz) -> np.ndarray:
    """Bradford (von Kries in the Bradford cone space) adaptation matrix, 3×3.

    XYZ_target = M @ XYZ_source, mapping ``source_white_xyz`` onto ``target_white_xyz``.

    References
    ----------
    Lam (1985); Lindbloom, *Chromatic Adaptation*; colour-science
    ``matrix_chromatic_adaptation_VonKries(..., transform="Bradford")``.
    """
    src = _white("source_white_xyz", source_white_xyz)
    dst = _white("target_white_xyz", target_white_xyz)
    return colour_tables.bradford_adaptation(src, dst)


def _white(name: str, value) -> np.ndarray:
    white = _checks.in_range(name, _checks.finite_array(name, value), lo=0.0, lo_open=True)
    if white.shape != (3,):
        raise ValueError(f"{name} must be an XYZ triple, got shape {white.shape}")
    return white


@functools.cache
def _xyz_to_rgb(space: str) -> np.ndarray:
    whitepoint, xyz_to_rgb = colour_tables.rgb_space(WORKING_SPACES[space])
    adapt = bradford_matrix(np.ones(3), colour_tables.xy_to_xyz(whitepoint))
    return read_only(xyz_to_rgb @ adapt)


def xyz_to_rgb_matrix(space: str = DEFAULT_SPACE) -> np.ndarray:
    """3×3 matrix from XYZ(E) to linear ``space`` RGB: M_XYZ→RGB(space) · Bradford(E → white).

    The space's primaries, white and XYZ → RGB matrix are colour-science's
    ``RGB_COLOURSPACES`` (shipped as data, :mod:`.colour_tables`); E's white is XYZ (1, 1, 1).
    A flat spectrum (XYZ = 1, 1, 1) maps to RGB (1, 1, 1) to rounding.

    Blender's config builds "Linear CIE-XYZ E" with a D65 white of XYZ (0.95047, 1, 1.08883)
    while its Rec.709/2020 matrices use xy (0.3127, 0.3290); the two D65s differ by 2e-4 in Z,
    so Blender's own composite maps E white to (1.00016, 0.99998, 0.99976). We keep the
    self-consistent white (so flat → 1 exactly); the matrices agree with Blender's to 1.3e-4
    relative to their largest entry (tested in ``tests/optics/test_spectra.py``).

    Parameters
    ----------
    space : str
        "Linear Rec.709" (default), "Linear Rec.2020" or "ACEScg".

    Returns
    -------
    ndarray, shape (3, 3)
        rgb = M @ xyz.

    References
    ----------
    ITU-R BT.709-6; ITU-R BT.2020-2; Academy S-2014-004; Lam (1985).
    """
    return _xyz_to_rgb(_space_name(space)).copy()


def rgb_to_xyz_matrix(space: str = DEFAULT_SPACE) -> np.ndarray:
    """3×3 matrix from linear ``space`` RGB to XYZ(E): the inverse of :func:`xyz_to_rgb_matrix`."""
    return np.linalg.inv(_xyz_to_rgb(_space_name(space)))


def rgb_to_rgb_matrix(source: str, target: str) -> np.ndarray:
    """3×3 matrix converting linear ``source`` RGB to linear ``target`` RGB through XYZ(E).

    White (1, 1, 1) stays white (both ends adapt to E the same way).
    """
    return xyz_to_rgb_matrix(target) @ rgb_to_xyz_matrix(source)


@functools.cache
def _xyz_d65_to_rgb(space: str) -> np.ndarray:
    whitepoint, xyz_to_rgb = colour_tables.rgb_space(WORKING_SPACES[space])
    d65 = colour_tables.xy_to_xyz(colour_tables.rgb_space("ITU-R BT.709")[0])
    white = colour_tables.xy_to_xyz(whitepoint)
    adapt = np.eye(3) if np.allclose(white, d65, atol=1e-12) else bradford_matrix(d65, white)
    return read_only(np.asarray(xyz_to_rgb, dtype=np.float64) @ adapt)


def scene_linear_matrix(space: str = DEFAULT_SPACE) -> np.ndarray:
    """3×3 matrix from CIE XYZ (D65-relative) to linear ``space`` RGB, as Blender's colour
    management defines it: what Cycles turns its colour-matching functions into RGB with.

    Blender's OCIO config relates every space to "Linear CIE-XYZ D65" (and to ACES2065-1, its
    ``aces_interchange`` role, through OCIO's built-in ACES AP0 → XYZ D65 Bradford matrix):
    Rec.709 and Rec.2020 use their own XYZ → RGB matrices, with no chromatic adaptation (their
    white is D65); ACEScg adds a Bradford adaptation from D65 to the ACES white. Cycles'
    ``ColorSpaceManager::get_xyz_to_scene_linear_rgb`` derives the matrix from the config's
    ``aces_interchange`` role (or its ``XYZ`` role); the result agrees with this one to 1e-6
    (tests/optics/test_spectra.py, against PyOpenColorIO with Blender's config). Unlike
    :func:`xyz_to_rgb_matrix` there is no adaptation from E: a flat spectrum is not white.
    ``space`` and the result (rgb = M @ xyz, 3×3) are as in :func:`xyz_to_rgb_matrix`.

    References
    ----------
    ITU-R BT.709-6; ITU-R BT.2020-2; Academy S-2014-004; Blender's ``datafiles/colormanagement/
    config.ocio``.
    """
    return _xyz_d65_to_rgb(_space_name(space)).copy()


#: The CMF table padded with a zero 1 nm beyond each end, so that the sensitivities' spline
#: falls to zero there (the table's values at 360 and 830 nm are ≈ 1e-4 and 1e-6 of the peak).
CMF_PAD_NM = 1.0


@functools.cache
def _channel_sensitivities(space: str) -> tuple[np.ndarray, np.ndarray]:
    lam, table = cmf_table()
    lam = np.concatenate(([lam[0] - CMF_PAD_NM], lam, [lam[-1] + CMF_PAD_NM]))
    table = np.concatenate((np.zeros((1, 3)), table, np.zeros((1, 3))))
    return read_only(lam), read_only(table @ _xyz_d65_to_rgb(space).T)


def channel_sensitivities(space: str = DEFAULT_SPACE) -> tuple[np.ndarray, np.ndarray]:
    """The working space's RGB colour-matching functions s_c(λ) = Σ_j M[c, j] x̄_j(λ).

    M is :func:`scene_linear_matrix`; x̄ the CIE 1931 2° table at 1 nm (360–830 nm) with a zero
    :data:`CMF_PAD_NM` beyond each end. A channel's reflectance under Cycles' per-channel film
    model is ∫ R s_c dλ / ∫ s_c dλ: each channel normalised on its own, so white reflects 1.

    Returns
    -------
    wavelengths_nm : ndarray, shape (473,)
    values : ndarray, shape (473, 3)
        Unnormalised sensitivities (they have negative lobes where the space's gamut does not
        reach the spectral locus).
    """
    lam, values = _channel_sensitivities(_space_name(space))
    return lam.copy(), values.copy()


def channel_weights(wavelengths_nm, space: str = DEFAULT_SPACE) -> np.ndarray:
    """Quadrature weights (W, 3) of :func:`channel_sensitivities` on a grid: R_c = R @ w[:, c].

    The sensitivities integrated exactly over each cell (as :func:`xyz_weights`), each column
    divided by the channel's integral over 360–830 nm, so a flat spectrum of 1 gives 1 in every
    channel.
    """
    m = _xyz_d65_to_rgb(_space_name(space))
    table = cmf_cell_integrals(cell_edges(wavelengths_nm)) @ m.T
    return table / (cmf_integrals() @ m.T)


# --------------------------------------------------------------------------------------------
# Linear RGB → spectrum (Mallett & Yuksel 2019)
# --------------------------------------------------------------------------------------------


@functools.lru_cache(maxsize=1)
def _mallett_table() -> tuple[np.ndarray, np.ndarray]:
    """Mallett–Yuksel sRGB basis (r, g, b) extended from 380–780 to 360–830 by holding its ends.

    The table stops at 380/780 nm; the three curves sum to 1 everywhere, so holding the end
    values keeps white flat. The CMFs beyond 380/780 nm are < 3.3e-3 / 4e-5 of their peaks, so
    the extension barely touches XYZ, and the exact correction in :func:`rgb_basis` absorbs it.
    """
    lam, values = colour_tables.mallett2019()
    lam = np.concatenate(([WAVELENGTH_MIN_NM], lam, [WAVELENGTH_MAX_NM]))
    values = np.concatenate((values[:1], values, values[-1:]))
    return read_only(lam), read_only(values)


def _cell_averages(x: np.ndarray, y: np.ndarray, wavelengths_nm: np.ndarray) -> np.ndarray:
    """Average of the piecewise-linear (x, y) over each grid cell; point value for empty cells."""
    edges = cell_edges(wavelengths_nm)
    widths = np.diff(edges)
    integrals = integrate_piecewise_linear(x, y, edges)
    point = np.stack([np.interp(wavelengths_nm, x, y[:, c]) for c in range(y.shape[1])], axis=-1)
    empty = widths <= 0.0
    return np.where(empty[:, None], point, integrals / np.where(empty, 1.0, widths)[:, None])


def _uncorrected_basis(lam: np.ndarray, space: str) -> np.ndarray:
    """Mallett–Yuksel basis as seen from ``space``: B_space = Mᵀ B₇₀₉ with M = space → Rec.709."""
    x, table = _mallett_table()
    b709 = _cell_averages(x, table, lam).T
    return rgb_to_rgb_matrix(space, "Linear Rec.709").T @ b709


def rgb_basis_roundtrip_matrix(wavelengths_nm, space: str = DEFAULT_SPACE) -> np.ndarray:
    """T = B @ Wₓ @ M_XYZ→RGBᵀ for the *uncorrected* basis: rgb ↦ spectrum ↦ XYZ(E) ↦ rgb is rgb @ T.

    Mallett & Yuksel fit their basis so that sRGB reflectances reproduce under D65 with the
    CIE 1931 observer at 5 nm; emission read under E with Bradford adaptation and a different
    grid therefore round-trips only approximately: ``max|T − I|`` is 0.04–0.07 (measured on 16–471
    sample grids for the three working spaces).
    """
    lam = wavelength_axis("wavelengths_nm", wavelengths_nm)
    space = _space_name(space)
    return _uncorrected_basis(lam, space) @ xyz_weights(lam) @ xyz_to_rgb_matrix(space).T


def rgb_basis(wavelengths_nm, space: str = DEFAULT_SPACE) -> np.ndarray:
    """Linear map from working-space RGB to a spectrum: spectrum = rgb @ B, B of shape (3, W).

    Built from the Mallett & Yuksel (2019) sRGB spectral primaries (cell-averaged onto the
    grid, see :func:`cell_edges`). For Rec.2020/ACEScg the RGB is first taken linearly to
    Rec.709 (components may go negative; the map stays linear). Finally B is replaced by
    T⁻¹ B with T = :func:`rgb_basis_roundtrip_matrix`, so that on *this* grid and with the
    default :func:`xyz_weights` quadrature, rgb → spectrum → XYZ(E) → rgb is the identity to
    rounding (≈ 1e-15). T is within 7 % of I, so the correction is small, and because
    white already round-trips (the basis sums to 1), the corrected basis still sums to 1.

    Parameters
    ----------
    wavelengths_nm : array_like, shape (W,)
        Strictly increasing wavelengths, nm, W ≥ 2.
    space : str
        Working space of the RGB, see :data:`WORKING_SPACES`.

    Returns
    -------
    ndarray, shape (3, W)
        Rows: spectra of the unit red, green and blue of ``space`` (dimensionless, relative
        to a flat spectrum of 1 for white).

    References
    ----------
    Mallett & Yuksel (2019), §3–4; colour-science
    ``colour.recovery.MSDS_BASIS_FUNCTIONS_sRGB_MALLETT2019``.
    """
    lam = wavelength_axis("wavelengths_nm", wavelengths_nm)
    space = _space_name(space)
    basis = _uncorrected_basis(lam, space)
    t = basis @ xyz_weights(lam) @ xyz_to_rgb_matrix(space).T
    return np.linalg.solve(t, basis)
