"""Sphere scenes for comparing our renders with Cycles: shared by the Cycles tests and benchmarks.

The same sphere rendered by Cycles (a Principled BSDF with Thin Film Thickness / IOR, Base Color
black, so only the film's specular layer shows), by the product's three numpy paths (split sum,
SH, combined) and by our brute force (``render.shade_reference``). The camera matches
``precompute.output.render.sphere_view`` exactly (pinhole on −y looking at +y, 32° field of view, sphere
of radius 1 at the origin).

Used by tests/parity/test_cycles_parity.py, tests/parity/test_glossy.py and ``benchmarks.cycles_compare``
(docs/cycles-comparison.md). It lives in tests/ because the tests never import benchmarks/.

:func:`white_furnace_render` is the white furnace of the colour pipeline (tests/parity/test_cycles_parity.py,
``benchmarks.white_furnace``): a mirror-smooth Principled film under a uniform white World, seen by
an orthographic camera, so each pixel is the film's F_rgb(θ), with each pixel's cos θ and film
thickness read back from a second render.
"""

from __future__ import annotations

import math
import pathlib
import tempfile

import numpy as np

from precompute.bakes import bake
from precompute.colour import film_colour
from precompute.materials.material import Layer, Material
from precompute.output import render
from precompute.shading import lamps as lamp_shading
from precompute.shading import policy, sh_sum, split_sum
from precompute.world import hdri, lamps, prefilter

SIZE = 64
FOV_DEG = 32.0
DISTANCE = 4.0


def cycles_settings(scene, samples: int, *, size=None, bounces: int = 1, pixel_filter=("BOX", 1.0)) -> None:
    """Cycles on the CPU, fixed seed, no adaptive sampling and no denoising, ``bounces`` bounces
    and the given pixel filter (type, width in px); a ``size`` × ``size`` frame when given."""
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.use_adaptive_sampling = False
    scene.cycles.use_denoising = False
    scene.cycles.seed = 1
    scene.cycles.max_bounces = bounces
    scene.cycles.pixel_filter_type, scene.cycles.filter_width = pixel_filter
    scene.render.film_transparent = False
    if size is not None:
        scene.render.resolution_x = scene.render.resolution_y = size
        scene.render.resolution_percentage = 100


def film_material(bpy, name, thickness_nm, film_ior, base_ior, roughness):
    """A new material whose Principled BSDF is a black dielectric of IOR ``base_ior`` under a thin
    film (``thickness_nm`` nm, ``film_ior``) at ``roughness``: the film alone."""
    mat = bpy.data.materials.new(name)
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    bsdf.inputs["Roughness"].default_value = roughness
    bsdf.inputs["IOR"].default_value = base_ior
    bsdf.inputs["Thin Film Thickness"].default_value = thickness_nm
    bsdf.inputs["Thin Film IOR"].default_value = film_ior
    return mat


def cycles_render(hdri_path, thickness_nm, film_ior, base_ior, roughness, samples=256, size=SIZE):
    """Render the sphere with Cycles (CPU) and return the scene-linear RGB image (top row first)."""
    import bpy  # Blender as a module: only the Cycles side needs it (our renders are pure numpy)

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    # One bounce: a single sphere sees everything but its self-reflection. A 1-pixel box (the
    # pixel's area integral), matched by our supersampling and box average; Cycles' default
    # Blackman-Harris is narrower in effect and sharpens sub-pixel HDR lamps.
    cycles_settings(scene, samples, size=size)
    world = bpy.data.worlds.new("env")
    nt = world.node_tree
    env = nt.nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(str(hdri_path))
    nt.links.new(env.outputs["Color"], nt.nodes["Background"].inputs["Color"])
    scene.world = world
    bpy.ops.mesh.primitive_uv_sphere_add(segments=256, ring_count=128, radius=1.0)
    sphere = bpy.context.active_object
    bpy.ops.object.shade_smooth()
    sphere.data.materials.append(film_material(bpy, "film", thickness_nm, film_ior, base_ior, roughness))
    cam_data = bpy.data.cameras.new("cam")
    cam_data.angle = math.radians(FOV_DEG)
    cam = bpy.data.objects.new("cam", cam_data)
    cam.location = (0.0, -DISTANCE, 0.0)
    cam.rotation_euler = (math.pi / 2, 0.0, 0.0)
    scene.collection.objects.link(cam)
    scene.camera = cam
    with tempfile.TemporaryDirectory() as tmp:
        out = pathlib.Path(tmp) / "cycles.exr"
        scene.render.image_settings.file_format = "OPEN_EXR"
        scene.render.image_settings.color_depth = "32"
        scene.render.filepath = str(out)
        bpy.ops.render.render(write_still=True)
        return hdri.read_equirect(out)


