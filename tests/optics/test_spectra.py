"""Colorimetry: grids, CMFs, XYZ(E), illuminants, working spaces, Blender's OCIO, RGB → spectrum."""

import importlib.util
import pathlib
import re

import colour
import numpy as np
import pytest

from precompute.colour import rgb_spaces, spectra
from precompute.constants import WAVELENGTH_MAX_NM, WAVELENGTH_MIN_NM

SPACES = tuple(rgb_spaces.WORKING_SPACES)
GRID_SIZES = (16, 64, 471)

# Pure float64 arithmetic on O(1) numbers through a few hundred operations: 1e-12 leaves
# three orders of margin over the ~1e-15 rounding we measure.
TOL_ROUNDING = 1e-12


def test_default_grid_is_bin_centres():
    edges = spectra.bin_edges(47)
    grid = spectra.wavelength_grid(47)
    assert edges[0] == WAVELENGTH_MIN_NM and edges[-1] == WAVELENGTH_MAX_NM
    np.testing.assert_allclose(np.diff(edges), spectra.bin_width(47), rtol=TOL_ROUNDING)
    np.testing.assert_allclose(grid, 0.5 * (edges[:-1] + edges[1:]), rtol=TOL_ROUNDING)
    # The cells of the default grid are exactly its bins.
    np.testing.assert_allclose(spectra.cell_edges(grid), edges, rtol=TOL_ROUNDING)


def test_cell_edges_of_an_inclusive_grid_are_trapezoid_cells():
    grid = np.arange(360.0, 831.0, 10.0)
    widths = spectra.cell_widths(grid)
    assert widths[0] == widths[-1] == 5.0
    assert np.all(widths[1:-1] == 10.0)


@pytest.mark.parametrize("count", [0, -3, 2.5, True, "8"])
def test_grid_rejects_bad_count(count):
    """A wavelength grid with a bad count is refused with the argument named."""
    with pytest.raises(ValueError, match="count"):
        spectra.wavelength_grid(count)


def test_cmfs_reproduce_the_cie_table_and_vanish_outside():
    table = colour.MSDS_CMFS[spectra.CMFS_NAME]
    lam = np.asarray(table.wavelengths)
    # The 1 nm table itself must come back bit for bit (np.interp at the knots).
    np.testing.assert_array_equal(spectra.cmfs(lam), np.asarray(table.values))
    mid = spectra.cmfs(np.array([555.5]))
    np.testing.assert_allclose(mid[0], 0.5 * (table[555.0] + table[556.0]), rtol=TOL_ROUNDING)
    assert np.all(spectra.cmfs(np.array([300.0, 359.9, 830.1, 900.0])) == 0.0)
    assert spectra.cmfs(np.full((2, 5), 550.0)).shape == (2, 5, 3)


def test_cmf_areas_match_the_trapezoid_rule_and_are_nearly_equal():
    table = colour.MSDS_CMFS[spectra.CMFS_NAME]
    trapezoid = np.trapezoid(np.asarray(table.values), np.asarray(table.wavelengths), axis=0)
    np.testing.assert_allclose(spectra.cmf_integrals(), trapezoid, rtol=TOL_ROUNDING)
    # Sum of cell integrals = integral over their union, for any partition.
    np.testing.assert_allclose(
        spectra.cmf_cell_integrals(spectra.bin_edges(33)).sum(0), trapezoid, rtol=TOL_ROUNDING
    )
    # CIE 1931 is normalised to equal areas; the tabulated ones differ by 3.3e-4 at most.
    areas = spectra.cmf_integrals()
    assert np.ptp(areas) / areas[1] < 4e-4


@pytest.mark.parametrize("count", GRID_SIZES)
def test_flat_spectrum_is_xyz_one(count):
    grid = spectra.wavelength_grid(count)
    np.testing.assert_allclose(spectra.spectrum_to_xyz(np.ones(count), grid), 1.0, atol=TOL_ROUNDING)


def test_flat_spectrum_is_xyz_one_on_irregular_grids_and_with_explicit_weights():
    rng = np.random.default_rng(3)
    grid = np.sort(rng.uniform(355.0, 835.0, 90))
    np.testing.assert_allclose(spectra.spectrum_to_xyz(np.ones(90), grid), 1.0, atol=TOL_ROUNDING)
    lam = np.arange(380.0, 781.0, 5.0)
    xyz = spectra.spectrum_to_xyz(np.ones(lam.size), lam, weights=np.full(lam.size, 5.0))
    np.testing.assert_allclose(xyz, 1.0, atol=TOL_ROUNDING)


