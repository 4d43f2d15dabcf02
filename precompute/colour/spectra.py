"""Spectral colorimetry: wavelength grids, CIE 1931 CMFs, illuminants, XYZ(E) ↔ working RGB.

Everything here follows ``docs/conventions.md``:

- spectra live on 360–830 nm (the CIE 1931 2° table's range) with the wavelength on the last
  axis; the published tables are read once from :mod:`.colour_tables` (colour-science's
  numbers shipped as data, so nothing here imports colour-science), the arithmetic is on
  plain float64 arrays;
- tristimulus values use an **equal-energy (E) white**: a flat spectrum of 1 has
  X = Y = Z = 1, as Blender's "Linear CIE-XYZ E";
- XYZ(E) → working RGB is a Bradford adaptation from E to the space's white followed by the
  space's XYZ → RGB matrix, so a flat spectrum is RGB (1, 1, 1) in every space.

Quadrature
----------
A sampled spectrum S(λ_i) is read as the average of S over the *cell* of sample i. Cell edges
are the midpoints between samples; the outer edges sit half a spacing beyond the end samples
and are clipped to 360–830 nm (:func:`cell_edges`). For the default grid
(:func:`wavelength_grid`, bin centres) the cells are exactly the bins. The colour-matching
functions are integrated *exactly* over each cell (as the piecewise-linear interpolant of the
1 nm CIE table), so X_c = Σ_i S_i ∫_cell_i c̄ dλ / ∫ c̄ dλ is exact for any spectrum that is
constant on each cell, e.g. a band-averaged one. Each channel is divided by its own CMF area
(:func:`cmf_integrals`): the tabulated areas differ by ≤ 3.3e-4, so the CIE's single
k = 1/∫ȳ would leave a flat spectrum at XYZ (1.00008, 1, 1.00033), not E's (1, 1, 1).

References
----------
- CIE 015:2018 *Colorimetry*, 4th ed., §7 (tristimulus integrals) and Table 1 (2° CMFs).
- Lam, K. M. (1985). Metamerism and colour constancy. PhD thesis, Univ. of Bradford (the
  Bradford cone matrix); used as in Lindbloom, B. *Chromatic Adaptation*, brucelindbloom.com.
- ITU-R BT.709-6 (2015), ITU-R BT.2020-2 (2015); Academy S-2014-004 (ACEScg).
- Mallett, I. & Yuksel, C. (2019). Spectral Primary Decomposition for Rendering with sRGB
  Reflectance. EGSR 2019 (Eurographics Symposium on Rendering), DL-only track.
- Mansencal, T. et al. colour-science 0.4.7 (source of every table used here).
"""

from __future__ import annotations

import functools

import numpy as np

from .. import _checks
from ..constants import WAVELENGTH_MAX_NM, WAVELENGTH_MIN_NM
from . import colour_tables

__all__ = [
    "ILLUMINANTS",
    "WORKING_SPACES",
    "bin_edges",
    "bin_width",
    "bradford_matrix",
    "channel_sensitivities",
    "channel_weights",
    "cell_edges",
    "cell_widths",
    "cmf_cell_integrals",
    "cmf_integrals",
    "cmfs",
    "illuminant_spd",
    "illuminant_table",
    "rgb_basis",
    "rgb_basis_roundtrip_matrix",
    "rgb_to_rgb_matrix",
    "rgb_to_xyz_matrix",
    "scene_linear_matrix",
    "spectrum_to_xyz",
    "wavelength_grid",
    "xyz_to_rgb_matrix",
    "xyz_weights",
]

#: colour-science's name for the observer every integral uses.
CMFS_NAME = "CIE 1931 2 Degree Standard Observer"

#: Spacing (nm) of the aligned CMF table that :func:`cmfs` interpolates. The CIE publishes the
#: 2° observer at 1 nm; linear interpolation in between is the CIE 015 recommendation.
CMF_TABLE_STEP_NM = 1.0

