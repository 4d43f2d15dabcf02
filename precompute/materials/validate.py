"""The limits on every value a material may take, each with its reason, and the checks at the edge.

:class:`precompute.materials.material.Material` calls these when a description is built, so an invalid
value is a ``ValueError`` naming the parameter within milliseconds, never a bake that runs for
minutes and then fails (or writes NaN). Dispersion models are evaluated over the whole visible
range the bake integrates (:data:`VISIBLE_GRID_NM`, 360–830 nm at 1 nm, plus the points where a
model may take an extreme value between them), from the spec's own formula, so a Cauchy B that
makes n negative at 400 nm is refused at once.

Limits (docs/hostile-input.md lists them for users):

- real index n ≤ :data:`MAX_INDEX_N` and extinction k ≤ :data:`MAX_INDEX_K` (1000: the
  Principled metal fit's ~400 and ~200 pass, Blender's stored ``inf`` does not);
- layer thickness ≤ :data:`MAX_THICKNESS_NM` (100 µm, the largest Thin Film Thickness Blender's
  Principled BSDF accepts);
- at most :data:`MAX_LAYERS` layers, :data:`MAX_TABLE_POINTS` points in a measured index table
  and :data:`MAX_SELLMEIER_TERMS` Sellmeier terms.

Pure Python and numpy; never imports ``bpy``.
"""

from __future__ import annotations

import json
import math
import numbers

import numpy as np

from ..constants import WAVELENGTH_MAX_NM, WAVELENGTH_MIN_NM

__all__ = [
    "MAX_INDEX_K",
    "MAX_INDEX_N",
    "MAX_LAYERS",
    "MAX_SELLMEIER_TERMS",
    "MAX_TABLE_POINTS",
    "MAX_THICKNESS_NM",
    "VISIBLE_GRID_NM",
    "cauchy_coefficients",
    "check_nk_over_visible",
    "constant_index",
    "is_real",
    "known_valid",
    "real",
    "remember_valid",
    "sellmeier_coefficients",
    "spec_key",
    "table_columns",
]

#: Largest real part of a refractive index. Natural optical materials stay below ~6 in the visible
#: (Si ≈ 5.6 at 400 nm), but Gulbrandsen's fit of a Principled BSDF metal (conductors.py) reaches
#: n ≈ 398 for a Base Color of 0.99 with a low Specular Tint; 1000 keeps every such fit while
#: refusing what a careless script stores (Blender keeps ``inf`` as 3.4e38, which made the bake
#: run for minutes and fail on NaN).
MAX_INDEX_N = 1000.0
#: Largest extinction coefficient: measured metals stay below ~10 across 360–830 nm, the same
#: Principled fit reaches k ≈ 199; beyond 1000 a layer is opaque within a tenth of a nanometre.
MAX_INDEX_K = 1000.0
#: Thickest layer (nm): 100 µm, the maximum of Blender's Principled "Thin Film Thickness". Past
#: a few µm the fringes average to the incoherent sum anyway; the bake still takes ≤ ~15 s here.
MAX_THICKNESS_NM = 100_000.0
#: Most layers in a stack. The bake's cost grows linearly (~0.3 s per layer at auto quality);
#: beetle and butterfly reflectors have 10–30 layers, dielectric mirrors up to ~100.
MAX_LAYERS = 128
#: Most points of a measured (tabulated) index: refractiveindex.info tables have ≤ a few thousand.
MAX_TABLE_POINTS = 10_000
#: Most Sellmeier terms: published fits use 1–4.
MAX_SELLMEIER_TERMS = 16

#: Wavelengths (nm) at which every dispersion model is checked: the bake's range at 1 nm.
VISIBLE_GRID_NM = np.linspace(
    WAVELENGTH_MIN_NM, WAVELENGTH_MAX_NM, int(WAVELENGTH_MAX_NM - WAVELENGTH_MIN_NM) + 1
)


