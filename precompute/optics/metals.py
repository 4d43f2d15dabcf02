"""Measured complex refractive indices N = n + i·k of conductors, 360–830 nm and a little beyond.

Used as substrates under oxide films (anodised titanium, heat-tinted steel ≈ iron) and for
metallic beetles. The numbers live in ``precompute/data/metals/<Symbol>.csv`` (columns
``wavelength_nm,n,k``); each file's ``#`` header names the publication, the digital copy the
numbers were taken from and the unit conversion applied. Files are read on first use and cached.

Interpolation: n and k are interpolated separately and linearly in vacuum wavelength between the
published points (as :class:`precompute.optics.dispersion.TabulatedIndex` does). The Johnson &
Christy tables are sampled every ≈ 0.12 eV (17–70 nm in the visible); the curves are smooth on that
scale except near the interband edges of Au (≈ 500 nm) and Cu (≈ 580 nm), where the linear
interpolant follows the published points and no more. Wavelengths outside a file's tabulated range
raise ``ValueError``: no extrapolation.

References
----------
- P. B. Johnson and R. W. Christy (1972). Optical constants of the noble metals.
  Phys. Rev. B 6, 4370–4379, doi:10.1103/PhysRevB.6.4370 (Au, Ag, Cu).
- P. B. Johnson and R. W. Christy (1974). Optical constants of transition metals: Ti, V, Cr, Mn,
  Fe, Co, Ni, and Pd. Phys. Rev. B 9, 5056–5070, doi:10.1103/PhysRevB.9.5056 (Ti, Fe).
- K. M. McPeak et al. (2015). Plasmonic films can easily be better: rules and recipes.
  ACS Photonics 2, 326–333, doi:10.1021/ph5004237 (Al).
- Digital copies: refractiveindex.info database (M. N. Polyanskiy), CC0 1.0.
"""

from __future__ import annotations

import functools
import pathlib
from collections.abc import Iterator, Mapping
from dataclasses import dataclass

import numpy as np

from .. import _checks

#: Folder holding ``<Symbol>.csv``.
DATA_DIR = pathlib.Path(__file__).parent.parent / "data" / "metals"

_JC1972 = "P. B. Johnson and R. W. Christy, Phys. Rev. B 6, 4370 (1972), doi:10.1103/PhysRevB.6.4370"
_JC1974 = "P. B. Johnson and R. W. Christy, Phys. Rev. B 9, 5056 (1974), doi:10.1103/PhysRevB.9.5056"
_MCPEAK2015 = "K. M. McPeak et al., ACS Photonics 2, 326 (2015), doi:10.1021/ph5004237"