#: Working-space name (as Blender's OCIO config spells it) → colour-science RGB colourspace.
WORKING_SPACES = {
    "Linear Rec.709": "ITU-R BT.709",
    "Linear Rec.2020": "ITU-R BT.2020",
    "ACEScg": "ACEScg",
}

DEFAULT_SPACE = "Linear Rec.709"

#: Illuminants offered by :func:`illuminant_spd` (colour-science's ``SDS_ILLUMINANTS`` keys).
ILLUMINANTS = ("D65", "A", "E", *(f"FL{i}" for i in range(1, 13)))

#: The CIE's older "F1"…"F12" spellings of the fluorescent lamps.
ILLUMINANT_ALIASES = {f"F{i}": f"FL{i}" for i in range(1, 13)}

#: Number of equal bins (1 nm wide) used wherever a grid-independent dense integral is needed
#: (illuminant normalisation). 1 nm is the CMF table's own resolution.
DENSE_BIN_COUNT = int(round((WAVELENGTH_MAX_NM - WAVELENGTH_MIN_NM) / CMF_TABLE_STEP_NM))


# --------------------------------------------------------------------------------------------
# Grids
# --------------------------------------------------------------------------------------------


def bin_width(count: int) -> float:
    """Width (nm) of one of ``count`` equal bins spanning 360–830 nm."""
    count = _checks.positive_int("count", count)
    return (WAVELENGTH_MAX_NM - WAVELENGTH_MIN_NM) / count


def bin_edges(count: int) -> np.ndarray:
    """Edges (nm) of ``count`` equal bins over 360–830 nm, shape (count + 1,)."""
    count = _checks.positive_int("count", count)
    return np.linspace(WAVELENGTH_MIN_NM, WAVELENGTH_MAX_NM, count + 1)


def wavelength_grid(count: int) -> np.ndarray:
    """Default wavelength grid: centres (nm) of ``count`` equal bins over 360–830 nm.

    Parameters
    ----------
    count : int
        Number of bins, ≥ 1.

    Returns
    -------
    ndarray, shape (count,)
        λ_i = 360 + (i + ½)·Δ with Δ = :func:`bin_width` (``count``), in nm.
    """
    edges = bin_edges(count)
    return 0.5 * (edges[:-1] + edges[1:])


def _wavelength_axis(name: str, wavelengths_nm, *, min_count: int = 2) -> np.ndarray:
    """Validate a 1-D, strictly increasing, finite wavelength grid (nm)."""
    lam = _checks.finite_array(name, wavelengths_nm)
    if lam.ndim != 1:
        raise ValueError(f"{name} must be 1-D, got shape {lam.shape}")
    if lam.size < min_count:
        raise ValueError(f"{name} needs at least {min_count} samples, got {lam.size}")
    if np.any(np.diff(lam) <= 0.0):
        raise ValueError(f"{name} must be strictly increasing")
    return lam


def cell_edges(wavelengths_nm) -> np.ndarray:
    """Quadrature cell edges (nm) of a sorted grid, shape (W + 1,).

    Interior edges are the midpoints between neighbouring samples; the outer edges lie half
    the end spacing beyond the end samples. All edges are clipped to 360–830 nm, so a sample
    outside that range gets an empty cell. For :func:`wavelength_grid` these are exactly
    :func:`bin_edges`; for a grid that includes 360 and 830 the end cells are half cells
    (the trapezoid rule).

    Parameters
    ----------
    wavelengths_nm : array_like, shape (W,)
        Strictly increasing wavelengths, nm, W ≥ 2.
    """
    lam = _wavelength_axis("wavelengths_nm", wavelengths_nm)
    mids = 0.5 * (lam[:-1] + lam[1:])
    first = lam[0] - 0.5 * (lam[1] - lam[0])
    last = lam[-1] + 0.5 * (lam[-1] - lam[-2])
    edges = np.concatenate(([first], mids, [last]))
    return np.clip(edges, WAVELENGTH_MIN_NM, WAVELENGTH_MAX_NM)