def test_spectrum_to_xyz_agrees_with_colour_science():
    # colour's 'Integration' method is a plain 1 nm sum with k = 100/Σȳ; ours integrates the
    # interpolant cell by cell with a per-channel area. Rescaled to colour's k the two differ
    # by the O(Δ²) product-quadrature term, measured 1.2e-5 on D65: 5e-5 is the bound.
    sd = colour.SDS_ILLUMINANTS["D65"].copy().align(colour.SpectralShape(360, 830, 1))
    cmfs = colour.MSDS_CMFS[spectra.CMFS_NAME]
    expected = colour.sd_to_XYZ(sd, cmfs, illuminant=colour.sd_ones(sd.shape), method="Integration") / 100.0
    areas = spectra.cmf_integrals()
    ours = spectra.spectrum_to_xyz(sd.values, sd.wavelengths) * areas / areas[1]
    np.testing.assert_allclose(ours, expected, rtol=5e-5)


def test_spectrum_to_xyz_broadcasts_and_is_linear():
    grid = spectra.wavelength_grid(40)
    rng = np.random.default_rng(0)
    spectra_block = rng.uniform(0.0, 2.0, (4, 5, 40))
    xyz = spectra.spectrum_to_xyz(spectra_block, grid)
    assert xyz.shape == (4, 5, 3)
    np.testing.assert_allclose(
        xyz[2, 3], spectra.spectrum_to_xyz(spectra_block[2, 3], grid), rtol=TOL_ROUNDING
    )
    np.testing.assert_allclose(xyz, spectra_block @ spectra.xyz_weights(grid), rtol=TOL_ROUNDING)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"spectrum": np.ones(5), "wavelengths_nm": np.linspace(400, 700, 6)}, "spectrum"),
        ({"spectrum": np.ones(3), "wavelengths_nm": [500.0, 400.0, 600.0]}, "wavelengths_nm"),
        ({"spectrum": np.ones(3), "wavelengths_nm": [400.0, np.nan, 600.0]}, "wavelengths_nm"),
        ({"spectrum": [1.0, np.inf, 1.0], "wavelengths_nm": [400.0, 500.0, 600.0]}, "spectrum"),
        (
            {"spectrum": np.ones(3), "wavelengths_nm": [400.0, 500.0, 600.0], "weights": [1.0, -1.0, 1.0]},
            "weights",
        ),
        ({"spectrum": np.ones(3), "wavelengths_nm": [400.0, 500.0, 600.0], "weights": [1.0, 1.0]}, "weights"),
        ({"spectrum": np.ones(1), "wavelengths_nm": [500.0]}, "wavelengths_nm"),
        ({"spectrum": [], "wavelengths_nm": []}, "wavelengths_nm"),
    ],
)
def test_spectrum_to_xyz_rejects_bad_input(kwargs, name):
    with pytest.raises(ValueError, match=name):
        spectra.spectrum_to_xyz(**kwargs)


# --------------------------------------------------------------------------------------------
# Illuminants
# --------------------------------------------------------------------------------------------


def _cie_chromaticity(name):
    """xy with the CIE's single constant k (undo the per-channel E normalisation)."""
    grid = spectra.wavelength_grid(spectra.DENSE_BIN_COUNT)
    xyz = spectra.spectrum_to_xyz(spectra.illuminant_spd(name, grid), grid) * spectra.cmf_integrals()
    return xyz[:2] / xyz.sum()


@pytest.mark.parametrize(
    ("name", "xy"),
    # CIE 015:2018 Table 3 / CIE 15.2 Table 1.1 (5 decimals). Our 1 nm integral of the
    # interpolated 5 nm tables lands within 3e-5 of them; 1e-4 covers the last printed digit.
    [
        ("D65", (0.31272, 0.32903)),
        ("A", (0.44757, 0.40745)),
        ("FL2", (0.37208, 0.37529)),
        ("E", (1 / 3, 1 / 3)),
    ],
)
def test_illuminant_chromaticities_match_cie(name, xy):
    """Our illuminant spectra have the CIE's published chromaticities (1e-4): the white point of every colour
    we make is right."""
    np.testing.assert_allclose(_cie_chromaticity(name), xy, atol=1e-4)


