"""Argument checks that raise ``ValueError`` naming the offending parameter.

Every public function in ``precompute`` validates its inputs with these helpers, so bad
input fails loudly with the parameter's name instead of propagating NaN.
"""

from __future__ import annotations

import numpy as np


def _describe(value) -> str:
    arr = np.asarray(value)
    if arr.size == 1:
        return repr(arr.reshape(()).item())
    return f"array of shape {arr.shape}"


def finite_array(name: str, value, *, dtype=float, allow_complex: bool = False) -> np.ndarray:
    """Return ``value`` as an array, raising if it is empty, non-numeric or non-finite."""
    try:
        arr = np.asarray(value, dtype=complex if allow_complex else dtype)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be numeric, got {value!r}") from exc
    if arr.size == 0:
        raise ValueError(f"{name} is empty")
    bad = ~np.isfinite(arr)
    if np.any(bad):
        first = arr[bad].reshape(-1)[0]
        raise ValueError(f"{name} must be finite, got {first!r} (NaN or Inf in {int(bad.sum())} entries)")
    return arr


def in_range(name: str, arr: np.ndarray, lo=None, hi=None, *, lo_open: bool = False) -> np.ndarray:
    """Raise unless every element of ``arr`` lies in [lo, hi] (or (lo, hi] when ``lo_open``)."""
    if lo is not None:
        bad = arr <= lo if lo_open else arr < lo
        if np.any(bad):
            op = ">" if lo_open else "≥"
            raise ValueError(f"{name} must be {op} {lo}, got {_describe(arr[bad].reshape(-1)[0])}")
    if hi is not None and np.any(arr > hi):
        raise ValueError(f"{name} must be ≤ {hi}, got {_describe(arr[arr > hi].reshape(-1)[0])}")
    return arr


def positive_int(name: str, value, *, minimum: int = 1, maximum: int | None = None) -> int:
    """Return ``value`` as an int in [minimum, maximum], raising otherwise."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name} must be an integer, got {value!r}")
    if value < minimum or (maximum is not None and value > maximum):
        upper = "" if maximum is None else f" and ≤ {maximum}"
        raise ValueError(f"{name} must be ≥ {minimum}{upper}, got {value}")
    return int(value)


def choice(name: str, value, options) -> str:
    """Raise unless ``value`` is one of ``options``."""
    if value not in options:
        raise ValueError(f"{name} must be one of {sorted(options)}, got {value!r}")
    return value
