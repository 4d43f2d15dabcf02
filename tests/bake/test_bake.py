"""Bake: fast factorised tables against the brute-force baker, hard cases, auto choices, storage."""

import math

import numpy as np
import pytest

from precompute import brdf
from precompute.bakes import bake, planner, sh_order
from precompute.bakes.bake_reference import bake_reference
from precompute.colour import rgb_spaces, spectra
from precompute.materials.material import MAX_SH_ORDER, PRESETS, Layer, Material, Quality, preset
from precompute.optics import reflectance
from precompute.tables import table_io

SQRT_4PI = math.sqrt(4 * math.pi)
# 19 view angles = 5° steps, so 80°, 85° and 90° (grazing) are all in the comparison.
SMALL = Quality(sh_order=4, view_samples=19, thickness_samples=2)

GRID = {
    "soap glossy": preset("soap_film").with_(quality=SMALL),
    "soap rough": preset("soap_film").with_(roughness=0.6, quality=SMALL),
    "oil on water": preset("oil_on_water").with_(quality=SMALL),
    "titanium (metal)": preset("anodised_titanium").with_(quality=SMALL),
    "beetle stack": preset("beetle_multilayer").with_(quality=Quality(sh_order=3, view_samples=10)),
    "diffuse base": preset("coated_car_window").with_(base_color=(0.6, 0.3, 0.1), quality=SMALL),
    "per channel": preset("soap_film").with_(colour_mode="per_channel", quality=SMALL),
    "fluorescent FL2": preset("coated_car_window").with_(illuminant="FL2", quality=SMALL),
    "glassner": preset("soap_film").with_(model="glassner2000", quality=SMALL),
}


@pytest.mark.parametrize("name", list(GRID))
def test_fast_bake_matches_brute_force_reference(name):
    material = GRID[name]
    fast = bake.bake(material)
    ref = bake_reference(material)
    assert fast.data.shape == ref.data.shape
    rel = np.max(np.abs(fast.data - ref.data)) / np.max(np.abs(ref.data))
    # Same quadrature nodes; the only difference is the piecewise-Chebyshev interpolation of
    # R(u), accepted at ≤ 1e-6 of max R on test points → ≤ 1e-4 on the table with margin.
    # Per channel, Cycles' clamp of the film RGB to [0, 1] puts a kink in u wherever a channel
    # crosses 0, and polynomial interpolation through a kink converges only as O(h²): measured
    # 2.5e-4 even at 64 nodes per interval, 3.3e-4 at the chosen degree (≈ 0.01 ΔE2000).
    limit = 1e-3 if material.colour_mode == "per_channel" else 1e-4
    assert rel <= limit, f"{name}: relative difference {rel:.2e}"


def albedo_rgb(result, t=0):
    """Response to white uniform light: M_0 · (√4π, √4π, √4π), shape (A, 3)."""
    m0 = result.data[t, :, 0]
    return (m0 @ np.full(3, SQRT_4PI)) if m0.ndim == 3 else m0 * SQRT_4PI


def test_l0_entry_is_the_directional_albedo_of_an_independent_quadrature():
    material = Material(
        layers=(Layer(1.33, 350.0),),
        roughness=0.4,
        multiscatter="none",  # the identity below is for the single-scattering lobe
        quality=Quality(sh_order=2, view_samples=7, wavelength_count=64),
    )
    result = bake.bake(material)
    wl, g = bake.spectral_quadrature(64, material.colour_space, "E", "spectral")

    def film(c):
        return reflectance(material.indices(), material.thicknesses(), wl, c)

    albedo = brdf.directional_albedo(np.cos(result.view_angles_rad), 0.4, film, 256, 128)  # full-φ grid
    expected = np.einsum("aw,wkc->ak", albedo, g)
    # Two different quadratures of the same integral (half-range φ with 96×48 vs full φ with
    # 256×128 nodes): measured ≤ 1.4e-5 of the peak below 90°, 1.6e-4 at exactly 90° where
    # the horizon cuts the lobe and both converge slowest.
    err = np.abs(albedo_rgb(result) - expected) / np.max(expected)
    assert np.max(err[:-1]) <= 5e-5 and np.max(err[-1]) <= 3e-4


