"""Thin-film optics against independent implementations (tmm, colour) and closed forms."""

import math

import numpy as np
import pytest
import tmm
from hypothesis import given
from hypothesis import strategies as st

from precompute.optics import (
    FUSED_SILICA,
    CauchyIndex,
    ConstantIndex,
    SellmeierIndex,
    TabulatedIndex,
    airy_is_exact,
    reflectance,
    reflectance_sweep,
)

# float64 against independent code: both sides round ~1e-16 per operation; a 20-layer stack
# accumulates a few hundred operations, so 1e-9 absolute leaves six orders of margin.
TOL_INDEPENDENT = 1e-9


def tmm_reference(indices, thicknesses, wavelengths, cos_theta, polarization):
    """Reflectance from the `tmm` package (Byrnes), one (angle, wavelength) at a time."""
    out = np.empty((len(cos_theta), len(wavelengths)))
    d_list = [np.inf, *thicknesses, np.inf]
    for a, c in enumerate(cos_theta):
        theta = math.acos(c)
        for w, lam in enumerate(wavelengths):
            n_list = [complex(np.asarray(n)[w]) if np.ndim(n) else complex(n) for n in indices]
            pols = ("s", "p") if polarization == "unpolarized" else (polarization,)
            out[a, w] = np.mean([tmm.coh_tmm(p, n_list, d_list, theta, lam)["R"] for p in pols])
    return out


dielectric = st.floats(1.0, 3.0)
low_index = st.floats(1.0, 1.6)  # below a 1.6+ ambient → total internal reflection
metal = st.builds(complex, st.floats(0.05, 3.0), st.floats(0.0, 8.0))
thickness = st.one_of(st.just(0.0), st.floats(0.0, 1200.0))
angle_deg = st.one_of(st.just(0.0), st.just(89.99), st.floats(0.0, 89.99))


@st.composite
def stacks(draw):
    layers = draw(st.integers(1, 20))
    ambient = draw(st.sampled_from([1.0, 1.33, 1.7]))
    films = []
    for _ in range(layers):
        kind = draw(st.sampled_from(["dielectric", "low", "metal", "equal"]))
        films.append(
            {"dielectric": draw(dielectric), "low": draw(low_index), "metal": draw(metal), "equal": None}[
                kind
            ]
        )
    substrate = draw(st.one_of(dielectric, metal))
    films = [substrate if f is None else f for f in films]  # "equal": film index = substrate's
    d = [draw(thickness) for _ in range(layers)]
    wl = sorted(draw(st.lists(st.floats(360.0, 830.0), min_size=1, max_size=3)))
    cos = [math.cos(math.radians(draw(angle_deg))) for _ in range(2)]
    pol = draw(st.sampled_from(["s", "p", "unpolarized"]))
    return [ambient, *films, substrate], d, wl, cos, pol


@given(stacks())
def test_reflectance_matches_tmm_package(case):
    """Our thin-film reflectance equals the independent tmm package for each stack, angle and polarisation:
    the core physics is right."""
    indices, d, wl, cos, pol = case
    ours = reflectance(indices, d, wl, cos, pol)
    ref = tmm_reference(indices, d, wl, cos, pol)
    assert ours.shape == (len(cos), len(wl))
    assert np.max(np.abs(ours - ref)) <= TOL_INDEPENDENT


