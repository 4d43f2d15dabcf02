"""The effect plan (precompute/effects/): each effect switches on only the code it needs.

Pure-numpy part: which code paths a bake runs (spies that raise or count), table shapes, the
shader cost, the scene plan (sharing, World order) and the bake-time estimate. Blender part
(``pytest.mark.blender``, real bpy, the repository imported as the extension ``thinfilm_sh``
through a symlink as in test_extension.py): what the viewport collects and bakes for a scene,
the ``thinfilm_sh plan`` command and the Plan panel's data.

Already covered elsewhere, not repeated here (tests/extension/test_addon_materials.py,
``test_equal_settings_share_one_bake_and_only_relevant_changes_rebake``): two materials with
equal settings share one table, changing the thickness re-bakes, an unrelated property (viewport
colour, object colour) does not.
"""

from __future__ import annotations

import dataclasses
import importlib
import json
import math

import numpy as np
import pytest
from _extension import EXTENSION_ID, gpu_layer, linked_extension

import precompute.optics as optics
from precompute.bakes import bake, planner
from precompute.commands import cli
from precompute.effects import cost_model, plan_text
from precompute.effects import plans as effects_plans
from precompute.materials.material import Layer, Material, Quality
from precompute.optics import dispersion, metals, stack
from precompute.shading import policy, sh_rotation
from precompute.shading.variant import Variant

#: Small explicit quality: a bake takes a fraction of a second.
FAST = Quality(sh_order=2, view_samples=6, thickness_samples=6, wavelength_count=32)


def fast(**kwargs) -> Material:
    kwargs.setdefault("quality", FAST)
    return Material(**kwargs)


@pytest.fixture
def no_dispersion_models(monkeypatch):
    """Every dispersive index model raises when evaluated."""

    def boom(self, wavelengths_nm):
        raise AssertionError(f"{type(self).__name__}.index was evaluated")

    for cls in (
        dispersion.CauchyIndex,
        dispersion.SellmeierIndex,
        dispersion.TabulatedIndex,
        metals.TabulatedMetal,
    ):
        monkeypatch.setattr(cls, "index", boom)


# ----------------------------------------------------------------------------------------------
# Code paths
# ----------------------------------------------------------------------------------------------
def test_plain_numbers_are_constant_indices_and_no_dispersion_model_runs(no_dispersion_models, monkeypatch):
    m = fast(layers=(Layer(1.33, 300.0),), substrate=[1.5, 0.0], thickness_range_nm=(100.0, 500.0))
    assert all(isinstance(model, dispersion.ConstantIndex) for model in m.indices())
    calls = []
    original = dispersion.ConstantIndex.index
    monkeypatch.setattr(
        dispersion.ConstantIndex, "index", lambda self, wl: calls.append(1) or original(self, wl)
    )
    mp = effects_plans.material_plan(m)
    assert mp.effects["dispersion"] is False and "no dispersion model" in mp.reasons["dispersion"]
    calls.clear()
    result = bake.bake(m)  # would raise if a Cauchy/Sellmeier/tabulated model were evaluated
    assert result.data.shape == mp.table_shape
    # Constant media are resolved once per reflectance sweep (a handful per bake: media × ladder
    # steps), never per wavelength, thickness row or u node.
    assert 0 < len(calls) <= 3 * (len(planner.U_DEGREE_LADDER) + 3)


def test_a_dispersive_film_does_evaluate_its_model(no_dispersion_models):
    m = fast(layers=(Layer({"cauchy": [1.45, 0.004]}, 300.0),), substrate=1.5)
    with pytest.raises(AssertionError, match="CauchyIndex.index was evaluated"):
        bake.bake(m)


def test_a_cauchy_law_without_b_and_c_is_planned_as_non_dispersive():
    m = fast(layers=(Layer({"cauchy": [1.45, 0.0, 0.0]}, 300.0),), substrate=1.5)
    assert effects_plans.material_plan(m).effects["dispersion"] is False
    m = fast(layers=(Layer({"cauchy": [1.45, 0.004]}, 300.0),), substrate={"metal": "gold"})
    mp = effects_plans.material_plan(m)
    assert mp.effects["dispersion"] and "layer 1 (Cauchy)" in mp.reasons["dispersion"]
    assert "substrate (tabulated metal)" in mp.reasons["dispersion"]


