"""A transparent film's shadow in EEVEE's own render, against Cycles.

A smooth thin wall lets the light through in Cycles (its singular transmission passes shadow
rays) and in EEVEE (the wall's *Transparent Shadows*, addon/eevee/wiring.py); a wall's shadow
pass lets through the wall's fitted curve (precompute.bakes.eevee_table.shadow_fit), whatever its
thickness (the thickness source drops out of that pass).

A *rough* thin wall of an index other than 1 (Roughness 0.0045 and up) stops Cycles' shadow
rays (precompute.shading.transmit.wall_stops_shadow_rays): the ground under it keeps 0.25–0.67 of
the open ground's light in the scenes measured (what reaches it by other paths; 0.55 under this
file's plate of IOR 1.52 at Roughness 0.05 and 0.3). EEVEE can let a wall's light through or
stop it, nothing between: such a wall's *Transparent Shadows* is switched off, so EEVEE stops
the sun there too (the light by other paths is not rendered). At IOR 1 Cycles lets shadow rays
through at any roughness (0.894 at 0.3).
"""

import math

import _cycles_scenes as cc
import numpy as np
import pytest
from _eevee_scene import eevee_camera, eevee_film, eevee_plate, eevee_render, eevee_scene

pytestmark = pytest.mark.blender


def _sunlit_ground(bpy, scene) -> None:
    """A dim World (0.02), a 20 m ground 1 m under the origin, a sun of 3 W/m² straight down."""
    scene.world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.02, 0.02, 0.02, 1.0)
    bpy.ops.mesh.primitive_plane_add(size=20.0, location=(0.0, 0.0, -1.0))
    bpy.context.active_object.data.materials.append(bpy.data.materials.new("ground"))
    sun = bpy.data.lights.new("sun", "SUN")
    sun.energy, sun.angle = 3.0, 0.0
    scene.collection.objects.link(bpy.data.objects.new("sun", sun))


def _wall(bpy, ior: float, thickness: float = 300.0, film_ior: float = 1.33, roughness: float = 0.0):
    """A Principled thin wall (Transmission 1, Base Color white) of IOR ``ior`` under a film."""
    mat = eevee_film(bpy, name="wall", thickness=thickness, film_ior=film_ior, ior=ior, roughness=roughness)
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    bsdf.inputs["Transmission Weight"].default_value = 1.0
    bsdf.inputs["Thin Wall"].default_value = True
    return mat


def _hidden_plate(bpy, scene, mat):
    """The plate wearing ``mat``, hidden from a 3 m orthographic camera that sees its shadow."""
    plate = eevee_plate(bpy, scene, mat)
    plate.visible_camera = False
    eevee_camera(bpy, scene, scale=3.0)
    return plate


def _shadow_ratios(bpy, ext, tmp_path, ior: float, roughness: float = 0.0, synced=None, after=None) -> dict:
    """The shadowed ground over the open ground (the plate hidden) under a sunlit thin-wall plate
    (:func:`_wall` of ``ior`` and ``roughness``) hidden from the camera, in EEVEE (the film synced;
    ``synced(mat)`` then, ``after(mat, scene)`` after its renders) and in Cycles (64 spp)."""
    ratios = {}
    for engine in ("EEVEE", "CYCLES"):
        scene = eevee_scene(bpy, size=16)
        scene.eevee.taa_render_samples = 16
        _sunlit_ground(bpy, scene)
        mat = _wall(bpy, ior, roughness=roughness)
        plate = _hidden_plate(bpy, scene, mat)
        if engine == "EEVEE":
            ext.sync.sync_material(mat, scene)
            if synced is not None:
                synced(mat)
        else:
            cc.cycles_settings(scene, 64, size=16, bounces=4)
        shadowed = eevee_render(bpy, scene, tmp_path / f"{engine}.exr")[..., 1].mean()
        plate.hide_render = True
        open_ground = eevee_render(bpy, scene, tmp_path / f"{engine}_open.exr")[..., 1].mean()
        ratios[engine] = float(shadowed / open_ground)
        if engine == "EEVEE" and after is not None:
            after(mat, scene)
    return ratios