@given(stacks())
def test_stack_and_airy_paths_agree_and_lossless_stacks_are_bounded(case):
    indices, d, wl, cos, pol = case
    exact = reflectance(indices, d, wl, cos, pol, method="stack")
    lossless = all(np.imag(n) == 0 for n in indices)
    if lossless:
        assert np.all(exact >= 0.0) and np.all(exact <= 1.0 + 1e-12)
    single = [indices[0], indices[1], indices[-1]]
    s = reflectance(single, d[:1], wl, cos, pol, method="stack")
    if not airy_is_exact(complex(indices[1])):
        # No material (n < 1 and k < 1): the Airy sum's real form parts from the stack there (a
        # film of 0.08 between two media of 1 at 89.99°, p: airy 1.1e-5, stack 1.6e-20, tmm
        # 1.4e-22), so the default "exact" takes the stack. Over 40000 random films that are
        # materials the two paths agreed within 3.6e-13.
        assert np.max(np.abs(reflectance(single, d[:1], wl, cos, pol) - s)) <= 1e-12
        return
    a = reflectance(single, d[:1], wl, cos, pol, method="airy")
    # The real form's rounding grows as 1 / cos θ at grazing incidence where the film all but
    # vanishes (a metal of 1 + 2i between two media of 1, p, 360 nm; measured 2026-12-08):
    # 0–1e-6 nm at 89.99° (cos 1.7e-4) 5.2e-11–1.03e-10, at cos 1e-3 ≤ 1.6e-12, 0.1 nm 1.2e-12,
    # 1 nm 2.3e-14. The default path drops a 0 nm film before the Airy sum.
    assert np.max(np.abs(a - s)) <= 1e-12 + 2e-14 / min(cos), (np.max(np.abs(a - s)), min(cos))


def test_agrees_with_colour_multilayer_tmm():
    import colour

    wl = np.linspace(360, 830, 48)
    theta_deg = np.array([0.0, 30.0, 60.0, 85.0])
    n = [1.0, 1.38, 2.3, 1.46, 1.52]
    d = [95.0, 60.0, 240.0]
    r_colour, _ = colour.phenomena.multilayer_tmm(n, d, wl, theta_deg)  # (W, A, 1, 2) = [Rs, Rp]
    for k, pol in enumerate(["s", "p"]):
        ours = reflectance(n, d, wl, np.cos(np.radians(theta_deg)), pol)
        assert np.max(np.abs(ours - r_colour[:, :, 0, k].T)) <= TOL_INDEPENDENT


def test_zero_thickness_is_exactly_the_bare_interface():
    wl = np.linspace(360, 830, 17)
    cos = np.linspace(0.0, 1.0, 9)
    bare = reflectance([1.0, 1.5], [], wl, cos)
    film = reflectance([1.0, 2.4, 1.5], [0.0], wl, cos)
    two = reflectance([1.0, 2.4, 1.2 + 0.5j, 1.5], [0.0, 0.0], wl, cos)
    # Bit for bit: zero-thickness layers are removed before any arithmetic, so both sides run the
    # same code on the same numbers in this process (the sweep path below computes them instead).
    np.testing.assert_array_equal(film, bare, err_msg="one 0 nm layer must be removed, not computed")
    np.testing.assert_array_equal(two, bare, err_msg="two 0 nm layers must be removed, not computed")
    # Through the sweep path (no layer removal) it agrees to rounding only.
    swept = reflectance_sweep([1.0, 2.4, 1.5], [[0.0]], wl, cos)[0]
    assert np.max(np.abs(swept - bare)) <= 1e-15


def test_closed_forms_normal_brewster_critical_grazing():
    wl = [550.0]
    assert reflectance([1.0, 1.5], [], wl, [1.0])[0, 0] == pytest.approx(0.04, abs=1e-15)
    brewster = math.atan(1.5)
    assert reflectance([1.0, 1.5], [], wl, [math.cos(brewster)], "p")[0, 0] <= 1e-30
    critical = math.asin(1.0 / 1.5)
    beyond = np.cos(np.linspace(critical + 1e-6, math.pi / 2 - 1e-3, 7))
    assert np.allclose(reflectance([1.5, 1.0], [], wl, beyond), 1.0, atol=1e-12)
    # Total internal reflection with a thin low-index gap: frustrated, so R < 1.
    frustrated = reflectance([1.5, 1.0, 1.5], [50.0], wl, [math.cos(critical + 0.2)])[0, 0]
    assert 0.0 < frustrated < 1.0
    assert np.allclose(reflectance([1.0, 1.33, 1.0], [400.0], wl, [0.0]), 1.0, atol=1e-12)


def test_soap_film_first_order_colour_follows_interference_condition():
    # Constructive reflection at 2 n d = (m + ½) λ for a film in air (half-wave phase flip).
    wl = np.linspace(360, 830, 941)
    for d in (110.0, 130.0, 150.0):
        r = reflectance([1.0, 1.33, 1.0], [d], wl, [1.0])[0]
        assert wl[np.argmax(r)] == pytest.approx(4 * 1.33 * d, abs=1.0)