@pytest.fixture
def stack_spy(monkeypatch):
    """Counts calls of the general stack code (Rouard's recursion), or makes them raise."""
    state = {"calls": 0, "forbid": False}
    original = stack.stack_amplitude

    def spy(*args, **kwargs):
        if state["forbid"]:
            raise AssertionError("the general stack code ran")
        state["calls"] += 1
        return original(*args, **kwargs)

    monkeypatch.setattr(stack, "stack_amplitude", spy)
    return state


@pytest.mark.parametrize(
    "material",
    [
        fast(layers=(Layer(1.33, 400.0),), substrate=1.5),
        fast(layers=(Layer(1.38, 140.0),), substrate=1.52, thickness_range_nm=(100.0, 300.0)),
        fast(layers=(Layer([2.6, 0.3], 60.0),), substrate={"metal": "iron"}, base_color=(0.5, 0.5, 0.5)),
        fast(layers=(Layer(1.33, 400.0),), substrate=1.0, model="glassner2000"),
    ],
    ids=["constant", "varying", "metal+diffuse", "glassner2000"],
)
def test_a_single_film_never_runs_the_general_stack_code(material, stack_spy):
    mp = effects_plans.material_plan(material)
    assert mp.effects["interference"] and not mp.effects["stack"]
    assert "never the general stack code" in mp.reasons["stack"] or "glassner2000" in mp.reasons["stack"]
    stack_spy["forbid"] = True
    result = bake.bake(material)
    assert np.all(np.isfinite(result.data))


def test_a_two_layer_stack_runs_the_stack_code(stack_spy):
    m = fast(layers=(Layer(1.38, 100.0), Layer(2.1, 80.0)), substrate=1.52)
    mp = effects_plans.material_plan(m)
    assert mp.effects["stack"] and "transfer recursion" in mp.reasons["stack"]
    bake.bake(m)
    assert stack_spy["calls"] > 0


def test_the_stack_spy_sees_the_code_the_dispatcher_uses(stack_spy):
    """Guards the spy itself: the stack path of the optics dispatcher goes through it."""
    optics.reflectance([1.0, 1.38, 2.1, 1.52], [100.0, 80.0], [500.0], [1.0])
    assert stack_spy["calls"] == 2  # s and p


def test_no_film_means_no_interference_and_the_bare_interface_path(monkeypatch):
    bare = fast(layers=(), substrate=1.5)
    mp = effects_plans.material_plan(bare)
    assert not any(mp.effects[n] for n in ("interference", "stack", "thickness_axis"))
    assert "Fresnel only" in mp.reasons["interference"]

    def boom(*args, **kwargs):
        raise AssertionError("the u-node search ran for a bare interface")

    monkeypatch.setattr(planner, "choose_u_degree", boom)
    monkeypatch.setattr(optics, "airy_film_reflectance", boom)
    result = bake.bake(bare)
    assert result.data.shape == mp.table_shape and result.data.shape[0] == 1


def test_zero_thickness_film_is_planned_as_no_interference_and_bakes_the_bare_table():
    zero = fast(layers=(Layer(1.33, 0.0),), substrate=1.5)
    mp = effects_plans.material_plan(zero)
    assert not mp.effects["interference"] and not mp.effects["stack"]
    assert "0 nm" in mp.reasons["interference"] and "bare-interface path" in mp.reasons["interference"]
    a = bake.bake(zero).data
    b = bake.bake(fast(layers=(), substrate=1.5)).data
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-6 * np.abs(b).max())


def test_zero_thickness_film_takes_the_bare_interface_path(monkeypatch):
    def boom(*args, **kwargs):
        raise AssertionError("film code ran for a 0 nm film")

    monkeypatch.setattr(optics, "airy_film_reflectance", boom)
    monkeypatch.setattr(planner, "choose_u_degree", boom)
    bake.bake(fast(layers=(Layer(1.33, 0.0),), substrate=1.5))