HARD = {
    "normal and grazing views": Material(roughness=0.3, quality=Quality(view_samples=91)),
    "zero thickness": Material(layers=(Layer(1.5, 0.0),), substrate=1.5, roughness=0.3),
    "20 µm film": Material(layers=(Layer(1.33, 20000.0),), roughness=0.3),
    "film below the ambient (TIR)": Material(
        ambient=1.5, layers=(Layer(1.2, 300.0),), substrate=1.5, roughness=0.3
    ),
    "gold": Material(layers=(Layer(1.4, 100.0),), substrate={"metal": "gold"}, roughness=0.2),
    "roughness 0.02": Material(roughness=0.02, quality=Quality(sh_order=8)),
    "roughness 1": Material(roughness=1.0),
    "SH order 8": Material(roughness=0.5, quality=Quality(sh_order=8)),
}


@pytest.mark.parametrize("name", list(HARD))
def test_hard_cases_are_finite_and_physically_bounded(name):
    result = bake.bake(HARD[name])
    assert np.all(np.isfinite(result.data))
    # White in, at most white out — in XYZ: R(λ) ∈ [0, 1] and CMFs ≥ 0 bound each of X, Y, Z
    # by the white's 1. (RGB is no bound: saturated film colours such as gold's red lie outside
    # Rec.709 and legitimately exceed 1 or dip below 0 in one channel.) 2e-3 covers the linear
    # basis summing to 1 only within 1e-5 and the single-scatter quadrature near grazing.
    xyz = albedo_rgb(result) @ rgb_spaces.rgb_to_xyz_matrix("Linear Rec.709").T
    assert np.all(xyz >= -2e-3) and np.all(xyz <= 1.0 + 2e-3), (xyz.min(), xyz.max())


def test_zero_thickness_film_equals_the_bare_substrate():
    film = bake.bake(
        Material(
            layers=(Layer(2.0, 0.0),),
            substrate=1.5,
            roughness=0.3,
            quality=Quality(sh_order=3, view_samples=9, wavelength_count=48),
        )
    )
    bare = bake.bake(
        Material(
            layers=(),
            substrate=1.5,
            roughness=0.3,
            quality=Quality(sh_order=3, view_samples=9, wavelength_count=48),
        )
    )
    assert np.max(np.abs(film.data - bare.data)) <= 1e-12


def test_thin_film_colours_a_white_light_and_glassner_differs_from_exact():
    exact = bake.bake(preset("soap_film").with_(quality=SMALL))
    approx = bake.bake(preset("soap_film").with_(model="glassner2000", quality=SMALL))
    a = albedo_rgb(exact, t=1)[0]  # 1000 nm film, normal view
    assert np.ptp(a) > 0.005  # coloured, not grey
    assert np.max(np.abs(exact.data - approx.data)) > 1e-3


@pytest.mark.parametrize(("count", "tol"), [(48, 3e-3), (256, 1e-3)])
def test_spectral_quadrature_integrates_illuminants_including_lines(count, tol):
    for illuminant in ("E", "D65", "FL2", "FL11"):
        wl, g = bake.spectral_quadrature(count, "Linear Rec.709", illuminant, "spectral")
        white_light_response = g.sum(axis=(0, 2))  # a film with R ≡ 1 under RGB (1, 1, 1)
        lam, s = spectra.illuminant_table(illuminant) if illuminant != "E" else (None, None)
        if illuminant == "E":
            expected = np.ones(3)
        else:
            expected = rgb_spaces.xyz_to_rgb_matrix("Linear Rec.709") @ spectra.spectrum_to_xyz(
                s, lam, weights=np.gradient(lam)
            )
        # Lines are exact nodes; what remains is the smooth part sampled once per cell against the
        # cell-integrated CMFs: measured 2.8e-3 (FL) / 6.9e-4 (D65) at 48 cells, 6e-4 at 256,
        # against a Riemann sum of the 5 nm table (itself good to ~2e-4).
        assert np.allclose(white_light_response, expected, atol=tol), illuminant
    wl, _ = bake.spectral_quadrature(48, "Linear Rec.709", "FL2", "spectral")
    assert wl.size > 48 and np.any(np.abs(wl - 546.0) < 3.0)  # mercury line is its own node