def test_glassner_two_beam_gap_for_a_soap_film():
    """The paper's eq. 4 against the exact Airy film, soap (n = 1.33) in air.

    Measured gap (0–1000 nm, 360–830 nm): at normal incidence R_f = 0.0201 and the neglected
    multiple-beam terms change R by at most 3.1e-3 absolute (4 % of the exact peak 0.077); at
    80° R_f = 0.347 (unpolarised) and the two-beam model peaks at 1.39 against the exact 0.74,
    a gap of 0.65 absolute — it exceeds 1, which the exact model never does.
    """
    wl = np.linspace(360, 830, 95)
    d = np.linspace(0.0, 1000.0, 201)[:, None]
    exact = reflectance_sweep([1.0, 1.33, 1.0], d, wl, [1.0])
    approx = reflectance_sweep([1.0, 1.33, 1.0], d, wl, [1.0], method="glassner2000")
    gap_normal = np.max(np.abs(exact - approx))
    assert 2.5e-3 < gap_normal < 3.5e-3
    exact80 = reflectance_sweep([1.0, 1.33, 1.0], d, wl, [math.cos(math.radians(80))])
    approx80 = reflectance_sweep([1.0, 1.33, 1.0], d, wl, [math.cos(math.radians(80))], method="glassner2000")
    gap80 = np.max(np.abs(exact80 - approx80))
    assert 0.6 < gap80 < 0.7 and approx80.max() > 1.0 and exact80.max() <= 1.0


def test_sweep_matches_per_thickness_calls():
    wl = np.linspace(400, 700, 11)
    cos = [1.0, 0.3]
    sets = np.array([[100.0, 0.0], [250.0, 80.0], [0.0, 500.0]])
    swept = reflectance_sweep([1.0, 2.0, 1.4, 1.5 + 0.1j], sets, wl, cos)
    for t, row in enumerate(sets):
        assert np.max(np.abs(swept[t] - reflectance([1.0, 2.0, 1.4, 1.5 + 0.1j], row, wl, cos))) <= 1e-14


@pytest.mark.parametrize(
    "indices",
    [[1.0, 1.33, 1.0], [1.0, 2.6 + 0.3j, 2.9 + 3.0j], [1.5, 1.2, 1.0]],
    ids=["soap", "absorbing film on metal", "evanescent film"],
)
def test_a_sweep_over_evenly_spaced_rows_equals_one_call_per_row(indices):
    """A bake's thickness axis is evenly spaced: the Airy sweep then steps the phase by
    recurrence (optics.airy._phasor) instead of an exponential per element. Each row must equal
    its own single-thickness call (an exponential) to rounding, also where the film absorbs
    (|z| < 1) or the wave is evanescent in it (total internal reflection from n = 1.5)."""
    wl = np.linspace(360.0, 830.0, 24)
    cos = np.linspace(0.0, 1.0, 33)
    rows = np.linspace(5.0, 1505.0, 61)  # 61 rows: 60 recurrence steps of 25 nm
    with np.errstate(invalid="ignore", divide="ignore"):
        swept = reflectance_sweep(indices, rows[:, None], wl, cos)
        for t in (0, 1, 30, 60):
            one = reflectance(indices, [rows[t]], wl, cos)
            assert np.max(np.abs(swept[t] - one)) <= 1e-12, t
    assert np.all(np.isfinite(swept)) and swept.min() >= 0.0 and swept.max() <= 1.0