# ----------------------------------------------------------------------------------------------
# Table dimensions and shader variants
# ----------------------------------------------------------------------------------------------
def test_constant_thickness_gives_a_1d_table_and_the_1d_shader():
    m = fast(layers=(Layer(1.33, 400.0),), substrate=1.5)
    mp = effects_plans.material_plan(m)
    assert mp.effects["thickness_axis"] is False and mp.plan.thickness_samples == 1
    assert mp.table_shape[0] == 1 and "1-D table" in mp.reasons["thickness_axis"]
    assert mp.shader.taps == 2 and "TF_VARY_THICKNESS" not in dict(mp.shader.defines)
    result = bake.bake(m)
    assert result.data.shape == mp.table_shape and result.thicknesses_nm.size == 1
    assert mp.table_bytes == result.data.size * 4


def test_a_thickness_range_gives_a_2d_table_and_the_vary_variant():
    m = fast(layers=(Layer(1.33, 400.0),), substrate=1.5, thickness_range_nm=(200.0, 600.0))
    mp = effects_plans.material_plan(m)
    assert mp.effects["thickness_axis"] and mp.table_shape[0] == FAST.thickness_samples > 1
    assert mp.shader.taps == 4 and dict(mp.shader.defines)["TF_VARY_THICKNESS"] == "1"
    assert bake.bake(m).data.shape == mp.table_shape


def test_per_channel_tables_and_texture_bytes():
    m = fast(layers=(Layer(1.33, 400.0),), substrate=1.5, colour_mode="per_channel")
    mp = effects_plans.material_plan(m)
    k = 6  # (2+1)(2+2)/2 coefficients at l_max 2
    assert mp.table_shape == (1, FAST.view_samples, k, 3)
    assert mp.texture_bytes == k * 1 * FAST.view_samples * 16  # one RGBA32F layer per coefficient
    assert mp.shader.channels == 3 and "TF_SPECTRAL" not in dict(mp.shader.defines)
    assert bake.bake(m).data.shape == mp.table_shape


def test_shader_cost_follows_the_documented_formula():
    # SH only, L = 8, K = 45. The generated band-by-band code multiplies only the structurally
    # non-zero X(±90°) entries (246 per sign for l = 1…8), 3 channels each; three z-rotations of
    # Σ l = 36 pairs at 12 each; the angle powers c_m = c_(m-1) c_1 from l = 2, 4 each.
    nonzero = sum(
        int(np.sum(np.abs(b) > policy.X90_ZERO))
        for s in (1, -1)
        for b in sh_rotation.x_rotation_bands(8, s)[1:]
    )
    rotation = 3 * nonzero + 12 * 3 * 36 + 4 * 3 * 7
    assert rotation == 3 * 492 + 1296 + 84
    c = cost_model.shader_cost(Variant(8, spectral=True, vary_thickness=False, display=False))
    assert (c.floats_fetched, c.multiply_adds, c.texel_fetches) == (810, rotation + 810 + 405, 270)
    c = cost_model.shader_cost(Variant(8, spectral=True, vary_thickness=True, display=False))
    assert c.floats_fetched == 1620 and c.multiply_adds == rotation + 1620 + 405
    c = cost_model.shader_cost(Variant(2, spectral=False, vary_thickness=False, display=False))
    assert c.floats_fetched == 2 * 6 * 3 and c.variant == (2, False, False)
    # l ≤ 2: bands 1 and 2 turned straight from the frame rows (tf_local_coefficients_direct):
    # band 1 two 3-term vec3 sums (18), band 2 the Q entries (21), Q z and Q x (54), three
    # quadratic forms (27) and the scaled outputs (12).
    assert c.multiply_adds == (18 + 21 + 54 + 27 + 12) + 36 + 18


def test_sh_order_follows_roughness_and_sets_the_variant():
    rough = Material(layers=(Layer(1.33, 400.0),), substrate=1.5, roughness=0.9)
    smooth = Material(layers=(Layer(1.33, 400.0),), substrate=1.5, roughness=0.3)
    mr, ms = effects_plans.material_plan(rough), effects_plans.material_plan(smooth)
    assert mr.plan.sh_order < ms.plan.sh_order == effects_plans.MAX_ORDER
    assert "roughness 0.9" in mr.reasons["sh_order"]
    assert dict(mr.shader.defines)["TF_L_MAX"] == str(mr.plan.sh_order)
    assert mr.shader.multiply_adds < ms.shader.multiply_adds
    assert mr.table_shape[2] == (mr.plan.sh_order + 1) * (mr.plan.sh_order + 2) // 2