@pytest.mark.parametrize("ior", [1.0, 1.52])
def test_a_smooth_thin_walls_shadow_lets_through_what_cycles_does(bpy, ext, tmp_path, ior):
    """A smooth thin-wall plate (a soap film on air, a coated pane) over a sunlit ground, hidden
    from the camera, which sees its shadow: the shadowed ground over the open ground (the plate
    hidden) in EEVEE's render within 0.12 of Cycles' (64 spp), and above 0.8 in both (a wall
    cast as opaque leaves the World's 0.02)."""

    def synced(mat):
        assert mat.surface_render_method == "BLENDED" and mat.use_transparent_shadow

    ratios = _shadow_ratios(bpy, ext, tmp_path, ior, synced=synced)
    print(f"IOR {ior}: shadowed / open ground {ratios}")
    assert min(ratios.values()) > 0.8, f"a smooth thin wall lets the sun through: {ratios}"
    assert abs(ratios["EEVEE"] - ratios["CYCLES"]) < 0.12, f"EEVEE's shadow must be Cycles': {ratios}"


def test_a_walls_shadow_is_its_fitted_curve_at_any_thickness(bpy, ext, tmp_path):
    """EEVEE evaluates a transparent wall's nodes in its shadow pass (*Transparent Shadows*): for
    shadow rays the group lets through the wall's fitted curve, a few math nodes, and not the
    image at the pixel's thickness, so the thickness source drops out of that pass (a noise
    source was half the soap bubble scene's frame time). A thin-wall film of index 2.5 whose
    thickness runs 0–60 nm across the plate (T ≈ 1 to ≈ 0.35) over a sunlit ground, the plate
    hidden from the camera: its shadow is even across; with the switch cut, the gradient shows."""
    scene = eevee_scene(bpy)
    scene.eevee.taa_render_samples = 16
    _sunlit_ground(bpy, scene)
    mat = _wall(bpy, 1.0, thickness=30.0, film_ior=2.5, roughness=0.05)
    nt = mat.node_tree
    bsdf = nt.nodes["Principled BSDF"]
    coords, split = nt.nodes.new("ShaderNodeTexCoord"), nt.nodes.new("ShaderNodeSeparateXYZ")
    remap = nt.nodes.new("ShaderNodeMapRange")
    for name, value in (("From Min", -2.0), ("From Max", 2.0), ("To Min", 0.0), ("To Max", 60.0)):
        remap.inputs[name].default_value = value
    nt.links.new(coords.outputs["Object"], split.inputs[0])
    nt.links.new(split.outputs["X"], remap.inputs["Value"])
    nt.links.new(remap.outputs["Result"], bsdf.inputs["Thin Film Thickness"])
    _hidden_plate(bpy, scene, mat)
    ext.sync.sync_material(mat, scene)
    group = ext.nodes.find(mat.node_tree)[0].node_tree

    def sides(name):
        """(right − left) / mean of the shadow's outer thirds, and the mean."""
        pixels = eevee_render(bpy, scene, tmp_path / f"{name}.exr")[..., 1]
        third = pixels.shape[1] // 3
        left, right = pixels[:, :third].mean(), pixels[:, -third:].mean()
        return float((right - left) / pixels.mean()), float(pixels.mean())

    even, lit = sides("switched")
    for name in ("shadow or view", "shadow row"):  # shadow rays read the image at their own row
        switch = group.nodes[name].inputs["Factor"]
        for link in list(switch.links):
            group.links.remove(link)
        switch.default_value = 0.0
    graded, _ = sides("cut")
    print(f"shadow's right − left / mean: {even:+.4f} switched, {graded:+.4f} cut; ground {lit:.3f}")
    assert 0.3 < lit < 3.5, "the ground must be lit through the wall (a film lets light through)"
    assert abs(graded) > 0.1 and abs(even) < 0.25 * abs(graded), (even, graded)