#: Version of :func:`build_sphere_blend`'s scene, part of the benchmarks' cache keys.
SPHERE_SCENE_VERSION = 1


def studiolight_path(name: str) -> pathlib.Path:
    """bpy's studio-light HDRI ``name`` (courtyard, forest, studio, sunset, …)."""
    from precompute.commands.cli import studiolight

    return pathlib.Path(studiolight(name))


def build_sphere_blend(
    path,
    hdri_path,
    thickness_nm,
    film_ior,
    base_ior,
    roughness,
    size=SIZE,
    samples=256,
    base_color=(0.0, 0.0, 0.0),
):
    """Save the Cycles comparison scene as a .blend: the sphere of :func:`cycles_render` with a
    Principled thin film (Base Color ``base_color``, black by default) under the HDRI, the same
    camera, Cycles settings for a reference (CPU, ``samples``, no denoising, fixed seed) and
    Cycles' default pixel filter (Blackman–Harris, 1.5 px). Returns the path."""
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    # one bounce: a single sphere sees everything but its self-reflection
    cycles_settings(scene, samples, size=size, pixel_filter=("BLACKMAN_HARRIS", 1.5))
    scene.view_settings.view_transform = "Standard"
    world = bpy.data.worlds.new("env")
    nt = world.node_tree
    env = nt.nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(str(hdri_path))
    nt.links.new(env.outputs["Color"], nt.nodes["Background"].inputs["Color"])
    scene.world = world
    bpy.ops.mesh.primitive_uv_sphere_add(segments=256, ring_count=128, radius=1.0)
    sphere = bpy.context.active_object
    bpy.ops.object.shade_smooth()
    mat = bpy.data.materials.new("film")
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*base_color, 1.0)
    bsdf.inputs["Roughness"].default_value = roughness
    bsdf.inputs["IOR"].default_value = base_ior
    bsdf.inputs["Thin Film Thickness"].default_value = thickness_nm
    bsdf.inputs["Thin Film IOR"].default_value = film_ior
    sphere.data.materials.append(mat)
    cam_data = bpy.data.cameras.new("cam")
    cam_data.angle = math.radians(FOV_DEG)
    cam = bpy.data.objects.new("cam", cam_data)
    cam.location = (0.0, -DISTANCE, 0.0)
    cam.rotation_euler = (math.pi / 2, 0.0, 0.0)
    scene.collection.objects.link(cam)
    scene.camera = cam
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    bpy.ops.wm.save_as_mainfile(filepath=str(path.resolve()), check_existing=False)
    return path


def cycles_render_blend(blend) -> np.ndarray:
    """Cycles' render of a .blend as it is (its own settings): scene-linear RGB, top row first."""
    import bpy

    bpy.ops.wm.open_mainfile(filepath=str(pathlib.Path(blend).resolve()))
    scene = bpy.context.scene
    with tempfile.TemporaryDirectory() as tmp:
        out = pathlib.Path(tmp) / "cycles.exr"
        scene.render.image_settings.file_format = "OPEN_EXR"
        scene.render.image_settings.color_depth = "32"
        scene.render.filepath = str(out)
        bpy.ops.render.render(write_still=True)
        return read_exr(out)


def read_exr(path) -> np.ndarray:
    """RGB (H, W, 3) float64 of an EXR written by Blender (R, G, B[, A]) or by us ("RGB")."""
    return hdri.read_equirect(path)


SUPERSAMPLE = 4
#: HDRI name → (lamp count, share of the light), filled by :func:`our_renders` for the report.
LAMPS_SEEN: dict = {}