def test_per_channel_mode_is_diagonal_and_matches_spectral_on_white():
    spectral = bake.bake(preset("soap_film").with_(quality=SMALL))
    per_ch = bake.bake(preset("soap_film").with_(colour_mode="per_channel", quality=SMALL))
    assert per_ch.data.shape == spectral.data.shape[:-1]
    # Under white light both reduce to the film's CIE-weighted RGB reflectance; they differ only
    # through the RGB basis's spectral shape (per-channel ignores it). Measured ≤ 0.02.
    assert np.allclose(albedo_rgb(per_ch), albedo_rgb(spectral), atol=0.03)


def test_automatic_choices_follow_the_physics():
    thin = planner.plan(Material(layers=(Layer(1.33, 200.0),)))
    thick = planner.plan(Material(layers=(Layer(1.33, 20000.0),)))
    assert thick.wavelength_count > 10 * thin.wavelength_count >= 10 * 48
    assert thin.thickness_samples == 1  # constant thickness → 1-D table
    varying = planner.plan(Material(layers=(Layer(1.33, 300.0),), thickness_range_nm=(0.0, 2000.0)))
    assert (
        varying.thickness_samples
        > planner.plan(
            Material(layers=(Layer(1.33, 300.0),), thickness_range_nm=(0.0, 200.0))
        ).thickness_samples
    )
    orders = [planner.plan(Material(roughness=r)).sh_order for r in (0.1, 0.5, 0.8, 1.0)]
    # Judged at normal and 80° views (the horizon cuts grazing lobes): measured 12, 12, 7, 6
    # (glossy lobes need more than the cap; rough ones stop early).
    assert orders[0] == orders[1] == MAX_SH_ORDER and orders[2] < orders[1] and orders[3] <= orders[2]
    assert all(isinstance(v, str) and v for v in thin.reasons.values())
    assert sh_order.lobe_truncation_error(1.0, 4) < sh_order.lobe_truncation_error(0.3, 4)


@pytest.mark.parametrize("unused_nm", [0.0, 300.0, 100000.0])
def test_an_unused_top_layer_thickness_changes_neither_plan_nor_key_nor_cost(unused_nm):
    """Issue 24: with a thickness range the top layer's own thickness is unused by the table,
    yet 100 µm of it made the wavelength count 3,348 instead of 48 (a 5–7× slower bake of an
    identical table). It must change neither the plan, the table key, the planned cost nor the
    table."""
    from precompute.effects import plans

    quality = Quality(sh_order=2, view_samples=4, thickness_samples=4)  # wavelengths automatic
    used = Material(
        layers=(Layer(1.33, 300.0),), substrate=1.5, roughness=0.3, thickness_range_nm=(100.0, 300.0)
    )
    used = used.with_(quality=quality)
    other = used.with_(layers=(Layer(1.33, unused_nm),))
    assert planner.plan(other) == planner.plan(used) and planner.plan(used).wavelength_count == 48
    assert planner.table_key(other) == planner.table_key(used)
    assert planner.table_material(other) == planner.table_material(used)
    a, b = plans.material_plan(used), plans.material_plan(other)
    assert (a.key, a.plan, a.bake_seconds, a.u_degree, a.reasons) == (
        b.key,
        b.plan,
        b.bake_seconds,
        b.u_degree,
        b.reasons,
    )
    first, second = bake.bake(used), bake.bake(other)
    # Bit for bit: the unused value is never read, so both bakes run the same arithmetic in this
    # process (a value that was read would move entries by far more than rounding).
    np.testing.assert_array_equal(
        first.data, second.data, err_msg="a thickness range that is not used changed the bake"
    )
    assert first.attributes()["material"] == second.attributes()["material"]
    # A constant thickness is used: there it still counts.
    still = Material(layers=(Layer(1.33, 300.0),), substrate=1.5)
    assert planner.table_key(still.with_(layers=(Layer(1.33, 310.0),))) != planner.table_key(still)
    assert planner.table_material(still) is still