def test_conductor_lines_diffuse_and_multiscatter_are_detected():
    gold = effects_plans.material_plan(fast(layers=(Layer(1.45, 250.0),), substrate={"metal": "gold"}))
    assert gold.effects["conductor"] and "absorbing substrate" in gold.reasons["conductor"]
    nk = effects_plans.material_plan(fast(layers=(Layer(1.45, 250.0),), substrate=[0.2, 3.0]))
    assert nk.effects["conductor"] and not nk.effects["dispersion"]
    glass = effects_plans.material_plan(fast(layers=(Layer(1.45, 250.0),), substrate=1.5))
    assert not glass.effects["conductor"] and not glass.effects["illuminant_lines"]

    fl = fast(layers=(Layer(1.45, 250.0),), substrate=1.5, illuminant="FL2")
    mp = effects_plans.material_plan(fl)
    assert mp.effects["illuminant_lines"] and mp.line_count > 0
    assert mp.wavelength_nodes == FAST.wavelength_count + mp.line_count
    assert bake.bake(fl).wavelengths_nm.size == mp.wavelength_nodes

    diffuse = effects_plans.material_plan(
        fast(layers=(Layer(1.45, 250.0),), substrate=1.5, base_color=(0.5, 0.2, 0.1))
    )
    assert diffuse.effects["diffuse_base"] and diffuse.table_shape == glass.table_shape

    assert glass.effects["multiscatter"]
    film = (Layer(1.45, 250.0),)
    assert not effects_plans.material_plan(fast(layers=film, multiscatter="none")).effects["multiscatter"]
    assert not effects_plans.material_plan(fast(layers=film, roughness=0.0)).effects["multiscatter"]


def test_every_choice_has_a_reason_and_the_text_shows_them():
    m = Material(
        layers=(Layer(1.33, 400.0),), substrate=1.5, roughness=0.5, thickness_range_nm=(100.0, 700.0)
    )
    mp = effects_plans.material_plan(m)
    assert list(mp.effects) == list(effects_plans.EFFECTS)
    for name in (
        *effects_plans.EFFECTS,
        "sh_order",
        "view_samples",
        "thickness_samples",
        "wavelength_count",
        "u_nodes",
        "bake_time",
        "shader",
        "colour_mode",
    ):
        assert mp.reasons.get(name), name
    text = plan_text.format_plan(mp, "Soap")
    for needle in (
        "material 'Soap'",
        "thickness_axis on",
        "stack off",
        "float32",
        f"SH order {effects_plans.MAX_ORDER}",
        "bake ≈",
        "multiply-adds",
        "why:",
        "TF_VARY_THICKNESS=1",
    ):
        assert needle in text, needle
    json.dumps(mp.to_dict())  # JSON-ready


# ----------------------------------------------------------------------------------------------
# Scene plan
# ----------------------------------------------------------------------------------------------
def test_an_empty_scene_plans_nothing():
    sp = effects_plans.scene_plan({}, world_coeffs=np.ones((81, 3)))
    assert sp.empty and sp.tables == {} and sp.table_bytes == 0 and sp.bake_seconds == 0.0
    assert "nothing is baked or drawn" in plan_text.format_plan(sp)


def test_equal_materials_share_one_table_and_kernels_are_charged_once():
    a = fast(layers=(Layer(1.33, 400.0),), substrate=1.5)
    b = fast(layers=(Layer(1.33, 420.0),), substrate=1.5)  # same roughness and quality: same kernel
    sp = effects_plans.scene_plan({"A": a, "A.001": a, "B": b})
    assert len(sp.tables) == 2 and sp.tables[effects_plans.material_plan(a).key] == ("A", "A.001")
    assert sp.bake_seconds_each["A.001"] == 0.0
    assert sp.table_bytes == sp.materials["A"].table_bytes + sp.materials["B"].table_bytes
    alone = effects_plans.material_plan(b).bake_seconds
    assert sp.bake_seconds_each["B"] < 0.5 * alone  # its kernel was computed for A
    assert "A.001" in plan_text.format_plan(sp) and "shares the table of 'A'" in plan_text.format_plan(sp)
    cached = effects_plans.scene_plan({"A": a, "B": b}, cached={sp.materials["A"].key})
    assert cached.bake_seconds_each["A"] == 0.0 and "already cached" in cached.reasons["cache"]
    assert len(sp.variants) == 1  # one compiled shader for all three


