"""The published colour tables the product needs, shipped as data in ``precompute/data/colour/``.

- the CIE 1931 2° colour-matching functions, 360–830 nm at 1 nm (:func:`cmfs`);
- the CIE illuminants offered: D65, A, E and FL1–FL12 (:func:`illuminant`);
- Mallett & Yuksel's (2019) sRGB spectral basis, 380–780 nm at 5 nm (:func:`mallett2019`);
- the white point (xy) and XYZ → RGB matrix of each working space (:func:`rgb_space`);
- the Bradford cone matrix and the von Kries adaptation built on it (:func:`bradford_adaptation`).

The files are copies of colour-science 0.4.7's tables (``scripts/export_colour_tables.py``
writes them, each number as the shortest decimal that reads back to the same float64), so the
arrays here are exactly colour-science's (``tests/optics/test_colour_tables.py``) and the extension
needs no colour-science at run time: a bake reads a few kB of text instead of importing a
9 MB package (2–4 s, and warnings printed at every Blender start). Each table is read once,
returned read-only.

References
----------
- CIE 015:2018 *Colorimetry*, 4th ed., Table 1 (2° CMFs), Tables 2–3 (D65, A); CIE 15.2-1986
  Table 1.1 (F1–F12).
- Lam, K. M. (1985). Metamerism and colour constancy. PhD thesis, Univ. of Bradford.
- Mallett, I. & Yuksel, C. (2019). Spectral Primary Decomposition for Rendering with sRGB
  Reflectance. EGSR 2019.
- ITU-R BT.709-6 (2015), ITU-R BT.2020-2 (2015); Academy S-2014-004 (ACEScg).
- Mansencal, T. et al. colour-science 0.4.7 (the source of every number here).
"""

from __future__ import annotations

import functools
import pathlib

import numpy as np

__all__ = [
    "BRADFORD",
    "CMFS_NAME",
    "ILLUMINANTS",
    "RGB_SPACES",
    "bradford_adaptation",
    "cmfs",
    "illuminant",
    "mallett2019",
    "rgb_space",
    "xy_to_xyz",
]

DATA_DIR = pathlib.Path(__file__).resolve().parent.parent / "data" / "colour"
CMFS_FILE = "cie_1931_2deg_cmfs.csv"
ILLUMINANTS_FILE = "cie_illuminants.csv"
MALLETT_FILE = "mallett2019_srgb_basis.csv"
RGB_SPACES_FILE = "rgb_spaces.csv"

#: colour-science's name of the observer the CMFs are.
CMFS_NAME = "CIE 1931 2 Degree Standard Observer"
#: Illuminants in the data (colour-science's ``SDS_ILLUMINANTS`` names).
ILLUMINANTS = ("D65", "A", "E", *(f"FL{i}" for i in range(1, 13)))
#: RGB spaces in the data (colour-science's ``RGB_COLOURSPACES`` names).
RGB_SPACES = ("ITU-R BT.709", "ITU-R BT.2020", "ACEScg")

#: The Bradford cone-response matrix (Lam 1985; Lindbloom, *Chromatic Adaptation*), as
#: colour-science's ``CAT_BRADFORD``.
BRADFORD = np.array(
    [
        [0.8951, 0.2664, -0.1614],
        [-0.7502, 1.7135, 0.0367],
        [0.0389, -0.0685, 1.0296],
    ]
)
BRADFORD.flags.writeable = False


def _read_only(arr) -> np.ndarray:
    arr = np.ascontiguousarray(arr, dtype=np.float64)
    arr.flags.writeable = False
    return arr


@functools.cache
def _rows(name: str) -> tuple[tuple[str, ...], ...]:
    """The data rows of a shipped CSV file (comments and the column header skipped)."""
    lines = (DATA_DIR / name).read_text(encoding="utf-8").splitlines()
    body = [line for line in lines if line and not line.startswith("#")]
    return tuple(tuple(line.split(",")) for line in body[1:])


def _curves(name: str) -> tuple[np.ndarray, np.ndarray]:
    """(first column, the other columns) of a shipped CSV table of curves, read-only float64."""
    table = np.array(_rows(name), dtype=np.float64)
    return _read_only(table[:, 0]), _read_only(table[:, 1:])


@functools.cache
def cmfs() -> tuple[np.ndarray, np.ndarray]:
    """CIE 1931 2° x̄, ȳ, z̄: (wavelengths nm (471,), values (471, 3)), 360–830 nm at 1 nm."""
    return _curves(CMFS_FILE)


@functools.cache
def illuminant(name: str) -> tuple[np.ndarray, np.ndarray]:
    """A CIE illuminant's relative spectral power at its native spacing: (wavelengths nm, values).

    ``name`` is one of :data:`ILLUMINANTS` (ValueError otherwise). D65 and A cover 300–780 nm,
    E 360–830 nm, FL1–FL12 380–780 nm, all at 5 nm; the values are as published (not normalised).
    """
    if name not in ILLUMINANTS:
        raise ValueError(f"illuminant must be one of {', '.join(ILLUMINANTS)}, got {name!r}")
    table = np.array([row[1:] for row in _rows(ILLUMINANTS_FILE) if row[0] == name], dtype=np.float64)
    return _read_only(table[:, 0]), _read_only(table[:, 1])


@functools.cache
def mallett2019() -> tuple[np.ndarray, np.ndarray]:
    """Mallett & Yuksel's sRGB basis: (wavelengths nm (81,), values (81, 3) for r, g, b)."""
    return _curves(MALLETT_FILE)


@functools.cache
def rgb_space(name: str) -> tuple[np.ndarray, np.ndarray]:
    """(white point xy (2,), XYZ → RGB matrix (3, 3)) of one of :data:`RGB_SPACES`."""
    for row in _rows(RGB_SPACES_FILE):
        if row[0] == name:
            values = np.array(row[1:], dtype=np.float64)
            return _read_only(values[:2]), _read_only(values[2:].reshape(3, 3))
    raise ValueError(f"RGB space must be one of {', '.join(RGB_SPACES)}, got {name!r}")


def xy_to_xyz(xy) -> np.ndarray:
    """CIE xy chromaticity → XYZ with Y = 1: (x/y, 1, (1 − x − y)/y)."""
    x, y = (float(v) for v in xy)
    return np.array([x / y, 1.0, (1.0 - x - y) / y])


def bradford_adaptation(source_white_xyz, target_white_xyz) -> np.ndarray:
    """Von Kries adaptation in the Bradford cone space, 3×3: XYZ_target = M @ XYZ_source.

    M = B⁻¹ diag(B w_target / B w_source) B with B = :data:`BRADFORD` (Lam 1985), as
    colour-science's ``matrix_chromatic_adaptation_VonKries(..., transform="Bradford")``.
    """
    source = BRADFORD @ np.asarray(source_white_xyz, dtype=np.float64)
    target = BRADFORD @ np.asarray(target_white_xyz, dtype=np.float64)
    return np.linalg.inv(BRADFORD) @ np.diag(target / source) @ BRADFORD