@pytest.mark.parametrize("tilt_deg", [0.0, 60.0, 70.0])
def test_a_walls_shadow_lets_through_its_curve_at_the_lights_angle(bpy, ext, tmp_path, tilt_deg):
    """The group's shadow curve (math nodes) against numpy's shadow_model with the constants the
    sync wrote: a smooth soap film on air (300 nm of 1.33) tilted ``tilt_deg`` under a sun
    straight down, hidden from the camera; the ground under the shadow's middle over the open
    ground within 0.03 of T at the sun's cosine (the dim World adds < 0.01)."""
    from precompute.bakes import eevee_table

    scene = eevee_scene(bpy, size=16)
    scene.eevee.taa_render_samples = 16
    _sunlit_ground(bpy, scene)
    mat = _wall(bpy, 1.0)
    plate = _hidden_plate(bpy, scene, mat)
    plate.rotation_euler = (math.radians(tilt_deg), 0.0, 0.0)
    ext.sync.sync_material(mat, scene)
    nodes = ext.nodes.find(mat.node_tree)[0].node_tree.nodes
    r0 = np.array(nodes[ext.nodes.SHADOW_R0].inputs["A"].default_value[:3])
    exponent = nodes[ext.nodes.SHADOW_EXPONENT].inputs[1].default_value
    assert 1.0 <= exponent <= 10.0 and np.all((r0 > 0.0) & (r0 < 0.2)), (r0, exponent)
    cos = math.cos(math.radians(tilt_deg))
    expected = eevee_table.shadow_model(r0, exponent, np.array([[cos]]))[0].mean()
    shadowed = eevee_render(bpy, scene, tmp_path / "shadowed.exr")[6:10, 6:10, 1].mean()
    plate.hide_render = True
    open_ground = eevee_render(bpy, scene, tmp_path / "open.exr")[6:10, 6:10, 1].mean()
    ratio = float(shadowed / open_ground)
    print(f"tilt {tilt_deg}°: shadowed / open {ratio:.4f}, the curve {expected:.4f}")
    assert abs(ratio - expected) < 0.03, (ratio, expected)


@pytest.mark.parametrize("ior", [1.0, 1.52])
def test_a_rough_walls_shadow_stops_the_sun_where_cycles_does(bpy, ext, tmp_path, ior):
    """A rough thin-wall plate (Roughness 0.05) over a sunlit ground, hidden from the camera: at
    IOR 1 both engines let the sun through (EEVEE's shadow within 0.12 of Cycles', both above
    0.8), at IOR 1.52 Cycles stops its shadow rays (under 0.7: the rest comes by other paths) and
    the sync switches the wall's *Transparent Shadows* off, so EEVEE stops the sun (under 0.1:
    the dim World's light); the wall made smooth, or the film removed, the material's own
    setting is back."""

    def synced(mat):
        assert mat.use_transparent_shadow == (ior == 1.0)  # Blender's default is on

    def after(mat, scene):
        bsdf = mat.node_tree.nodes["Principled BSDF"]
        for roughness, through in ((0.0, True), (0.05, ior == 1.0)):  # smoothed, then rough again
            bsdf.inputs["Roughness"].default_value = roughness
            ext.sync.sync_material(mat, scene)
            assert mat.use_transparent_shadow == through, roughness
        bsdf.inputs["Thin Film Thickness"].default_value = 0.0
        assert ext.sync.sync_material(mat, scene) == "removed"
        assert mat.use_transparent_shadow, "the film off restores the material's own setting"

    ratios = _shadow_ratios(bpy, ext, tmp_path, ior, 0.05, synced, after)
    print(f"IOR {ior}, Roughness 0.05: shadowed / open ground {ratios}")
    if ior == 1.0:
        assert min(ratios.values()) > 0.8 and abs(ratios["EEVEE"] - ratios["CYCLES"]) < 0.12, ratios
    else:
        assert ratios["CYCLES"] < 0.7 and ratios["EEVEE"] < 0.1, ratios