@pytest.mark.parametrize("name", spectra.ILLUMINANTS)
def test_illuminants_are_normalised_to_unit_luminance(name):
    grid = spectra.wavelength_grid(spectra.DENSE_BIN_COUNT)
    y = spectra.spectrum_to_xyz(spectra.illuminant_spd(name, grid), grid)[1]
    assert abs(y - 1.0) < TOL_ROUNDING


def test_illuminant_e_is_flat_one_and_aliases_work():
    np.testing.assert_allclose(spectra.illuminant_spd("E", np.linspace(360, 830, 50)), 1.0, rtol=TOL_ROUNDING)
    lam = np.linspace(380, 780, 81)
    np.testing.assert_array_equal(spectra.illuminant_spd("F7", lam), spectra.illuminant_spd("FL7", lam))
    table_lam, table_values = spectra.illuminant_table("FL2")
    assert table_lam[0] == 380.0 and np.all(np.diff(table_lam) == 5.0)
    np.testing.assert_allclose(spectra.illuminant_spd("FL2", table_lam), table_values, rtol=TOL_ROUNDING)


def test_unknown_illuminant_lists_the_valid_names():
    with pytest.raises(ValueError, match=r"name must be one of .*'D65'"):
        spectra.illuminant_spd("D50x", [500.0])


# --------------------------------------------------------------------------------------------
# Working spaces
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("space", SPACES)
def test_flat_spectrum_is_rgb_white(space):
    grid = spectra.wavelength_grid(64)
    rgb = rgb_spaces.xyz_to_rgb_matrix(space) @ spectra.spectrum_to_xyz(np.ones(64), grid)
    np.testing.assert_allclose(rgb, 1.0, atol=1e-6)  # the brief's bound; measured ≤ 2e-15
    np.testing.assert_allclose(rgb_spaces.rgb_to_xyz_matrix(space) @ np.ones(3), 1.0, atol=TOL_ROUNDING)


@pytest.mark.parametrize("source", SPACES)
@pytest.mark.parametrize("target", SPACES)
def test_rgb_to_rgb_composes_and_keeps_white(source, target):
    m = rgb_spaces.rgb_to_rgb_matrix(source, target)
    np.testing.assert_allclose(m @ np.ones(3), 1.0, atol=TOL_ROUNDING)
    np.testing.assert_allclose(rgb_spaces.rgb_to_rgb_matrix(target, source) @ m, np.eye(3), atol=TOL_ROUNDING)


def test_rec709_green_primary_chromaticity():
    """Rec.709 green taken to XYZ(E) and adapted back to D65 lands on the BT.709 primary: the adaptation and
    primaries are composed in the right order."""
    # Rec.709 pure green, taken to XYZ(E) and adapted back to D65, must sit on the BT.709
    # green primary (0.30, 0.60): checks that the adaptation and the primaries are composed
    # in the right order (an order swap moves it by > 1e-3).
    xyz_e = rgb_spaces.rgb_to_xyz_matrix("Linear Rec.709") @ np.array([0.0, 1.0, 0.0])
    d65 = colour.xy_to_XYZ(colour.RGB_COLOURSPACES["ITU-R BT.709"].whitepoint)
    xyz_d65 = rgb_spaces.bradford_matrix(np.ones(3), d65) @ xyz_e
    np.testing.assert_allclose(xyz_d65[:2] / xyz_d65.sum(), (0.30, 0.60), atol=1e-9)


def test_unknown_space_lists_the_valid_names():
    with pytest.raises(ValueError, match=r"space must be one of .*'ACEScg'.*'Linear Rec.709'"):
        rgb_spaces.xyz_to_rgb_matrix("sRGB")


# --------------------------------------------------------------------------------------------
# Blender's OCIO config
# --------------------------------------------------------------------------------------------


def _blender_colormanagement() -> pathlib.Path:
    spec = importlib.util.find_spec("bpy")  # locates the package without importing it
    if spec is None or not spec.submodule_search_locations:
        pytest.skip("bpy is not installed")
    for root in spec.submodule_search_locations:
        found = sorted(pathlib.Path(root).glob("*/datafiles/colormanagement/config.ocio"))
        if found:
            return found[-1].parent
    pytest.fail("bpy is installed but has no datafiles/colormanagement/config.ocio")


def _ocio_matrix(config: str, space: str) -> np.ndarray:
    """The 3×3 part of the MatrixTransform in ``space``'s from_scene_reference group."""
    block = config.split(f"name: {space}\n", 1)[1].split("- !<ColorSpace>", 1)[0]
    values = re.search(r"MatrixTransform> \{matrix: \[([^\]]+)\]", block).group(1)
    return np.array([float(v) for v in values.split(",")]).reshape(4, 4)[:3, :3]


