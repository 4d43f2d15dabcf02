"""Write the colour tables the product ships (precompute/data/colour/) from colour-science.

    .venv/bin/python scripts/export_colour_tables.py

The extension needs a handful of published tables: the CIE 1931 2° colour-matching functions,
the CIE illuminants it offers (D65, A, E, FL1–FL12), Mallett & Yuksel's (2019) sRGB spectral
basis, and the white points and XYZ → RGB matrices of its three working spaces. They are copied
here from colour-science (the version pinned in requirements-dev.txt), every number written as
the shortest decimal that reads back to the same float64, so :mod:`precompute.colour.colour_tables`
returns exactly colour-science's arrays (tests/optics/test_colour_tables.py checks it) and the
extension no longer needs colour-science at run time.
"""

from __future__ import annotations

import pathlib
import sys

import colour
import numpy as np

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from precompute.colour import colour_tables  # noqa: E402

HEADER = (
    "# {what}\n"
    "# Source: colour-science {version} ({source}); exported by scripts/export_colour_tables.py.\n"
    "# Every value is the shortest decimal that reads back to colour-science's float64.\n"
)


def _num(value) -> str:
    return repr(float(value))


def _write(name: str, what: str, source: str, columns: list[str], rows) -> None:
    path = colour_tables.DATA_DIR / name
    lines = [HEADER.format(what=what, version=colour.__version__, source=source), ",".join(columns) + "\n"]
    lines += [",".join(row) + "\n" for row in rows]
    path.write_text("".join(lines), encoding="utf-8", newline="\n")
    print(f"wrote {path.relative_to(ROOT)} ({len(lines) - 2} rows)")


def main() -> int:
    """Write every table of :mod:`precompute.colour.colour_tables` from the installed colour-science."""
    colour_tables.DATA_DIR.mkdir(parents=True, exist_ok=True)
    cmfs = colour.MSDS_CMFS[colour_tables.CMFS_NAME]
    _write(
        colour_tables.CMFS_FILE,
        "CIE 1931 2 degree standard observer colour-matching functions (CIE 015:2018, Table 1)",
        f'MSDS_CMFS["{colour_tables.CMFS_NAME}"]',
        ["wavelength_nm", "x_bar", "y_bar", "z_bar"],
        ([_num(w), *map(_num, v)] for w, v in zip(cmfs.wavelengths, cmfs.values, strict=True)),
    )
    rows = []
    for name in colour_tables.ILLUMINANTS:
        sd = colour.SDS_ILLUMINANTS[name]
        rows += [[name, _num(w), _num(v)] for w, v in zip(sd.wavelengths, sd.values, strict=True)]
    _write(
        colour_tables.ILLUMINANTS_FILE,
        "CIE illuminants D65 and A (CIE 015:2018), E, and FL1-FL12 (CIE 15.2-1986), relative power",
        "SDS_ILLUMINANTS",
        ["illuminant", "wavelength_nm", "relative_power"],
        rows,
    )
    basis = colour.recovery.MSDS_BASIS_FUNCTIONS_sRGB_MALLETT2019
    _write(
        colour_tables.MALLETT_FILE,
        "Mallett & Yuksel (2019) sRGB spectral primary decomposition basis",
        "recovery.MSDS_BASIS_FUNCTIONS_sRGB_MALLETT2019",
        ["wavelength_nm", "red", "green", "blue"],
        ([_num(w), *map(_num, v)] for w, v in zip(basis.wavelengths, basis.values, strict=True)),
    )
    rows = []
    for name in colour_tables.RGB_SPACES:
        cs = colour.RGB_COLOURSPACES[name]
        rows.append([name, *map(_num, cs.whitepoint), *map(_num, np.asarray(cs.matrix_XYZ_to_RGB).ravel())])
    _write(
        colour_tables.RGB_SPACES_FILE,
        "RGB working spaces: white point xy and the XYZ to RGB matrix, row-major (ITU-R BT.709-6, "
        "ITU-R BT.2020-2, Academy S-2014-004)",
        "RGB_COLOURSPACES",
        ["space", "white_x", "white_y", *(f"m{r}{c}" for r in range(3) for c in range(3))],
        rows,
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