def cell_widths(wavelengths_nm) -> np.ndarray:
    """Quadrature cell widths (nm) of a sorted grid, shape (W,): ``diff(cell_edges)``."""
    return np.diff(cell_edges(wavelengths_nm))


def _integrate_piecewise_linear(x: np.ndarray, y: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Exact integrals of the piecewise-linear interpolant of (x, y) over consecutive edges.

    The interpolant is zero outside [x₀, x_last]. ``y`` has shape (N, C); returns (E − 1, C).
    Within knot interval k, with t = e − x_k and slope s_k, the primitive is
    C(e) = C(x_k) + y_k t + s_k t² / 2.
    """
    e = np.clip(edges, x[0], x[-1])
    h = np.diff(x)
    slope = np.diff(y, axis=0) / h[:, None]
    trapezoids = 0.5 * h[:, None] * (y[:-1] + y[1:])
    knot_primitive = np.concatenate((np.zeros((1, y.shape[1])), np.cumsum(trapezoids, axis=0)))
    k = np.clip(np.searchsorted(x, e, side="right") - 1, 0, x.size - 2)
    t = (e - x[k])[:, None]
    primitive = knot_primitive[k] + y[k] * t + 0.5 * slope[k] * t * t
    return np.diff(primitive, axis=0)


# --------------------------------------------------------------------------------------------
# Colour-matching functions
# --------------------------------------------------------------------------------------------


def _read_only(arr: np.ndarray) -> np.ndarray:
    arr = np.ascontiguousarray(arr, dtype=np.float64)
    arr.flags.writeable = False
    return arr


@functools.lru_cache(maxsize=1)
def _cmf_table() -> tuple[np.ndarray, np.ndarray]:
    """CIE 1931 2° x̄ȳz̄ aligned to 360–830 nm at 1 nm: (wavelengths (471,), values (471, 3))."""
    source_lam, source = colour_tables.cmfs()  # colour-science's table, shipped as data
    # np.interp rather than SpectralDistribution.align: at the CIE's own 1 nm knots it returns
    # the published values untouched (align's interpolator leaves ±3e-22 where z̄ is 0).
    count = int(round((WAVELENGTH_MAX_NM - WAVELENGTH_MIN_NM) / CMF_TABLE_STEP_NM)) + 1
    lam = np.linspace(WAVELENGTH_MIN_NM, WAVELENGTH_MAX_NM, count)
    values = np.stack([np.interp(lam, source_lam, source[:, c]) for c in range(3)], axis=-1)
    return _read_only(lam), _read_only(values)


def cmfs(wavelengths_nm) -> np.ndarray:
    """CIE 1931 2° colour-matching functions x̄, ȳ, z̄ at arbitrary wavelengths.

    Linear interpolation of the 1 nm CIE table (CIE 015:2018 §7.2.2), zero outside 360–830 nm.

    Parameters
    ----------
    wavelengths_nm : array_like
        Wavelengths, nm, any shape.

    Returns
    -------
    ndarray, shape (..., 3)
        Dimensionless CMF values (ȳ peaks at 1.0 near 555 nm).

    References
    ----------
    CIE 015:2018, Table 1; colour-science ``MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]``.
    """
    lam = _checks.finite_array("wavelengths_nm", wavelengths_nm)
    x, table = _cmf_table()
    return np.stack([np.interp(lam, x, table[:, c], left=0.0, right=0.0) for c in range(3)], axis=-1)


def cmf_cell_integrals(edges_nm) -> np.ndarray:
    """∫ c̄(λ) dλ over each cell [e_i, e_{i+1}] (nm), shape (E − 1, 3).

    Exact integrals of the linearly interpolated 1 nm CIE table, zero outside 360–830 nm.

    Parameters
    ----------
    edges_nm : array_like, shape (E,)
        Non-decreasing cell edges, nm, E ≥ 2.
    """
    edges = _checks.finite_array("edges_nm", edges_nm)
    if edges.ndim != 1 or edges.size < 2:
        raise ValueError(f"edges_nm must be 1-D with at least 2 entries, got shape {edges.shape}")
    if np.any(np.diff(edges) < 0.0):
        raise ValueError("edges_nm must be non-decreasing")
    x, table = _cmf_table()
    return _integrate_piecewise_linear(x, table, edges)


def cmf_integrals() -> np.ndarray:
    """(∫x̄, ∫ȳ, ∫z̄) over 360–830 nm, in nm, shape (3,): the E-white normalisation.

    CIE 1931 is defined with equal areas, but the tabulated 1 nm values give
    (106.8654, 106.8569, 106.8919): x̄ and z̄ exceed ȳ by 7.9e-5 and 3.3e-4 (rounding of the
    table and its 360–830 truncation, CIE 015:2018 §7.2). Dividing each channel by its own
    area makes a flat spectrum exactly XYZ (1, 1, 1), i.e. E's white, as the conventions require.
    """
    return cmf_cell_integrals([WAVELENGTH_MIN_NM, WAVELENGTH_MAX_NM])[0].copy()


# --------------------------------------------------------------------------------------------
# Spectrum → XYZ(E)
# --------------------------------------------------------------------------------------------


def xyz_weights(wavelengths_nm, weights=None) -> np.ndarray:
    """Matrix Wₓ (W, 3) with XYZ(E) = S @ Wₓ for a spectrum S sampled on ``wavelengths_nm``.

    X_c = ∫ S c̄ dλ / ∫ c̄ dλ for c̄ ∈ {x̄, ȳ, z̄}: CIE 015:2018 eq. 7.1 with an equal-energy
    white. CIE uses one constant k = 1/∫ȳ; the tabulated areas differ by ≤ 3.3e-4
    (:func:`cmf_integrals`), so dividing each channel by its own area is the same thing up
    to that table artefact and makes a flat spectrum exactly XYZ (1, 1, 1).

    - ``weights=None``: S_i is the average of S over its cell (:func:`cell_edges`) and
      Wₓ[i] ∝ ∫_cell_i c̄ dλ, integrated exactly (the default, for band-averaged spectra).
    - ``weights`` given: point quadrature Wₓ[i] ∝ c̄(λ_i)·wᵢ with wᵢ in nm (e.g. a Riemann
      sum with the table spacing); the grid then need not be sorted.

    The denominators are Σ_i of the same unnormalised weights — the *same* quadrature — so a
    flat spectrum of 1 gives XYZ = (1, 1, 1) to rounding on any grid. (A grid covering only
    part of 360–830 nm is therefore normalised as if the spectrum continued flat.)

    Parameters
    ----------
    wavelengths_nm : array_like, shape (W,)
        Wavelengths, nm.
    weights : array_like, shape (W,), optional
        Quadrature widths, nm, ≥ 0.

    Returns
    -------
    ndarray, shape (W, 3)
        Dimensionless per-sample weights; each column sums to 1.

    References
    ----------
    CIE 015:2018 §7.1–7.3.
    """
    if weights is None:
        table = cmf_cell_integrals(cell_edges(wavelengths_nm))
    else:
        lam = _checks.finite_array("wavelengths_nm", wavelengths_nm)
        if lam.ndim != 1:
            raise ValueError(f"wavelengths_nm must be 1-D, got shape {lam.shape}")
        w = _checks.in_range("weights", _checks.finite_array("weights", weights), lo=0.0)
        if w.shape != lam.shape:
            raise ValueError(f"weights must have shape {lam.shape} like wavelengths_nm, got {w.shape}")
        table = cmfs(lam) * w[:, None]
    totals = table.sum(axis=0)
    if not np.all(totals > 0.0):
        raise ValueError("wavelengths_nm must overlap 360–830 nm where the CMFs are non-zero")
    return table / totals


def spectrum_to_xyz(spectrum, wavelengths_nm, weights=None) -> np.ndarray:
    """CIE XYZ with an equal-energy white: X_c = ∫ S c̄ dλ / ∫ c̄ dλ (see :func:`xyz_weights`).

    Parameters
    ----------
    spectrum : array_like, shape (..., W)
        Spectral values (any radiometric unit; the result is relative to a flat spectrum of 1).
    wavelengths_nm : array_like, shape (W,)
        Wavelengths, nm.
    weights : array_like, shape (W,), optional
        Quadrature widths, nm; see :func:`xyz_weights` for the default.

    Returns
    -------
    ndarray, shape (..., 3)
        XYZ; a flat spectrum of 1 gives (1, 1, 1).

    References
    ----------
    CIE 015:2018 §7.1.
    """
    w = xyz_weights(wavelengths_nm, weights)
    s = _checks.finite_array("spectrum", spectrum)
    if s.shape[-1:] != (w.shape[0],):
        raise ValueError(f"spectrum must have {w.shape[0]} samples on its last axis, got shape {s.shape}")
    return s @ w


# --------------------------------------------------------------------------------------------
# Illuminants
# --------------------------------------------------------------------------------------------


def _illuminant_name(name) -> str:
    name = ILLUMINANT_ALIASES.get(name, name)
    return _checks.choice("name", name, set(ILLUMINANTS))


@functools.cache
def _illuminant_native(name: str) -> tuple[np.ndarray, np.ndarray]:
    """The CIE table for ``name`` at its native spacing, scaled to Y = 1 (see below)."""
    lam, values = colour_tables.illuminant(name)
    dense = wavelength_grid(DENSE_BIN_COUNT)
    y = spectrum_to_xyz(np.interp(dense, lam, values), dense)[1]
    return _read_only(lam), _read_only(values / y)


def illuminant_table(name: str) -> tuple[np.ndarray, np.ndarray]:
    """An illuminant's tabulated SPD at its native spacing (nm), normalised like :func:`illuminant_spd`.

    Use this (with :mod:`precompute.colour.composite`) for line spectra, whose lines are folded into
    single table samples.

    Returns
    -------
    wavelengths_nm, values : ndarray, shape (N,)
        Copies of the table; values are relative spectral power (Y = 1).
    """
    lam, values = _illuminant_native(_illuminant_name(name))
    return lam.copy(), values.copy()


def illuminant_spd(name: str, wavelengths_nm) -> np.ndarray:
    """Relative SPD of a CIE illuminant at arbitrary wavelengths, normalised to Y = 1.

    Values are linear interpolation of colour-science's table; beyond the table (D65 and A
    stop at 780 nm, FL1–FL12 cover 380–780 nm) the end values are held. The CMFs there are
    < 3.3e-3 (below 380 nm) and < 4e-5 (above 780 nm) of their peaks, so holding instead of
    zeroing changes XYZ by < 6e-5 relative (measured on FL2, D65, A). The scale makes
    Y = ∫ S ȳ dλ / ∫ ȳ dλ = 1 on a dense 1 nm grid (so E is exactly 1 everywhere).

    Fluorescent lamps (FL*) have emission lines folded into single 5 nm samples: interpolating
    them onto a coarse grid misplaces their power. Use :mod:`precompute.colour.composite` for those.

    Parameters
    ----------
    name : str
        "D65", "A", "E", "FL1"…"FL12" (aliases "F1"…"F12").
    wavelengths_nm : array_like
        Wavelengths, nm, any shape.

    Returns
    -------
    ndarray
        Same shape as ``wavelengths_nm``, dimensionless relative power.

    References
    ----------
    CIE 015:2018 Tables 2–3 (D65, A); CIE 15.2-1986 Table 1.1 (F1–F12); colour-science
    ``SDS_ILLUMINANTS``.
    """
    lam_table, values = _illuminant_native(_illuminant_name(name))
    lam = _checks.finite_array("wavelengths_nm", wavelengths_nm)
    return np.interp(lam, lam_table, values)


# --------------------------------------------------------------------------------------------
# XYZ(E) ↔ working RGB
# --------------------------------------------------------------------------------------------


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
    return _read_only(xyz_to_rgb @ adapt)


def xyz_to_rgb_matrix(space: str = DEFAULT_SPACE) -> np.ndarray:
    """3×3 matrix from XYZ(E) to linear ``space`` RGB: M_XYZ→RGB(space) · Bradford(E → white).

    The space's primaries, white and XYZ → RGB matrix are colour-science's
    ``RGB_COLOURSPACES`` (shipped as data, :mod:`.colour_tables`); E's white is XYZ (1, 1, 1).
    A flat spectrum (XYZ = 1, 1, 1) maps to RGB (1, 1, 1) to rounding.

    Blender's config builds "Linear CIE-XYZ E" with a D65 white of XYZ (0.95047, 1, 1.08883)
    while its Rec.709/2020 matrices use xy (0.3127, 0.3290); the two D65s differ by 2e-4 in Z,
    so Blender's own composite maps E white to (1.00016, 0.99998, 0.99976). We keep the
    self-consistent white (so flat → 1 exactly); the matrices agree with Blender's to 1.3e-4
    relative to their largest entry (tested in ``tests/test_spectra.py``).

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
    return _read_only(np.asarray(xyz_to_rgb, dtype=np.float64) @ adapt)