def _blender_matrices():
    folder = _blender_colormanagement()
    config = (folder / "config.ocio").read_text()
    # "Linear CIE-XYZ E" = XYZ D65 → inverse(xyz_E_to_D65.spimtx), so the spimtx is E → D65.
    assert "src: xyz_E_to_D65.spimtx, interpolation: linear, direction: inverse" in config
    e_to_d65 = np.loadtxt(folder / "luts" / "xyz_E_to_D65.spimtx")[:, :3]
    return e_to_d65, {space: _ocio_matrix(config, space) for space in ("Linear Rec.709", "Linear Rec.2020")}


@pytest.mark.parametrize("space", ["Linear Rec.709", "Linear Rec.2020"])
def test_xyz_e_to_rgb_matches_blender(space):
    e_to_d65, d65_to_rgb = _blender_matrices()
    blender = d65_to_rgb[space] @ e_to_d65
    ours = rgb_spaces.xyz_to_rgb_matrix(space)
    # Relative to the matrix's largest entry. Blender's E→D65 matrix adapts to a D65 white of
    # XYZ (0.95047, 1, 1.08883) while its XYZ→RGB matrices (and colour) use xy (0.3127, 0.3290),
    # whose Z is 1.089058: a 2.1e-4 difference in one white component (see the next test),
    # which moves the composed matrix by 7.8e-5 (Rec.709) and 1.3e-4 (Rec.2020) of its largest
    # entry. 2e-4 bounds that; the config's 7–8 printed digits (≤ 5e-8) are far below it.
    assert np.abs(ours - blender).max() / np.abs(blender).max() < 2e-4


def test_blender_matrices_explained():
    """Blender's OCIO matrices are explained by colour-science (XYZ → RGB) and Bradford(E → D65) to their
    printed decimals: our spectral colour uses Blender's conventions."""
    e_to_d65, d65_to_rgb = _blender_matrices()
    # The XYZ(D65) → RGB matrices are colour's to the 7 printed decimals (rounding ≤ 5e-8).
    for space, name in (("Linear Rec.709", "ITU-R BT.709"), ("Linear Rec.2020", "ITU-R BT.2020")):
        np.testing.assert_allclose(
            d65_to_rgb[space], colour.RGB_COLOURSPACES[name].matrix_XYZ_to_RGB, atol=1e-7
        )
    # The spimtx is Bradford(E → (0.95047, 1, 1.08883)) to its 8 printed decimals (≤ 5e-9,
    # measured 4e-9), and not Bradford(E → xy (0.3127, 0.3290)) (off by 2.3e-4).
    blender_d65 = np.array([0.95047, 1.0, 1.08883])
    np.testing.assert_allclose(rgb_spaces.bradford_matrix(np.ones(3), blender_d65), e_to_d65, atol=1e-8)
    colour_d65 = colour.xy_to_XYZ(colour.RGB_COLOURSPACES["ITU-R BT.709"].whitepoint)
    assert np.abs(rgb_spaces.bradford_matrix(np.ones(3), colour_d65) - e_to_d65).max() > 1e-4
    # Consequence: Blender maps a flat (E) spectrum to Rec.709 (1.00016, 0.99998, 0.99976).
    np.testing.assert_allclose(d65_to_rgb["Linear Rec.709"] @ e_to_d65 @ np.ones(3), 1.0, atol=3e-4)


# --------------------------------------------------------------------------------------------
# RGB → spectrum (Mallett & Yuksel 2019)
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("space", SPACES)
@pytest.mark.parametrize("count", GRID_SIZES)
def test_rgb_basis_round_trips_exactly(space, count):
    grid = spectra.wavelength_grid(count)
    basis = rgb_spaces.rgb_basis(grid, space)
    assert basis.shape == (3, count)
    roundtrip = basis @ spectra.xyz_weights(grid) @ rgb_spaces.xyz_to_rgb_matrix(space).T
    np.testing.assert_allclose(roundtrip, np.eye(3), atol=1e-10)  # brief's bound; measured ≤ 5e-16
    # The acceptance: RGB white → spectrum → XYZ(E) → RGB is white within 1e-4.
    white = rgb_spaces.xyz_to_rgb_matrix(space) @ spectra.spectrum_to_xyz(np.ones(3) @ basis, grid)
    np.testing.assert_allclose(white, 1.0, atol=1e-4)
    rgb = np.random.default_rng(count).uniform(-0.5, 4.0, (50, 3))
    back = spectra.spectrum_to_xyz(rgb @ basis, grid) @ rgb_spaces.xyz_to_rgb_matrix(space).T
    np.testing.assert_allclose(back, rgb, atol=1e-10)