def _world_with_bands(energies) -> np.ndarray:
    """SH coefficients ((L+1)², 3) whose band l has energy ``energies[l]`` (spread over m, rgb)."""
    l_top = len(energies) - 1
    c = np.zeros(((l_top + 1) ** 2, 3))
    for l, e in enumerate(energies):
        c[l * l : (l + 1) ** 2] = math.sqrt(e / (3 * (2 * l + 1)))
    return c


def test_world_order_is_the_highest_material_order_and_the_content_order_is_reported():
    smooth_world = _world_with_bands([1.0, 0.05, 0.003] + [0.0] * 6)  # tail above l = 1: 0.3 %
    assert effects_plans.world_content_order(smooth_world)[0] == 1
    detailed_world = _world_with_bands([1.0] + [0.1] * 8)  # 10 % per band up to l = 8
    assert effects_plans.world_content_order(detailed_world)[0] == 8
    assert effects_plans.world_content_order(np.zeros((81, 3)))[0] == 0

    low = fast(layers=(Layer(1.33, 400.0),), substrate=1.5)  # sh_order 2
    sp = effects_plans.scene_plan({"low": low}, world_coeffs=smooth_world)
    assert (sp.world_content_order, sp.world_order) == (1, 2)  # the material needs 2
    sp = effects_plans.scene_plan({"low": low}, world_coeffs=detailed_world)
    # The draw windows the World to each material's l_max: a detailed World is drawn at 2 here.
    assert sp.world_order == 2 and "World SH order 2" in sp.reasons["world"]
    assert sp.world_content_order == 8
    high = Material(layers=(Layer(1.33, 400.0),), substrate=1.5, roughness=0.3)  # needs the cap
    assert (
        effects_plans.scene_plan({"high": high}, world_coeffs=smooth_world).world_order
        == effects_plans.MAX_ORDER
    )


# ----------------------------------------------------------------------------------------------
# Bake-time estimate
# ----------------------------------------------------------------------------------------------
def test_bake_time_estimate_follows_the_bakes_work():
    """The estimate's structure, without a clock (its accuracy in seconds is a benchmark:
    benchmarks/bake_estimate.py → docs/bake-estimate.md; timed here it failed under load).

    - the u degree the estimate predicts is within two ladder steps of the one the bake chooses
      (the docstring's claim; the degree sets the reflectance sweep and the kernel's width);
    - cold minus warm is exactly the kernel and multiscatter terms (the two caches a warm bake
      skips), so a second material of equal roughness is estimated cheaper;
    - every quality axis adds work: more wavelengths, view angles, thickness rows or SH bands
      never lower the estimate, and each raises the stage it feeds.
    """
    ladder = list(planner.U_DEGREE_LADDER)
    materials = {
        "1-D": fast(layers=(Layer(1.33, 400.0),), substrate=1.5, roughness=0.31),
        "2-D": fast(
            layers=(Layer(1.47, 300.0),), substrate=1.33, roughness=0.41, thickness_range_nm=(100.0, 800.0)
        ),
        "thick": fast(layers=(Layer(1.33, 2500.0),), substrate=1.5, roughness=0.2),
        "gold": fast(layers=(Layer(1.38, 350.0),), substrate={"metal": "gold"}, roughness=0.25),
        "stack": fast(
            layers=(Layer(1.56, 95.0), Layer([1.68, 0.05], 80.0)) * 3,
            substrate=1.56,
            roughness=0.51,
            multiscatter="none",
        ),
    }
    for name, material in materials.items():
        mp = effects_plans.material_plan(material)
        chosen = bake.bake(material).u_nodes
        steps = abs(ladder.index(mp.u_degree) - ladder.index(chosen))
        assert steps <= 2, (
            f"{name}: estimated u degree {mp.u_degree}, the bake chose {chosen} ({steps} steps)"
        )

        cold = mp.bake_time(kernel_cold=True, order_kernel_cold=False)
        warm = mp.bake_time(kernel_cold=False, order_kernel_cold=False)
        skipped = cold["kernel"] + cold["multiscatter"]
        assert skipped > 0 and warm["kernel"] == warm["multiscatter"] == 0.0, (name, cold, warm)
        assert math.isclose(cold["total"] - warm["total"], skipped, rel_tol=1e-12), (name, cold, warm)

    base = materials["2-D"]
    before = effects_plans.material_plan(base).bake_breakdown
    for field, stage in (
        ("wavelength_count", "reflectance"),
        ("view_samples", "kernel"),
        ("thickness_samples", "reflectance"),
        ("sh_order", "contract"),
    ):
        more = base.with_(
            quality=dataclasses.replace(base.quality, **{field: 2 * getattr(base.quality, field)})
        )
        after = effects_plans.material_plan(more).bake_breakdown
        assert after["total"] > before["total"], f"doubling {field} did not raise the estimate"
        assert after[stage] > before[stage], f"doubling {field} did not raise the {stage} stage"