def test_dispersion_models():
    """Dispersion models give the published indices (Malitson's fused silica at 587.6 nm), and a model or its
    sampled array give the same reflectance."""
    # Malitson (1965): fused silica n = 1.4585 at the helium d line, 587.6 nm.
    assert FUSED_SILICA.index([587.56])[0].real == pytest.approx(1.4585, abs=1e-4)
    cauchy = CauchyIndex(1.5, 0.004)
    assert cauchy.index([500.0])[0].real == pytest.approx(1.5 + 0.004 / 0.25)
    tab = TabulatedIndex((400.0, 600.0), (1.0, 2.0), (0.0, 1.0))
    assert tab.index([500.0])[0] == pytest.approx(1.5 + 0.5j)
    wl = np.linspace(400, 600, 5)
    as_array = reflectance([1.0, cauchy.index(wl), 1.0], [300.0], wl, [0.7])
    as_model = reflectance([1.0, cauchy, 1.0], [300.0], wl, [0.7])
    # The model is evaluated at the wavelengths inside reflectance: rounding only between the two.
    np.testing.assert_allclose(
        as_model, as_array, rtol=1e-14, atol=0, err_msg="a dispersion model against its values at the grid"
    )
    np.testing.assert_allclose(
        reflectance([1.0, ConstantIndex(1.4), 1.0], [200.0], wl, [1.0]),
        reflectance([1.0, 1.4, 1.0], [200.0], wl, [1.0]),
        rtol=1e-14,
        atol=0,
        err_msg="a constant-index model against the plain number",
    )
    with pytest.raises(ValueError, match="wavelengths_nm outside"):
        tab.index([700.0])
    with pytest.raises(ValueError, match="equally many"):
        SellmeierIndex((1.0,), ())


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"thicknesses_nm": [float("nan")]}, "thicknesses_nm"),
        ({"thicknesses_nm": [float("inf")]}, "thicknesses_nm"),
        ({"thicknesses_nm": [-1.0]}, "thicknesses_nm"),
        ({"thicknesses_nm": [1.0, 2.0]}, "thicknesses_nm"),
        ({"indices": [1.0, 1.5 - 0.1j, 1.0]}, r"indices\[1\].*extinction"),
        ({"indices": [1.0, 0.0, 1.0]}, r"indices\[1\].*n > 0"),
        ({"indices": [1.0, -1.3, 1.0]}, r"indices\[1\]"),
        ({"indices": [1.0, float("nan"), 1.0]}, r"indices\[1\]"),
        ({"indices": [1.0 + 0.1j, 1.3, 1.0]}, r"indices\[0\]"),
        ({"indices": [1.0]}, "indices"),
        ({"indices": []}, "indices"),
        ({"indices": [1.0, np.ones(3), 1.0]}, r"indices\[1\] has 3 values"),
        ({"cos_theta": [1.2]}, "cos_theta"),
        ({"cos_theta": [-1.5]}, "cos_theta"),
        ({"cos_theta": [-0.5]}, "cos_theta"),
        ({"cos_theta": [float("nan")]}, "cos_theta"),
        ({"wavelengths_nm": [float("inf")]}, "wavelengths_nm"),
        ({"wavelengths_nm": [0.0]}, "wavelengths_nm"),
        ({"wavelengths_nm": []}, "wavelengths_nm"),
        ({"polarization": "circular"}, "polarization"),
        ({"method": "magic"}, "method"),
    ],
)
def test_bad_input_raises_value_error_naming_the_parameter(kwargs, match):
    args = {
        "indices": [1.0, 1.33, 1.0],
        "thicknesses_nm": [300.0],
        "wavelengths_nm": [400.0, 500.0],
        "cos_theta": [1.0, 0.5],
    }
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        reflectance(**args)


def test_extreme_inputs_stay_finite():
    """Extreme thicknesses, grazing angles and strong absorbers give finite reflectances within [0, 1]: no
    NaN reaches a table."""
    wl = np.linspace(360, 830, 40)
    cos = np.array([0.0, 1e-9, 1e-4, 0.5, 1.0])
    for indices, d in [
        ([1.0, 1.33, 1.0], [1e6]),
        ([1.0, 2.5 + 3.0j, 1.5], [1e5]),
        ([1.7, 1.0, 1.0, 1.7], [5e4, 1e4]),
        ([1.0, 0.2 + 3.5j], []),
    ]:
        r = reflectance(indices, d, wl, cos)
        assert np.all(np.isfinite(r)) and np.all(r >= 0) and np.all(r <= 1 + 1e-12)