def test_constant_thickness_table_has_a_single_thickness_row():
    result = bake.bake(preset("beetle_multilayer").with_(quality=Quality(sh_order=2, view_samples=4)))
    assert result.data.shape[0] == 1 and result.thicknesses_nm.size == 1


@pytest.mark.parametrize("precision", ["float", "half"])
def test_baked_table_round_trips_through_exr(tmp_path, precision):
    result = bake.bake(preset("oil_on_water").with_(quality=SMALL))
    path = table_io.write_table(tmp_path / "t.exr", result.data, result.attributes(), precision=precision)
    table = table_io.read_table(path, expect={"sh_order": 4, "colour_space": "Linear Rec.709"})
    if precision == "float":
        assert np.array_equal(table.data, result.data.astype(np.float32))
    else:  # half: 10-bit mantissa → ≤ 2^-11 relative, or 2^-25 absolute below 2^-14
        tol = np.maximum(np.abs(result.data) * 2.0**-11, 2.0**-25)
        assert np.all(np.abs(table.data - result.data) <= tol * 1.0001 + 1e-7 * 0)
    assert Material.from_dict(table.attributes["material"]) == result.material
    with pytest.raises(table_io.TableError, match="sh_order"):
        table_io.read_table(path, expect={"sh_order": 8})


@pytest.mark.parametrize("mode", ["none", "film", "cycles"])
def test_multiscatter_modes_add_energy_only_where_single_scattering_loses_it(mode):
    base = preset("coated_car_window").with_(roughness=0.8, quality=SMALL)
    plain = albedo_rgb(bake.bake(base.with_(multiscatter="none")), t=0)
    comp = albedo_rgb(bake.bake(base.with_(multiscatter=mode)), t=0)
    if mode == "none":  # the same material twice in this process: the same arithmetic, bit for bit
        np.testing.assert_array_equal(comp, plain, err_msg="multiscatter 'none' must add nothing")
    else:
        assert np.all(comp >= plain - 1e-12) and np.any(comp > plain * 1.01)  # rough lobe: energy added
    xyz = comp @ rgb_spaces.rgb_to_xyz_matrix("Linear Rec.709").T
    assert np.all(xyz <= 1.0 + 2e-3)  # never above white
    smooth = preset("coated_car_window").with_(roughness=0.05, quality=SMALL)
    assert np.allclose(
        albedo_rgb(bake.bake(smooth.with_(multiscatter=mode))),
        albedo_rgb(bake.bake(smooth.with_(multiscatter="none"))),
        rtol=2e-3,
    )  # E ≈ 1