def scene_linear_matrix(space: str = DEFAULT_SPACE) -> np.ndarray:
    """3×3 matrix from CIE XYZ (D65-relative) to linear ``space`` RGB, as Blender's colour
    management defines it: what Cycles turns its colour-matching functions into RGB with.

    Blender's OCIO config relates every space to "Linear CIE-XYZ D65" (and to ACES2065-1, its
    ``aces_interchange`` role, through OCIO's built-in ACES AP0 → XYZ D65 Bradford matrix):
    Rec.709 and Rec.2020 use their own XYZ → RGB matrices, with no chromatic adaptation (their
    white is D65); ACEScg adds a Bradford adaptation from D65 to the ACES white. Cycles'
    ``ColorSpaceManager::get_xyz_to_scene_linear_rgb`` derives the matrix from the config's
    ``aces_interchange`` role (or its ``XYZ`` role); the result agrees with this one to 1e-6
    (tests/test_spectra.py, against PyOpenColorIO with Blender's config). Unlike
    :func:`xyz_to_rgb_matrix` there is no adaptation from E: a flat spectrum is not white.

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
    ITU-R BT.709-6; ITU-R BT.2020-2; Academy S-2014-004; Blender's ``datafiles/colormanagement/
    config.ocio``.
    """
    return _xyz_d65_to_rgb(_space_name(space)).copy()