def is_real(value) -> bool:
    """A real number (numpy's included), not a bool."""
    t = type(value)
    if t is float or t is int:  # the common case first: ABC checks cost ~1 µs each
        return True
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def real(name: str, value, lo=None, hi=None, *, lo_open: bool = False, why: str = "") -> float:
    """``value`` as a finite float in [lo, hi] (or (lo, hi] with ``lo_open``), else ValueError
    naming ``name``; ``why`` is appended to the message of a value out of range."""
    if not is_real(value):
        raise ValueError(f"{name} must be a number, got {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"{name} must be finite, got {v!r}")
    below = lo is not None and (v <= lo if lo_open else v < lo)
    if below or (hi is not None and v > hi):
        if lo is not None and hi is not None:
            text = f"must lie in {'(' if lo_open else '['}{lo:g}, {hi:g}]"
        elif lo is not None:
            text = f"must be {'>' if lo_open else '≥'} {lo:g}"
        else:
            text = f"must be ≤ {hi:g}"
        raise ValueError(f"{name} {text}, got {v!r}" + (f" ({why})" if why else ""))
    return v


def _reals(name: str, values, *, count=None, minimum: int = 1, maximum: int | None = None) -> tuple:
    """A sequence of finite reals (its length checked), as a tuple of floats."""
    if isinstance(values, (str, bytes, dict)) or not hasattr(values, "__len__"):
        raise ValueError(f"{name} must be a list of numbers, got {values!r}")
    n = len(values)
    if count is not None and n != count:
        raise ValueError(f"{name} must have {count} values, got {n}")
    if n < minimum or (maximum is not None and n > maximum):
        most = f" and at most {maximum}" if maximum is not None else ""
        raise ValueError(f"{name} must have at least {minimum}{most} values, got {n}")
    return tuple(real(f"{name}[{i}]", v) for i, v in enumerate(values))


def check_nk_over_visible(name: str, wavelengths_nm, n, k) -> None:
    """Raise ValueError naming ``name`` unless 0 < n ≤ MAX_INDEX_N and 0 ≤ k ≤ MAX_INDEX_K,
    all finite, at each of ``wavelengths_nm``; the message gives the first bad wavelength."""
    wl = np.atleast_1d(np.asarray(wavelengths_nm, dtype=float))
    n = np.broadcast_to(np.asarray(n, dtype=float), wl.shape)
    k = np.broadcast_to(np.asarray(k, dtype=float), wl.shape)
    with np.errstate(invalid="ignore"):
        checks = (
            (~np.isfinite(n), "needs finite n", n),
            (~np.isfinite(k), "needs finite k", k),
            (n <= 0, "needs n > 0", n),
            (n > MAX_INDEX_N, f"needs n ≤ {MAX_INDEX_N:g}", n),
            (k < 0, "needs extinction k ≥ 0", k),
            (k > MAX_INDEX_K, f"needs k ≤ {MAX_INDEX_K:g}", k),
        )
    for bad, text, arr in checks:
        if bad.any():
            i = int(np.argmax(bad))
            where = f" at {wl[i]:g} nm" if wl.size > 1 else ""
            raise ValueError(f"{name}: {text}, got {float(arr[i])!r}{where}")


def constant_index(name: str, n, k=0.0) -> tuple[float, float]:
    """(n, k) of a constant index N = n + ik, checked."""
    n = real(f"{name} n", n)
    k = real(f"{name} k", k)
    if not (0.0 < n <= MAX_INDEX_N and 0.0 <= k <= MAX_INDEX_K):  # plain floats: no numpy here
        check_nk_over_visible(name, [WAVELENGTH_MIN_NM], n, k)
    return n, k


def cauchy_coefficients(name: str, value) -> tuple[float, float, float]:
    """(A, B, C) of a ``{"cauchy": [A, B, C]}`` spec (B and C default to 0).

    n(λ) = A + B/λ² + C/λ⁴ (λ in µm) is checked over 360–830 nm: it is a parabola in
    x = 1/λ², so the 1 nm grid plus its vertex x = −B/2C hold its extremes.
    """
    coeffs = _reals(f"{name} Cauchy coefficients", value, minimum=1, maximum=3)
    a, b, c = coeffs + (0.0,) * (3 - len(coeffs))
    wl = VISIBLE_GRID_NM
    if c != 0.0 and -b / (2.0 * c) > 0:
        vertex = 1e3 / math.sqrt(-b / (2.0 * c))
        if WAVELENGTH_MIN_NM < vertex < WAVELENGTH_MAX_NM:
            wl = np.union1d(wl, [vertex])
    x = 1.0 / (wl * 1e-3) ** 2
    with np.errstate(all="ignore"):
        n = a + b * x + c * x * x
    check_nk_over_visible(f"{name} (Cauchy A={a:g}, B={b:g}, C={c:g})", wl, n, 0.0)
    return a, b, c


def sellmeier_coefficients(name: str, value) -> tuple[tuple, tuple]:
    """(B, C) of a ``{"sellmeier": {"B": [...], "C": [...]}}`` spec.

    n² = 1 + Σ B_i λ²/(λ² − C_i) (λ in µm, C_i in µm²) must have no resonance (pole) in
    360–830 nm, and n² > 0 and n within the limits on the 1 nm grid.
    """
    if not isinstance(value, dict) or set(value) != {"B", "C"}:
        raise ValueError(f"{name}: Sellmeier needs a dict with keys 'B' and 'C', got {value!r}")
    b = _reals(f"{name} Sellmeier B", value["B"], minimum=1, maximum=MAX_SELLMEIER_TERMS)
    c = _reals(f"{name} Sellmeier C", value["C"], count=len(b))
    for i, ci in enumerate(c):
        if ci > 0 and WAVELENGTH_MIN_NM <= 1e3 * math.sqrt(ci) <= WAVELENGTH_MAX_NM:
            raise ValueError(
                f"{name}: Sellmeier C[{i}] = {ci!r} µm² puts a resonance at {1e3 * math.sqrt(ci):.1f} nm, "
                f"inside {WAVELENGTH_MIN_NM:g}–{WAVELENGTH_MAX_NM:g} nm"
            )
    lam2 = (VISIBLE_GRID_NM * 1e-3) ** 2
    with np.errstate(all="ignore"):
        n2 = 1.0 + sum(bi * lam2 / (lam2 - ci) for bi, ci in zip(b, c, strict=True))
    if np.any(~(n2 > 0)):
        i = int(np.argmax(~(n2 > 0)))
        raise ValueError(
            f"{name}: Sellmeier gives n² = {n2[i]:.6g} at {VISIBLE_GRID_NM[i]:g} nm (needs n² > 0)"
        )
    check_nk_over_visible(f"{name} (Sellmeier)", VISIBLE_GRID_NM, np.sqrt(n2), 0.0)
    return b, c


def table_columns(name: str, value) -> tuple[tuple, tuple, tuple]:
    """(wavelengths_nm, n, k) of a ``{"table": {...}}`` spec covering 360–830 nm.

    Linear interpolation takes its extremes at the table's points, so n and k are checked at
    the points inside the range and at its two ends.
    """
    keys = set(value) if isinstance(value, dict) else set()
    if not {"wavelengths_nm", "n"} <= keys <= {"wavelengths_nm", "n", "k"}:
        raise ValueError(f"{name}: a table needs a dict with 'wavelengths_nm', 'n' and optionally 'k'")
    wl = _reals(f"{name} table wavelengths_nm", value["wavelengths_nm"], minimum=2, maximum=MAX_TABLE_POINTS)
    n = _reals(f"{name} table n", value["n"], count=len(wl))
    k = _reals(f"{name} table k", value.get("k", [0.0] * len(wl)), count=len(wl))
    if any(hi <= lo for lo, hi in zip(wl, wl[1:], strict=False)):
        raise ValueError(f"{name}: table wavelengths_nm must increase strictly")
    if wl[0] > WAVELENGTH_MIN_NM or wl[-1] < WAVELENGTH_MAX_NM:
        raise ValueError(
            f"{name}: the table covers {wl[0]:g}–{wl[-1]:g} nm but the bake needs "
            f"{WAVELENGTH_MIN_NM:g}–{WAVELENGTH_MAX_NM:g} nm"
        )
    inside = [w for w in wl if WAVELENGTH_MIN_NM < w < WAVELENGTH_MAX_NM]
    at = np.union1d([WAVELENGTH_MIN_NM, WAVELENGTH_MAX_NM], inside)
    check_nk_over_visible(f"{name} (table)", at, np.interp(at, wl, n), np.interp(at, wl, k))
    return wl, n, k


def spec_key(spec) -> str | None:
    """Canonical JSON of an index spec, the key of :func:`remember_valid`; None when it has no
    JSON form (then it is checked every time)."""
    try:
        return json.dumps(spec, sort_keys=True, allow_nan=True)
    except (TypeError, ValueError, RecursionError):
        return None


def known_valid(key: str | None) -> bool:
    """Whether the spec with this :func:`spec_key` was checked before and found valid."""
    return key is not None and key in _VALID_SPECS


def remember_valid(key: str | None) -> None:
    """Remember a spec found valid: the viewport builds the same descriptions every frame, and
    checking a dispersive index over 471 wavelengths costs ~20–50 µs per layer."""
    if key is None:
        return
    if len(_VALID_SPECS) >= _VALID_SPECS_LIMIT:
        _VALID_SPECS.clear()
    _VALID_SPECS.add(key)


_VALID_SPECS: set = set()
_VALID_SPECS_LIMIT = 4096