@pytest.mark.parametrize("space", SPACES)
@pytest.mark.parametrize("count", GRID_SIZES)
def test_rgb_basis_white_is_flat(space, count):
    # Mallett & Yuksel's three curves sum to 1 within 1.0e-5 (colour's 5 nm table); the
    # correction keeps white because white already round-trips. 1e-4 bounds both.
    basis = rgb_spaces.rgb_basis(spectra.wavelength_grid(count), space)
    np.testing.assert_allclose(basis.sum(axis=0), 1.0, atol=1e-4)


@pytest.mark.parametrize("space", SPACES)
@pytest.mark.parametrize("count", GRID_SIZES)
def test_uncorrected_round_trip_is_within_a_few_percent(space, count):
    # The correction must be small (Mallett's basis is built for sRGB reflectance under D65)
    # but not nil (else it would be dead code). Measured max|T − I| 0.037–0.074.
    deviation = np.abs(
        rgb_spaces.rgb_basis_roundtrip_matrix(spectra.wavelength_grid(count), space) - np.eye(3)
    ).max()
    assert 0.01 < deviation < 0.1


def test_rec709_basis_is_nonnegative_on_a_fine_grid():
    # Mallett's basis is non-negative (reflectances in [0, 1]); the < 7 % correction keeps it
    # so on a 1 nm grid (measured minimum 1.7e-3). Wider gamuts go negative by design.
    assert rgb_spaces.rgb_basis(spectra.wavelength_grid(471)).min() >= 0.0
    assert rgb_spaces.rgb_basis(spectra.wavelength_grid(471), "Linear Rec.2020").min() < 0.0


def test_rgb_basis_rejects_bad_input():
    with pytest.raises(ValueError, match="space"):
        rgb_spaces.rgb_basis(spectra.wavelength_grid(16), "Rec.709")
    with pytest.raises(ValueError, match="wavelengths_nm"):
        rgb_spaces.rgb_basis(np.array([[400.0, 500.0]]))


# Cycles' film: XYZ → scene linear through Blender's OCIO config (PyOpenColorIO ships with bpy).
#: OCIO's built-in ACES AP0 → XYZ D65 matrix (UTILITY - ACES-AP0_to_CIE-XYZ-D65_BFD): the one
#: Cycles' ColorSpaceManager composes with the config's ``aces_interchange`` role.
AP0_TO_XYZ_D65 = np.array(
    [[0.938280, -0.004451, 0.016628], [0.337369, 0.729522, -0.066890], [0.001174, -0.003711, 1.091595]]
)


def _ocio_to_scene_linear(ocio, config, source: str, scene_linear: str) -> np.ndarray:
    """The matrix of OCIO's source → ``scene_linear`` processor, read off the unit vectors."""
    processor = config.getProcessor(source, scene_linear).getDefaultCPUProcessor()
    return np.array([processor.applyRGB(list(e)) for e in np.eye(3)], dtype=np.float64).T


@pytest.mark.blender
@pytest.mark.parametrize("space", SPACES)
def test_scene_linear_matrix_is_blenders_xyz_to_scene_linear(bpy, space):
    bpy.utils.expose_bundled_modules()
    import PyOpenColorIO as ocio

    config = ocio.Config.CreateFromFile(str(_blender_colormanagement() / "config.ocio"))
    assert config.hasRole("aces_interchange")  # what Cycles derives its matrix from first
    via_aces = _ocio_to_scene_linear(ocio, config, "ACES2065-1", space) @ np.linalg.inv(AP0_TO_XYZ_D65)
    via_xyz = _ocio_to_scene_linear(ocio, config, "Linear CIE-XYZ D65", space)
    ours = rgb_spaces.scene_linear_matrix(space)
    # OCIO evaluates in float32 (≈ 6e-8 relative) and the built-in AP0 matrix is printed to 6
    # decimals (5e-7): 2e-6 of the largest entry bounds both routes; measured ≤ 1.1e-6.
    for blender in (via_aces, via_xyz):
        assert np.abs(ours - blender).max() / np.abs(blender).max() < 2e-6
