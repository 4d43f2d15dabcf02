"""Spectral colorimetry: wavelength grids, CIE 1931 CMFs, illuminants, spectrum → XYZ(E).

Everything here follows ``docs/conventions.md``:

- spectra live on 360–830 nm (the CIE 1931 2° table's range) with the wavelength on the last
  axis; the published tables are read once from :mod:`.colour_tables` (colour-science's
  numbers shipped as data, so nothing here imports colour-science), the arithmetic is on
  plain float64 arrays;
- tristimulus values use an **equal-energy (E) white**: a flat spectrum of 1 has
  X = Y = Z = 1, as Blender's "Linear CIE-XYZ E";
- XYZ(E) → working RGB is in :mod:`.rgb_spaces`.

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
- CIE 015:2018 *Colorimetry*, 4th ed., §7 (tristimulus integrals) and Table 1 (2° CMFs);
  CIE 15.2-1986 Table 1.1 (the fluorescent illuminants).
- Mansencal, T. et al. colour-science 0.4.7 (source of every table used here).
"""

from __future__ import annotations

import functools

import numpy as np

from .. import _checks
from ..constants import WAVELENGTH_MAX_NM, WAVELENGTH_MIN_NM
from . import colour_tables

#: colour-science's name for the observer every integral uses.
CMFS_NAME = "CIE 1931 2 Degree Standard Observer"

#: Spacing (nm) of the aligned CMF table that :func:`cmfs` interpolates. The CIE publishes the
#: 2° observer at 1 nm; linear interpolation in between is the CIE 015 recommendation.
CMF_TABLE_STEP_NM = 1.0

#: Illuminants offered by :func:`illuminant_spd` (colour-science's ``SDS_ILLUMINANTS`` keys).
ILLUMINANTS = ("D65", "A", "E", *(f"FL{i}" for i in range(1, 13)))

#: The CIE's older "F1"…"F12" spellings of the fluorescent lamps.
ILLUMINANT_ALIASES = {f"F{i}": f"FL{i}" for i in range(1, 13)}

#: Number of equal bins (1 nm wide) used wherever a grid-independent dense integral is needed
#: (illuminant normalisation). 1 nm is the CMF table's own resolution.
DENSE_BIN_COUNT = int(round((WAVELENGTH_MAX_NM - WAVELENGTH_MIN_NM) / CMF_TABLE_STEP_NM))

__all__ = [
    "ILLUMINANTS",
    "bin_edges",
    "bin_width",
    "cell_edges",
    "cell_widths",
    "cmf_cell_integrals",
    "cmf_integrals",
    "cmf_table",
    "cmfs",
    "illuminant_spd",
    "illuminant_table",
    "integrate_piecewise_linear",
    "read_only",
    "spectrum_to_xyz",
    "wavelength_axis",
    "wavelength_grid",
    "xyz_weights",
]


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


def wavelength_axis(name: str, wavelengths_nm, *, min_count: int = 2) -> np.ndarray:
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
    lam = wavelength_axis("wavelengths_nm", wavelengths_nm)
    mids = 0.5 * (lam[:-1] + lam[1:])
    first = lam[0] - 0.5 * (lam[1] - lam[0])
    last = lam[-1] + 0.5 * (lam[-1] - lam[-2])
    edges = np.concatenate(([first], mids, [last]))
    return np.clip(edges, WAVELENGTH_MIN_NM, WAVELENGTH_MAX_NM)


def cell_widths(wavelengths_nm) -> np.ndarray:
    """Quadrature cell widths (nm) of a sorted grid, shape (W,): ``diff(cell_edges)``."""
    return np.diff(cell_edges(wavelengths_nm))


def integrate_piecewise_linear(x: np.ndarray, y: np.ndarray, edges: np.ndarray) -> np.ndarray:
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


def read_only(arr: np.ndarray) -> np.ndarray:
    """``arr`` as a contiguous float64 array that cannot be written (a cached table)."""
    arr = np.ascontiguousarray(arr, dtype=np.float64)
    arr.flags.writeable = False
    return arr


@functools.lru_cache(maxsize=1)
def cmf_table() -> tuple[np.ndarray, np.ndarray]:
    """CIE 1931 2° x̄ȳz̄ aligned to 360–830 nm at 1 nm: (wavelengths (471,), values (471, 3))."""
    source_lam, source = colour_tables.cmfs()  # colour-science's table, shipped as data
    # np.interp rather than SpectralDistribution.align: at the CIE's own 1 nm knots it returns
    # the published values untouched (align's interpolator leaves ±3e-22 where z̄ is 0).
    count = int(round((WAVELENGTH_MAX_NM - WAVELENGTH_MIN_NM) / CMF_TABLE_STEP_NM)) + 1
    lam = np.linspace(WAVELENGTH_MIN_NM, WAVELENGTH_MAX_NM, count)
    values = np.stack([np.interp(lam, source_lam, source[:, c]) for c in range(3)], axis=-1)
    return read_only(lam), read_only(values)


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
    x, table = cmf_table()
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
    x, table = cmf_table()
    return integrate_piecewise_linear(x, table, edges)


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
    return read_only(lam), read_only(values / y)


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