#: The CMF table padded with a zero 1 nm beyond each end, so that the sensitivities' spline
#: falls to zero there (the table's values at 360 and 830 nm are ≈ 1e-4 and 1e-6 of the peak).
CMF_PAD_NM = 1.0


@functools.cache
def _channel_sensitivities(space: str) -> tuple[np.ndarray, np.ndarray]:
    lam, table = _cmf_table()
    lam = np.concatenate(([lam[0] - CMF_PAD_NM], lam, [lam[-1] + CMF_PAD_NM]))
    table = np.concatenate((np.zeros((1, 3)), table, np.zeros((1, 3))))
    return _read_only(lam), _read_only(table @ _xyz_d65_to_rgb(space).T)


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
    return _read_only(lam), _read_only(values)


def _cell_averages(x: np.ndarray, y: np.ndarray, wavelengths_nm: np.ndarray) -> np.ndarray:
    """Average of the piecewise-linear (x, y) over each grid cell; point value for empty cells."""
    edges = cell_edges(wavelengths_nm)
    widths = np.diff(edges)
    integrals = _integrate_piecewise_linear(x, y, edges)
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
    lam = _wavelength_axis("wavelengths_nm", wavelengths_nm)
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
    lam = _wavelength_axis("wavelengths_nm", wavelengths_nm)
    space = _space_name(space)
    basis = _uncorrected_basis(lam, space)
    t = basis @ xyz_weights(lam) @ xyz_to_rgb_matrix(space).T
    return np.linalg.solve(t, basis)