def our_renders(hdri_path, thickness_nm, film_ior, base_ior, roughness, size=SIZE, colour_mode="per_channel"):
    """Our three paths on the same sphere: split sum, SH (the paper's), and the combined product path.

    Supersampled 4×4 per pixel and box-averaged, like Cycles' pixel filter (``filter_size`` 1).
    The material uses the Cycles-matching colour mode and Cycles' multiple-scattering model.
    """
    material = Material(
        layers=(Layer(film_ior, thickness_nm),),
        substrate=base_ior,
        roughness=roughness,
        colour_mode=colour_mode,
        multiscatter="cycles",
    )
    result = bake.bake(material)
    full = hdri.read_equirect(hdri_path)
    # As the add-on: the World's lamps lifted out and shaded per light direction (lamps.py)
    found, mask = lamps.extract(full)
    LAMPS_SEEN[pathlib.Path(hdri_path).stem] = (found.count, found.share)
    rest = lamps.remove(full, mask)
    film = film_colour.film_table(result)
    background_image, _ = render.prepare_environment(full, result.sh_order, roughness=roughness)
    _, coeffs = render.prepare_environment(rest, result.sh_order, roughness=roughness)
    pre = prefilter.prefilter(full, lamp_mask=mask)
    view = render.sphere_view(size, size, DISTANCE, FOV_DEG, supersample=SUPERSAMPLE)
    m = view.mask
    n, v = view.normals[m], view.views[m]
    background = hdri.equirect_lookup(background_image, view.rays)
    split, sh_only, combined = background.copy(), background.copy(), background.copy()
    lit = lamp_shading.shade(film, found, roughness, n, v)
    cos_o = np.clip(np.sum(n * v, axis=-1), 0.0, 1.0)
    split_lamps = split_sum.lamp_weight_at(pre, policy.effective_roughness(roughness, cos_o))[:, None] * lit
    split[m] = split_sum.shade_split_sum(result, pre, n, v) + split_lamps
    sh_only[m] = sh_sum.shade_sh(result, coeffs, n, v) + lit
    combined[m] = split_sum.shade_combined(result, coeffs, pre, n, v, lamps=found, film=film)
    out = {
        name: render.box_downsample(img, SUPERSAMPLE)
        for name, img in (("split_sum", split), ("sh", sh_only), ("combined", combined))
    }
    return out, render.sphere_view(size, size, DISTANCE, FOV_DEG), result


def object_mask(view, erode: int = 1) -> np.ndarray:
    """Sphere pixels minus a border of ``erode`` pixels (edge pixels mix sphere and background)."""
    m = view.mask.copy()
    for _ in range(erode):
        m[1:-1, 1:-1] &= m[:-2, 1:-1] & m[2:, 1:-1] & m[1:-1, :-2] & m[1:-1, 2:]
        m[0, :] = m[-1, :] = m[:, 0] = m[:, -1] = False
    return m


BRUTE_SUPERSAMPLE = 2


def brute_force_render(hdri_path, thickness_nm, film_ior, base_ior, roughness, size=SIZE, max_width=None):
    """Our physics without any of the real-time approximations: ``render.shade_reference``.

    Exact film reflectance per direction in the single-scattering GGX BRDF, integrated against
    the full-resolution HDRI with a 48 × 48 GGX-importance grid per sample (2×2 per pixel): the
    floor the product's paths can reach. Single scattering, so it reads dark at roughness ≥ 0.5,
    and the fixed grid aliases small HDR lamps at large roughness. ``max_width``: first halve the
    HDRI (solid-angle exact) until it is at most this wide (faster; tests).
    """
    material = Material(
        layers=(Layer(film_ior, thickness_nm),),
        substrate=base_ior,
        roughness=roughness,
        colour_mode="per_channel",
        multiscatter="none",
    )
    full = hdri.read_equirect(hdri_path)
    while max_width is not None and full.shape[1] > max_width:
        full = hdri.downsample(full, 2)
    view = render.sphere_view(size, size, DISTANCE, FOV_DEG, supersample=BRUTE_SUPERSAMPLE)
    out = hdri.equirect_lookup(full, view.rays)
    m = view.mask
    out[m] = render.shade_reference(material, full, view.normals[m], view.views[m], n_theta=48, n_phi=48)
    return render.box_downsample(out, BRUTE_SUPERSAMPLE)


# ----------------------------------------------------------------------------------------------
# White furnace
# ----------------------------------------------------------------------------------------------
#: Half-width of Cycles' box pixel filter in the white furnace (``filter_width`` 0.01 px, its
#: minimum): every sample sits at the pixel centre, so a pixel is F at one angle, not an average.
FURNACE_FILTER_WIDTH = 0.01


def _furnace_scene(size: int, samples: int):
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    cycles_settings(scene, samples, size=size, bounces=2, pixel_filter=("BOX", FURNACE_FILTER_WIDTH))
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    world = bpy.data.worlds.new("furnace")
    scene.world = world
    bpy.ops.mesh.primitive_uv_sphere_add(segments=256, ring_count=128, radius=1.0)
    sphere = bpy.context.active_object
    bpy.ops.object.shade_smooth()
    ortho_camera(scene, 2.05)
    return scene, world, sphere


def ortho_camera(scene, scale: float) -> None:
    """An orthographic camera at y = −5 looking along +y, ``scale`` wide: the scene's camera."""
    import bpy

    cam_data = bpy.data.cameras.new("cam")
    cam_data.type = "ORTHO"
    cam_data.ortho_scale = scale
    cam = bpy.data.objects.new("cam", cam_data)
    cam.location = (0.0, -5.0, 0.0)
    cam.rotation_euler = (math.pi / 2, 0.0, 0.0)
    scene.collection.objects.link(cam)
    scene.camera = cam