def test_roughness_is_squared_like_cycles():
    # Cycles' Principled BSDF: alpha = roughness² (intern/cycles/kernel/svm/closure.h).
    assert float(brdf.alpha_from_roughness(0.5)) == 0.25
    assert float(brdf.alpha_from_roughness(0.0)) > 0  # clamped, never a delta


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"roughness": 1.5}, "roughness"),
        ({"roughness": float("nan")}, "roughness"),
        ({"layers": (Layer(1.33, -5.0),)}, r"layers\[0\].thickness_nm"),
        ({"layers": (Layer(1.33, float("inf")),)}, r"layers\[0\].thickness_nm"),
        ({"layers": (Layer([1.5, -0.1], 100.0),)}, r"layers\[0\].index.*extinction"),
        ({"layers": (Layer(0.0, 100.0),)}, r"layers\[0\].index.*n > 0"),
        ({"substrate": {"metal": "unobtainium"}}, "unobtainium"),
        ({"substrate": "glass"}, "substrate"),
        ({"ambient": 0.5}, "ambient"),
        ({"thickness_range_nm": (500.0, 100.0)}, "thickness_range_nm"),
        ({"base_color": (2.0, 0.0, 0.0)}, "base_color"),
        ({"model": "magic"}, "model"),
        ({"colour_space": "sRGB-ish"}, "sRGB-ish"),
        ({"quality": Quality(sh_order=MAX_SH_ORDER + 1)}, "quality.sh_order"),
        ({"quality": Quality(view_samples=1)}, "quality.view_samples"),
    ],
)
def test_invalid_material_parameters_are_named(changes, match):
    with pytest.raises(ValueError, match=match):
        Material(**changes)


def test_presets_round_trip_through_dicts():
    for name, material in PRESETS.items():
        assert Material.from_dict(material.to_dict()) == material, name
    with pytest.raises(ValueError, match="unknown preset"):
        preset("chrome")
    with pytest.raises(ValueError, match="unknown material parameters"):
        Material.from_dict({"colour": 1})


@pytest.mark.parametrize("top_nm", [1010.0, 1100.0])
def test_the_u_degree_is_the_lowest_rung_that_meets_the_tolerance(top_nm):
    """choose_u_degree probes the ladder's rungs in groups (one sweep per group): the degree
    must still be the lowest rung whose interpolation error, measured on its own, meets
    U_TOLERANCE, and R at its nodes the sweep's own."""
    from precompute.bakes.chunks import chunked_sweep
    from precompute.bakes.kernel import u_interpolation_matrix, u_nodes

    assert sum(planner.U_PROBE_GROUPS, ()) == planner.U_DEGREE_LADDER
    material = planner.table_material(PRESETS["soap_film"].with_(thickness_range_nm=(0.0, top_nm)))
    p = planner.plan(material)
    wl, _g = bake.spectral_quadrature(
        p.wavelength_count, material.colour_space, material.illuminant, material.colour_mode
    )
    indices, sets, _axis = planner.active_stack(material, p.thickness_samples)
    degree, err, at_nodes = planner.choose_u_degree(indices, sets, wl, "exact")
    probe = sets[np.unique(np.linspace(0, sets.shape[0] - 1, 4).round().astype(int))]
    errors = {}
    for rung in planner.U_DEGREE_LADDER[: planner.U_DEGREE_LADDER.index(degree) + 1]:
        nodes, test = u_nodes(rung), planner._test_points(rung)
        with np.errstate(invalid="ignore", divide="ignore"):
            values, exact = (
                chunked_sweep(indices, probe, wl, nodes, "exact"),
                chunked_sweep(indices, probe, wl, test, "exact"),
            )
        interp = np.matmul(u_interpolation_matrix(rung, test), values)
        errors[rung] = float(np.max(np.abs(interp - exact))) / max(float(np.abs(exact).max()), 1e-6)
    assert errors[degree] <= planner.U_TOLERANCE and errors[degree] == pytest.approx(err, rel=1e-9)
    assert all(e > planner.U_TOLERANCE for rung, e in errors.items() if rung < degree), errors
    assert degree > planner.U_DEGREE_LADDER[0]  # the check can fail: a lower rung was tried and refused
    with np.errstate(invalid="ignore", divide="ignore"):
        swept = chunked_sweep(indices, sets, wl, u_nodes(degree), "exact")
    np.testing.assert_allclose(at_nodes, swept, atol=1e-14)