@functools.cache
def _load_table(symbol: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read and check ``<symbol>.csv``; return read-only (wavelengths_nm, n, k)."""
    path = DATA_DIR / f"{symbol}.csv"
    data = np.loadtxt(path, comments="#", delimiter=",", ndmin=2, dtype=str)
    # The column-name line is the first non-comment row; everything after it is numeric.
    if tuple(data[0]) != ("wavelength_nm", "n", "k"):
        raise ValueError(f"{path}: expected header 'wavelength_nm,n,k', got {','.join(data[0])!r}")
    table = data[1:].astype(float)
    wl, n, k = table.T.copy()
    if wl.size < 2 or np.any(np.diff(wl) <= 0):
        raise ValueError(f"{path}: needs ≥ 2 strictly increasing wavelengths")
    if not np.all(np.isfinite(table)) or np.any(n <= 0) or np.any(k < 0):
        raise ValueError(f"{path}: n and k must be finite with n > 0 and k ≥ 0")
    for arr in (wl, n, k):
        arr.flags.writeable = False
    return wl, n, k


@dataclass(frozen=True)
class TabulatedMetal:
    """A conductor whose N = n + i·k is tabulated in ``precompute/data/metals/<symbol>.csv``.

    ``index(wavelengths_nm)`` has the same interface as the models in
    :mod:`precompute.optics.dispersion`, so a ``TabulatedMetal`` can be passed wherever a
    medium's index model is accepted.
    """

    name: str
    symbol: str
    source: str

    @property
    def path(self) -> pathlib.Path:
        """The metal's measured n, k CSV file."""
        return DATA_DIR / f"{self.symbol}.csv"

    @property
    def dispersive(self) -> bool:
        """True: measured metals disperse."""
        return True

    def table(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The published points as read-only arrays (wavelengths_nm, n, k)."""
        return _load_table(self.symbol)

    @property
    def wavelength_range(self) -> tuple[float, float]:
        """(shortest, longest) tabulated wavelength in nm."""
        wl = self.table()[0]
        return float(wl[0]), float(wl[-1])

    def index(self, wavelengths_nm) -> np.ndarray:
        """Complex index n + i·k at ``wavelengths_nm`` (any shape), linear in wavelength."""
        wl = _checks.finite_array("wavelengths_nm", wavelengths_nm)
        lo, hi = self.wavelength_range
        if np.any(wl < lo) or np.any(wl > hi):
            bad = wl[(wl < lo) | (wl > hi)].reshape(-1)[0]
            raise ValueError(
                f"wavelengths_nm must lie in {self.name}'s tabulated range {lo:g}–{hi:g} nm, got {bad!r}"
            )
        tab_wl, n, k = self.table()
        return np.interp(wl, tab_wl, n) + 1j * np.interp(wl, tab_wl, k)


class _MetalMapping(Mapping):
    """Canonical names → :class:`TabulatedMetal`; lookup also accepts aliases, case-insensitively."""

    def __init__(self, metals: dict[str, TabulatedMetal], aliases: dict[str, str]):
        self._metals = dict(metals)
        self._lookup = {name.lower(): name for name in metals}
        self._lookup.update({alias.lower(): name for alias, name in aliases.items()})

    def canonical(self, name) -> str:
        """The canonical name for ``name`` (a name, symbol or alias); ``KeyError`` if unknown."""
        if not isinstance(name, str):
            raise KeyError(name)
        return self._lookup[name.strip().lower()]

    def __getitem__(self, name) -> TabulatedMetal:
        return self._metals[self.canonical(name)]

    def __iter__(self) -> Iterator[str]:
        return iter(self._metals)

    def __len__(self) -> int:
        return len(self._metals)

    def __repr__(self) -> str:
        return f"METALS({', '.join(self._metals)})"


#: Canonical name → metal. Also indexable by symbol ("Au", …) and by "aluminum", in any case.
METALS: Mapping[str, TabulatedMetal] = _MetalMapping(
    {
        "gold": TabulatedMetal("gold", "Au", _JC1972),
        "silver": TabulatedMetal("silver", "Ag", _JC1972),
        "copper": TabulatedMetal("copper", "Cu", _JC1972),
        "aluminium": TabulatedMetal("aluminium", "Al", _MCPEAK2015),
        "titanium": TabulatedMetal("titanium", "Ti", _JC1974),
        "iron": TabulatedMetal("iron", "Fe", _JC1974),
    },
    aliases={
        "Au": "gold",
        "Ag": "silver",
        "Cu": "copper",
        "Al": "aluminium",
        "aluminum": "aluminium",
        "Ti": "titanium",
        "Fe": "iron",
    },
)


def available_metals() -> tuple[str, ...]:
    """Canonical names of the tabulated metals."""
    return tuple(METALS)


def get_metal(name: str) -> TabulatedMetal:
    """The :class:`TabulatedMetal` called ``name`` (name, symbol or alias, any case)."""
    try:
        return METALS[name]
    except KeyError:
        raise ValueError(
            f"name must be one of {list(available_metals())} (or a symbol Au, Ag, Cu, Al, Ti, Fe, "
            f"or 'aluminum'), got {name!r}"
        ) from None


def metal_index(name: str, wavelengths_nm) -> np.ndarray:
    """Complex index n + i·k of metal ``name`` at ``wavelengths_nm``."""
    return get_metal(name).index(wavelengths_nm)