def _thickness_socket(nt, thickness_range):
    """A node output giving the film thickness (nm): ``lo`` + (x + 1)/2 · (hi − lo) of object x."""
    lo, hi = thickness_range
    coords = nt.nodes.new("ShaderNodeTexCoord")
    split = nt.nodes.new("ShaderNodeSeparateXYZ")
    nt.links.new(coords.outputs["Object"], split.inputs[0])
    remap = nt.nodes.new("ShaderNodeMapRange")
    remap.inputs["From Min"].default_value = -1.0
    remap.inputs["From Max"].default_value = 1.0
    remap.inputs["To Min"].default_value = float(lo)
    remap.inputs["To Max"].default_value = float(hi)
    nt.links.new(split.outputs["X"], remap.inputs["Value"])
    return remap.outputs["Result"]


def _render_exr(scene, path) -> np.ndarray:
    import bpy

    scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    return hdri.read_equirect(path)


def white_furnace_render(film_ior, base_ior, thickness_range, metal=None, size=96, samples=4):
    """Cycles' white furnace of a Principled film: (F_rgb, cos θ, thickness nm, mask), (size, size[, 3]).

    A sphere of Principled BSDF (Roughness 0, Base Color black, IOR ``base_ior``; or Metallic 1 with
    ``metal`` = (Base Color, Specular Tint)) under a uniform white World of strength 1, seen by an
    orthographic camera: a pixel is the film's reflectance of white light at its angle. The thickness
    varies linearly with object x over ``thickness_range`` (lo, hi) nm. A second render of the same
    sphere with an Emission shader returns each pixel's cos θ = N·I and thickness (the Geometry
    node's own normal and incoming vectors), against a black World (the mask).
    """
    import bpy

    scene, world, sphere = _furnace_scene(size, samples)
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 1.0
    mat = bpy.data.materials.new("film")
    nt = mat.node_tree
    bsdf = nt.nodes["Principled BSDF"]
    bsdf.inputs["Roughness"].default_value = 0.0
    bsdf.inputs["Thin Film IOR"].default_value = float(film_ior)
    nt.links.new(_thickness_socket(nt, thickness_range), bsdf.inputs["Thin Film Thickness"])
    if metal is None:
        bsdf.inputs["Base Color"].default_value = (0.0, 0.0, 0.0, 1.0)
        bsdf.inputs["IOR"].default_value = float(base_ior)
    else:
        f0, tint = metal
        bsdf.inputs["Metallic"].default_value = 1.0
        bsdf.inputs["Base Color"].default_value = (*f0, 1.0)
        bsdf.inputs["Specular Tint"].default_value = (*tint, 1.0)
    sphere.data.materials.append(mat)
    with tempfile.TemporaryDirectory() as tmp:
        film = _render_exr(scene, pathlib.Path(tmp) / "film.exr")
        # The same pixels' angle and thickness: emission (N·I, d / 1000, 1) against a black World.
        world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
        geometry = nt.nodes.new("ShaderNodeNewGeometry")
        dot = nt.nodes.new("ShaderNodeVectorMath")
        dot.operation = "DOT_PRODUCT"
        nt.links.new(geometry.outputs["Normal"], dot.inputs[0])
        nt.links.new(geometry.outputs["Incoming"], dot.inputs[1])
        scale = nt.nodes.new("ShaderNodeMath")
        scale.operation = "DIVIDE"
        nt.links.new(_thickness_socket(nt, thickness_range), scale.inputs[0])
        scale.inputs[1].default_value = 1000.0
        combine = nt.nodes.new("ShaderNodeCombineXYZ")
        nt.links.new(dot.outputs["Value"], combine.inputs["X"])
        nt.links.new(scale.outputs["Value"], combine.inputs["Y"])
        combine.inputs["Z"].default_value = 1.0
        emission = nt.nodes.new("ShaderNodeEmission")
        emission.inputs["Strength"].default_value = 1.0
        nt.links.new(combine.outputs["Vector"], emission.inputs["Color"])
        output = next(n for n in nt.nodes if n.bl_idname == "ShaderNodeOutputMaterial")
        nt.links.new(emission.outputs["Emission"], output.inputs["Surface"])
        data = _render_exr(scene, pathlib.Path(tmp) / "data.exr")
    mask = np.abs(data[..., 2] - 1.0) < 1e-4
    return film, np.clip(data[..., 0], 0.0, 1.0), data[..., 1] * 1000.0, mask