@pytest.mark.parametrize("thickness", [100.0, 400.0, 1600.0])
def test_estimated_u_degree_is_within_two_ladder_steps_of_the_bakes_choice(thickness):
    m = fast(layers=(Layer(1.33, thickness),), substrate=1.0)
    mp = effects_plans.material_plan(m)
    chosen = bake.bake(m).u_nodes
    ladder = planner.U_DEGREE_LADDER
    assert abs(ladder.index(mp.u_degree) - ladder.index(chosen)) <= 2, (mp.u_degree, chosen)
    assert mp.u_tried == ladder[: ladder.index(mp.u_degree) + 1]


# ----------------------------------------------------------------------------------------------
# Command line (numpy)
# ----------------------------------------------------------------------------------------------
def test_precompute_cli_plan_prints_the_material_plan(capsys):
    assert cli.main(["plan", "--preset", "anodised_titanium"]) == 0
    out = capsys.readouterr().out
    for needle in (
        "interference on",
        "conductor on",
        "dispersion on",
        "thickness_axis on",
        "stack off",
        "table 17×",
        "why:",
        "dispersion: index depends on λ",
        "bake ≈",
    ):
        assert needle in out, needle
    assert cli.main(["plan", "--film-index", "1.4", "--thickness", "300", "--substrate", "1.5"]) == 0
    out = capsys.readouterr().out
    assert "thickness_axis off" in out and "table 1×" in out and "dispersion off" in out


# ----------------------------------------------------------------------------------------------
# Blender
# ----------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def tf(bpy, tmp_path_factory):
    """The repository imported as ``thinfilm_sh``; its modules as attributes."""
    import types

    root = tmp_path_factory.mktemp("extension")
    with linked_extension(root) as package:
        ns = types.SimpleNamespace(package=package, cache_dir=root / "cache")
        ns.addon = importlib.import_module(f"{EXTENSION_ID}.addon")
        for dotted in (
            "addon.headless.headless",
            "addon.materials.description",
            "addon.bakes.tables",
            "addon.ui.prefs",
            "addon.drawing.scene_draw",
            "addon.ui.ui",
        ):
            setattr(ns, dotted.rpartition(".")[2], importlib.import_module(f"{EXTENSION_ID}.{dotted}"))
        ns.gpu = gpu_layer()
        ns.plans = importlib.import_module(f"{EXTENSION_ID}.precompute.effects.plans")
        yield ns


