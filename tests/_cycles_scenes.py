"""Sphere scenes for comparing our renders with Cycles: shared by the Cycles tests and benchmarks.

The same sphere rendered by Cycles (a Principled BSDF with Thin Film Thickness / IOR, Base Color
black, so only the film's specular layer shows), by the product's three numpy paths (split sum,
SH, combined) and by our brute force (``render.shade_reference``). The camera matches
``precompute.render.sphere_view`` exactly (pinhole on −y looking at +y, 32° field of view, sphere
of radius 1 at the origin).

Used by tests/test_cycles_parity.py, tests/test_glossy.py and ``benchmarks.cycles_compare``
(docs/cycles-comparison.md). It lives in tests/ because the tests never import benchmarks/.
"""

from __future__ import annotations

import math
import pathlib
import tempfile

import numpy as np

from precompute import bake, film_colour, hdri, lamps, prefilter, render
from precompute.material import Layer, Material
from precompute.shading import lamps as lamp_shading
from precompute.shading import policy, sh_sum, split_sum

SIZE = 64
FOV_DEG = 32.0
DISTANCE = 4.0


def cycles_render(hdri_path, thickness_nm, film_ior, base_ior, roughness, samples=256, size=SIZE):
    """Render the sphere with Cycles (CPU) and return the scene-linear RGB image (top row first)."""
    import bpy  # Blender as a module: only the Cycles side needs it (our renders are pure numpy)

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.use_adaptive_sampling = False
    scene.cycles.use_denoising = False
    scene.cycles.seed = 1
    scene.cycles.max_bounces = 1  # a single sphere: one bounce sees everything but self-reflection
    scene.render.resolution_x = scene.render.resolution_y = size
    scene.render.resolution_percentage = 100
    scene.render.film_transparent = False
    # A 1-pixel box (the pixel's area integral), matched by our supersampling and box average.
    # Cycles' default Blackman-Harris is narrower in effect and sharpens sub-pixel HDR lamps.
    scene.cycles.pixel_filter_type = "BOX"
    scene.cycles.filter_width = 1.0
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
    bsdf.inputs["Base Color"].default_value = (0.0, 0.0, 0.0, 1.0)
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
    with tempfile.TemporaryDirectory() as tmp:
        out = pathlib.Path(tmp) / "cycles.exr"
        scene.render.image_settings.file_format = "OPEN_EXR"
        scene.render.image_settings.color_depth = "32"
        scene.render.filepath = str(out)
        bpy.ops.render.render(write_still=True)
        return hdri.read_equirect(out)


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
