"""The colour tables shipped as data equal colour-science's, and the runtime never imports it."""

import subprocess
import sys

import colour
import numpy as np
import pytest

from precompute.colour import colour_tables, spectra


def test_cmfs_are_colour_sciences_exactly():
    """Cmfs are colour sciences exactly."""
    lam, values = colour_tables.cmfs()
    table = colour.MSDS_CMFS[colour_tables.CMFS_NAME]
    np.testing.assert_array_equal(lam, table.wavelengths)
    np.testing.assert_array_equal(values, table.values)


@pytest.mark.parametrize("name", colour_tables.ILLUMINANTS)
def test_illuminants_are_colour_sciences_exactly(name):
    """Illuminants are colour sciences exactly."""
    lam, values = colour_tables.illuminant(name)
    sd = colour.SDS_ILLUMINANTS[name]
    np.testing.assert_array_equal(lam, sd.wavelengths)
    np.testing.assert_array_equal(values, sd.values)


def test_mallett_basis_is_colour_sciences_exactly():
    """Mallett basis is colour sciences exactly."""
    lam, values = colour_tables.mallett2019()
    basis = colour.recovery.MSDS_BASIS_FUNCTIONS_sRGB_MALLETT2019
    np.testing.assert_array_equal(lam, basis.wavelengths)
    np.testing.assert_array_equal(values, basis.values)


@pytest.mark.parametrize("name", colour_tables.RGB_SPACES)
def test_rgb_spaces_and_bradford_adaptation_match_colour_science(name):
    """Rgb spaces and bradford adaptation match colour science."""
    white, matrix = colour_tables.rgb_space(name)
    cs = colour.RGB_COLOURSPACES[name]
    np.testing.assert_array_equal(white, cs.whitepoint)  # copied constants: bit for bit
    # colour-science computes its matrix at import (primaries and white through a 3×3 inverse):
    # on another CPU its last bit can differ from the table exported on this one (measured: 1 ulp,
    # 4.4e-16 for ITU-R BT.709 on an AMD EPYC). Rounding only; a wrong primary or white would
    # change entries by ≥ 1e-4.
    np.testing.assert_allclose(
        matrix,
        cs.matrix_XYZ_to_RGB,
        rtol=1e-14,
        atol=1e-15,
        err_msg=f"{name}: the shipped XYZ→RGB matrix against colour-science's (the product's every colour)",
    )
    xyz = colour_tables.xy_to_xyz(white)
    np.testing.assert_allclose(xyz, colour.xy_to_XYZ(cs.whitepoint), rtol=0, atol=1e-15)
    expected = colour.adaptation.matrix_chromatic_adaptation_VonKries(np.ones(3), xyz, transform="Bradford")
    # float64 against an independent implementation: rounding only
    ours = colour_tables.bradford_adaptation(np.ones(3), xyz)
    np.testing.assert_allclose(ours, expected, rtol=0, atol=1e-12)


def test_unknown_names_are_refused():
    """Unknown names are refused."""
    with pytest.raises(ValueError, match="illuminant"):
        colour_tables.illuminant("D50")
    with pytest.raises(ValueError, match="RGB space"):
        colour_tables.rgb_space("sRGB")


def test_spectra_and_a_bake_run_without_colour_science():
    """Spectra and a bake run without colour science."""
    code = (
        "import sys; from precompute.colour import rgb_spaces, spectra; from precompute.bakes import bake;"
        "from precompute.materials import material;"
        "rgb_spaces.xyz_to_rgb_matrix('ACEScg'); spectra.illuminant_spd('FL2', spectra.wavelength_grid(40));"
        "bake.bake(material.PRESETS['soap_film'].with_(quality=material.Quality(sh_order=2, view_samples=4,"
        " thickness_samples=2, wavelength_count=32)));"
        "print('colour' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_the_tables_are_read_only():
    """The tables are read only."""
    lam, values = colour_tables.cmfs()
    with pytest.raises(ValueError):
        values[0, 0] = 1.0
    assert spectra.cmfs(np.array([555.0])).shape == (1, 3)