@pytest.fixture
def scene(bpy, tf):
    """An empty factory file, the extension registered, its cache private, caches empty."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    tf.package.register()
    entry = bpy.context.preferences.addons.new()
    entry.module = EXTENSION_ID
    tf.prefs.preferences().cache_dir = str(tf.cache_dir)
    tf.tables.clear_memory_cache()
    tf.scene_draw.CACHES.clear()
    tf.gpu.context.ensure_gpu_context()
    try:
        yield bpy.context.scene
    finally:
        bpy.context.preferences.addons.remove(entry)
        tf.package.unregister()
        tf.tables.clear_memory_cache()
        tf.scene_draw.CACHES.clear()


def _object(bpy, scene, name, material, location=(0.0, 0.0, 0.0)):
    import bmesh

    bm = bmesh.new()
    bmesh.ops.create_uvsphere(bm, u_segments=16, v_segments=8, radius=1.0)
    mesh = bpy.data.meshes.new(name)
    bm.to_mesh(mesh)
    bm.free()
    obj = bpy.data.objects.new(name, mesh)
    obj.location = location
    scene.collection.objects.link(obj)
    mesh.materials.append(material)
    return obj


def _film(bpy, name, preset, thickness=None):
    mat = bpy.data.materials.new(name)
    s = mat.thinfilm_sh
    s.preset = preset
    s.enabled = True
    s.sh_order, s.view_samples, s.thickness_samples, s.wavelength_count = "2", 4, 4, 32
    if thickness is not None:
        s.layers[0].thickness_nm = thickness
    return mat


def _collect(bpy, tf):
    return tf.scene_draw.collect(bpy.context.evaluated_depsgraph_get(), allow_bake=True, allow_world=True)


pytest_blender = pytest.mark.blender


@pytest_blender
def test_a_scene_without_an_enabled_film_bakes_and_draws_nothing(bpy, tf, scene, capsys):
    plain = bpy.data.materials.new("Plain")  # a Principled BSDF with Thin Film Thickness 0
    _object(bpy, scene, "Plain", plain)
    disabled = _film(bpy, "Disabled", "SOAP_FILM")
    disabled.thinfilm_sh.enabled = False
    _object(bpy, scene, "Disabled", disabled, (3.0, 0.0, 0.0))
    hidden = _film(bpy, "Hidden", "OIL_ON_WATER")
    _object(bpy, scene, "Hidden", hidden, (-3.0, 0.0, 0.0)).hide_viewport = True
    start = tf.tables.bake_count
    items, messages = _collect(bpy, tf)
    assert items == [], messages
    assert tf.tables.bake_count == start and tf.scene_draw.CACHES.stats["table_uploads"] == 0
    assert tf.headless.scene_materials(scene) == ({}, {})
    assert tf.headless.main(["plan"]) == 0
    assert "nothing is baked or drawn" in capsys.readouterr().out
    assert tf.tables.bake_count == start


@pytest_blender
def test_changing_one_films_thickness_rebakes_only_that_material(bpy, tf, scene):
    a = _film(bpy, "A", "SOAP_FILM")
    b = _film(bpy, "B", "OIL_ON_WATER")
    _object(bpy, scene, "A", a, (-1.5, 0.0, 0.0))
    _object(bpy, scene, "B", b, (1.5, 0.0, 0.0))
    start = tf.tables.bake_count
    items, _ = _collect(bpy, tf)
    assert len(items) == 2 and tf.tables.bake_count == start + 2
    key_a, key_b = (tf.description.description_key(tf.description.description(m)) for m in (a, b))
    table_b, result_b = (
        tf.scene_draw.CACHES.tables[key_b],
        tf.tables.peek_table(tf.description.description(b)),
    )

    a.thinfilm_sh.thickness_max_nm = 610.0  # the soap film varies: its range is what it uses
    items, _ = _collect(bpy, tf)
    assert len(items) == 2 and tf.tables.bake_count == start + 3  # exactly one bake: A's
    new_a = tf.description.description_key(tf.description.description(a))
    assert new_a != key_a and new_a in tf.scene_draw.CACHES.tables
    assert tf.scene_draw.CACHES.tables[key_b] is table_b  # B's texture untouched
    assert tf.tables.peek_table(tf.description.description(b)) is result_b
    assert all(item.table is table_b for item in items if item.name.startswith("B/"))

    _collect(bpy, tf)  # nothing changed: nothing baked or uploaded
    assert tf.tables.bake_count == start + 3


@pytest_blender
def test_thinfilm_sh_plan_prints_effects_and_reasons(bpy, tf, scene, capsys):
    a = _film(bpy, "Soap", "SOAP_FILM")
    b = _film(bpy, "Steel", "HEAT_TINTED_STEEL")
    b.thinfilm_sh.vary_thickness = False
    c = _film(bpy, "Soap copy", "SOAP_FILM")
    for i, mat in enumerate((a, b, c)):
        _object(bpy, scene, mat.name, mat, (3.0 * i, 0.0, 0.0))
    start = tf.tables.bake_count
    assert tf.headless.main(["plan"]) == 0
    out = capsys.readouterr().out
    assert tf.tables.bake_count == start  # planning bakes nothing
    for needle in (
        "material 'Soap'",
        "material 'Steel'",
        "material 'Soap copy'",
        "effects:",
        "why:",
        "thickness_axis: top layer varies",
        "thickness_axis: constant thickness",
        "conductor: absorbing substrate",
        "shares the table of 'Soap'",
        "world:",
        "bake ≈",
    ):
        assert needle in out, needle
    plans = [json.loads(line.partition(" ")[2]) for line in out.splitlines() if line.startswith("plan-json ")]
    assert {p["material"] for p in plans} == {"Soap", "Steel", "Soap copy"}
    steel = next(p for p in plans if p["material"] == "Steel")
    assert steel["effects"]["conductor"] and not steel["effects"]["thickness_axis"]
    assert steel["table_shape"][0] == 1 and steel["reasons"]["conductor"]


@pytest_blender
def test_plan_panel_is_registered_and_shows_the_active_materials_plan(bpy, tf, scene):
    assert hasattr(bpy.types, "THINFILM_PT_plan")
    mat = _film(bpy, "Soap", "SOAP_FILM")
    desc = tf.description.description(mat)
    start = tf.tables.bake_count
    mp = tf.ui.plan_for(desc, wait=True)
    assert mp.key == tf.description.description_key(desc) and tf.ui.plan_for(desc) is mp  # memoised
    lines = tf.ui.plan_lines(mp)
    text = "\n".join(lines)
    assert "Table 4×4×6×3×3" in text and "Bake ≈" in text and "multiply-adds" in text
    assert tf.tables.bake_count == start


@pytest_blender
def test_the_world_sh_reaches_every_band_of_a_high_order_table(bpy, tf, scene):
    """A film at the highest SH order gets the World's bands up to that order, not a truncation
    (the World was once projected to l = 8 only, so bands 9–12 of a table met zero light)."""
    import os

    path = os.path.join(bpy.utils.system_resource("DATAFILES"), "studiolights", "world", "courtyard.exr")
    world = bpy.data.worlds.new("World")
    scene.world = world
    env = world.node_tree.nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(path)
    world.node_tree.links.new(env.outputs["Color"], world.node_tree.nodes["Background"].inputs["Color"])
    top = tf.gpu.layout.MAX_L
    assert top == tf.plans.MAX_ORDER == 12
    film = _film(bpy, "Rough", "SOAP_FILM")
    film.thinfilm_sh.sh_order = str(top)
    film.thinfilm_sh.roughness = 0.7  # SH only: no split sum
    _object(bpy, scene, "Rough", film)
    items, messages = _collect(bpy, tf)
    assert len(items) == 1, messages
    (item,) = items
    assert item.table.l_max == top and item.lighting.l_max == top
    c = np.asarray(item.lighting.coefficients)
    assert c.shape == ((top + 1) ** 2, 3)
    high = np.abs(c[81:]).max()  # bands 9–12, windowed
    assert high > 1e-3 * np.abs(c[0]).max(), high


def test_a_constant_thickness_rough_film_is_costed_as_its_grid():
    """The viewport reads a constant-thickness film's SH half from the outgoing-radiance grid
    (policy.uses_grid): the plan's shader cost is the grid's four fetches, the same at every
    order, not the per-pixel l = 12 sum it replaced; a varying thickness keeps that sum."""
    film = Layer(1.33, 400.0)
    rough = effects_plans.material_plan(Material(layers=(film,), substrate=1.5, roughness=0.6))
    vary = effects_plans.material_plan(
        Material(layers=(film,), substrate=1.5, roughness=0.6, thickness_range_nm=(300.0, 500.0))
    )
    assert rough.plan.sh_order == vary.plan.sh_order >= policy.GRID_MIN_L
    assert dict(rough.shader.defines).get("TF_RADIANCE_GRID") == "1"
    assert "TF_RADIANCE_GRID" not in dict(vary.shader.defines)
    grid = rough.shader.stages["grid"]
    assert grid[1] == 4 and "sh" not in rough.shader.stages and "radiance grid" in rough.reasons["shader"]
    assert 10 * rough.shader.multiply_adds < vary.shader.multiply_adds  # the grid's whole point
    lower = effects_plans.material_plan(
        Material(layers=(film,), substrate=1.5, roughness=0.6, quality=Quality(sh_order=6))
    )
    assert lower.shader.stages["grid"] == grid  # not the order's
