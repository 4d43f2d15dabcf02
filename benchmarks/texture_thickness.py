"""A thickness that varies through a texture: the extension's headless frame against Cycles.

Scenes, each built by script in bpy and rendered twice — by Cycles (CPU, box filter) and by
the extension's headless ``render`` (:func:`addon.headless.render.render_scene`, the viewport's shader
on Mesa) — and compared by mean ΔE2000 over the sphere
(``precompute.colour.colour_difference.delta_e_2000``, route ``"E"``), in the Cycles-matching
(per-channel) colour mode a Principled BSDF is previewed in, at the default quality:

- ``noise``: an opaque film sphere (Base Color black, IOR 1.5, film IOR 1.33) whose Thin Film
  Thickness comes from Noise Texture → Map Range 150–850 nm, the socket's own value 0;
- ``gltf``: a sphere written as glTF with KHR_materials_iridescence (150–820 nm, IOR 1.45, an
  ``iridescenceThicknessTexture`` of stripes and rings in G) and imported by Blender's bundled
  importer (with the extension's import hook enabled);
- ``ramp``, ``distorted``: the noise through a Color Ramp, and with Distortion 1;
- ``subdivided``: the noise on a 32 × 16 sphere under a Subdivision Surface, ``twisted``: on
  the sphere twisted 90° about the camera's axis by a Simple Deform, ``subdivided_twisted``: both
  (Generated coordinates of a modified mesh, addon/thickness/generated.py).

The camera and the sphere are tests/_cycles_scenes.py's (pinhole on −y, 32°, radius 1).

Run: ``.venv/bin/python -m benchmarks.texture_thickness [--size 128] [--samples 256]``
→ ``docs/texture-thickness.md`` and ``docs/images/texture-thickness-*.png``.
"""

from __future__ import annotations

import argparse
import json
import math
import pathlib
import sys
import tempfile
import time

import numpy as np

from precompute.colour.colour_difference import delta_e_2000
from precompute.commands.cli import studiolight
from precompute.output import image_io, render
from precompute.world import hdri
from tests._cycles_scenes import DISTANCE, FOV_DEG, cycles_settings, object_mask
from tests._extension import EXTENSION_ID, linked_extension

from . import common

LIMIT = 2.5  # issue 21's acceptance: mean ΔE2000 over the object
#: Roughness of both spheres (``--roughness``). 0.15 is the split-sum regime; at 0.3 the product's
#: SH/split-sum blend is at its weakest even for a constant film (docs/cycles-comparison.md:
#: courtyard, 800 nm, roughness 0.3 → 2.61), which would measure the blend, not the texture.
ROUGHNESS = 0.15
HDRI = "courtyard"
#: The UV sphere's segments (``--segments``; rings: half of it). 256 resolves the textures at the
#: corners alone; Blender's default UV sphere has 32, where only a map per pixel does.
SEGMENTS = 256


def _world_and_camera(bpy, scene, hdri_path, size, samples):
    cycles_settings(scene, samples, size=size)
    world = bpy.data.worlds.new("env")
    env = world.node_tree.nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(str(hdri_path))
    world.node_tree.links.new(env.outputs["Color"], world.node_tree.nodes["Background"].inputs["Color"])
    scene.world = world
    cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
    cam.data.angle = math.radians(FOV_DEG)
    cam.location = (0.0, -DISTANCE, 0.0)
    cam.rotation_euler = (math.pi / 2, 0.0, 0.0)
    scene.collection.objects.link(cam)
    scene.camera = cam


def _sphere(bpy, segments=None):
    segments = segments or SEGMENTS
    bpy.ops.mesh.primitive_uv_sphere_add(segments=segments, ring_count=segments // 2, radius=1.0)
    sphere = bpy.context.active_object
    bpy.ops.object.shade_smooth()
    return sphere


def build_noise(bpy, folder, ramp: bool = False, distortion: float = 0.0, segments=None):
    """The opaque film sphere driven by Noise Texture → Map Range 150–850 nm (socket value 0);
    ``ramp``: through a Color Ramp of three coloured stops (Ease) between them; ``distortion``:
    the Noise Texture's; ``segments``: the UV sphere's (default :data:`SEGMENTS`). Returns the
    sphere."""
    sphere = _sphere(bpy, segments)
    mat = bpy.data.materials.new("noise film")
    tree = mat.node_tree
    bsdf = tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    bsdf.inputs["Roughness"].default_value = ROUGHNESS
    bsdf.inputs["IOR"].default_value = 1.5
    bsdf.inputs["Thin Film IOR"].default_value = 1.33
    bsdf.inputs["Thin Film Thickness"].default_value = 0.0
    noise = tree.nodes.new("ShaderNodeTexNoise")
    noise.inputs["Scale"].default_value = 3.0
    noise.inputs["Distortion"].default_value = distortion
    ranged = tree.nodes.new("ShaderNodeMapRange")
    ranged.inputs["To Min"].default_value = 150.0
    ranged.inputs["To Max"].default_value = 850.0
    tree.links.new(noise.outputs["Fac"], ranged.inputs["Value"])
    if ramp:  # the film's bands shaped by a ramp: thin and thick stripes, a colour's luminance
        node = tree.nodes.new("ShaderNodeValToRGB")
        stops = node.color_ramp.elements
        stops.new(0.5)
        node.color_ramp.interpolation = "EASE"
        for stop, position, colour in zip(
            stops, (0.35, 0.5, 0.62), ((0.05, 0.1, 0.02), (0.9, 0.6, 1.0), (0.2, 0.35, 0.1)), strict=True
        ):
            stop.position, stop.color = position, (*colour, 1.0)
        tree.links.new(noise.outputs["Fac"], node.inputs["Fac"])
        tree.links.new(node.outputs["Color"], ranged.inputs["Value"])
    tree.links.new(ranged.outputs["Result"], bsdf.inputs["Thin Film Thickness"])
    sphere.data.materials.append(mat)
    return sphere


def build_ramp(bpy, folder):
    """The noise sphere with a Color Ramp between the Noise Texture and the Map Range."""
    build_noise(bpy, folder, ramp=True)


def build_distorted(bpy, folder):
    """The noise sphere with the Noise Texture's Distortion at 1 (the swirls of oil on water)."""
    build_noise(bpy, folder, distortion=1.0)


def _stripes(size=256) -> np.ndarray:
    u, v = np.meshgrid((np.arange(size) + 0.5) / size, (np.arange(size) + 0.5) / size)
    return 0.5 + 0.5 * np.sin(2 * np.pi * (3 * u + 2 * v)) * np.cos(2 * np.pi * 2 * v)


def build_gltf(bpy, folder):
    """Write a glTF sphere with an iridescence thickness texture, then import it with Blender's
    importer (the extension's hook repairs the maximum it would lose)."""
    image = bpy.data.images.new("thickness", 256, 256)
    rgba = np.zeros((256, 256, 4), dtype=np.float32)
    rgba[..., 1], rgba[..., 3] = _stripes(), 1.0
    image.pixels.foreach_set(rgba.ravel())
    image.filepath_raw = str(folder / "thickness.png")
    image.file_format = "PNG"
    image.save()
    sphere = _sphere(bpy)
    mat = bpy.data.materials.new("gltf film")
    tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image = image
    mat.node_tree.links.new(tex.outputs["Color"], mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"])
    sphere.data.materials.append(mat)
    path = folder / "sphere.gltf"
    bpy.ops.export_scene.gltf(filepath=str(path), export_format="GLTF_SEPARATE", use_selection=True)
    data = json.loads(path.read_text())
    material = data["materials"][0]
    texture = material["pbrMetallicRoughness"].pop("baseColorTexture")
    material["pbrMetallicRoughness"].update(baseColorFactor=[0, 0, 0, 1], metallicFactor=0.0)
    material["pbrMetallicRoughness"]["roughnessFactor"] = ROUGHNESS
    material["extensions"] = {
        "KHR_materials_iridescence": {
            "iridescenceFactor": 1.0,
            "iridescenceIor": 1.45,
            "iridescenceThicknessMinimum": 150.0,
            "iridescenceThicknessMaximum": 820.0,
            "iridescenceThicknessTexture": texture,
        }
    }
    data.setdefault("extensionsUsed", []).append("KHR_materials_iridescence")
    path.write_text(json.dumps(data))
    bpy.data.objects.remove(sphere)
    bpy.data.materials.remove(mat)
    bpy.ops.import_scene.gltf(filepath=str(path))
    for obj in bpy.context.scene.objects:
        if obj.type == "MESH":
            obj.data.shade_smooth()


def build_subdivided(bpy, folder):
    """The noise on a 32 × 16 sphere under a Subdivision Surface (2 levels): the Noise Texture's
    Generated coordinates span the cage's texture space, not the smaller subdivided mesh's."""
    subdivide = build_noise(bpy, folder, segments=32).modifiers.new("subdivide", "SUBSURF")
    subdivide.levels = subdivide.render_levels = 2


def build_twisted(bpy, folder):
    """The noise sphere twisted 90° about the camera's axis (Simple Deform): still a sphere, but
    Blender's renders read its Generated coordinates where the vertices were before the twist."""
    twist = build_noise(bpy, folder).modifiers.new("twist", "SIMPLE_DEFORM")
    twist.deform_method, twist.deform_axis, twist.angle = "TWIST", "Y", math.radians(90.0)


def build_subdivided_twisted(bpy, folder):
    """The 32 × 16 sphere under a Subdivision Surface, then twisted as in :func:`build_twisted`
    (a rig under a subdivision: Generated is the object evaluated again without the twist)."""
    build_subdivided(bpy, folder)
    twist = bpy.context.active_object.modifiers.new("twist", "SIMPLE_DEFORM")
    twist.deform_method, twist.deform_axis, twist.angle = "TWIST", "Y", math.radians(90.0)


CASES = {
    "noise": build_noise,
    "ramp": build_ramp,
    "distorted": build_distorted,
    "gltf": build_gltf,
    "subdivided": build_subdivided,
    "twisted": build_twisted,
    "subdivided_twisted": build_subdivided_twisted,
}


def run_case(bpy, package, name, size, samples, folder):
    """(Cycles image, ours, mask, seconds, messages) of one case."""
    import addon_utils  # bpy's add-on utilities: the glTF add-on is enabled here

    bpy.ops.wm.read_factory_settings(use_empty=True)
    package.register()
    entry = bpy.context.preferences.addons.new()
    entry.module = EXTENSION_ID
    addon_utils.enable("io_scene_gltf2", default_set=True)
    scene = bpy.context.scene
    _world_and_camera(bpy, scene, studiolight(HDRI), size, samples)
    CASES[name](bpy, folder)
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    scene.render.filepath = str(folder / f"{name}-cycles.exr")
    t0 = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    t_cycles = time.perf_counter() - t0
    ref = hdri.read_equirect(scene.render.filepath)
    render_module = sys.modules[f"{EXTENSION_ID}.addon.headless.render"]
    t0 = time.perf_counter()
    result = render_module.render_scene(scene, folder / f"{name}-ours.png", size, size, background=True)
    t_ours = time.perf_counter() - t0
    ours = hdri.read_equirect(result["exr"])
    mask = object_mask(render.sphere_view(size, size, DISTANCE, FOV_DEG))
    return ref, ours, mask, (t_cycles, t_ours), result["messages"]


def write_pictures(name, ref, ours, de, mask) -> str:
    """Cycles | ours | ΔE2000 ×10 side by side, sRGB."""
    heat = np.zeros_like(ref)
    heat[..., 0] = np.where(mask, np.clip(de / 10.0, 0.0, 1.0), 0.0)
    heat[..., 1] = np.where(mask, np.clip(1.0 - de / 10.0, 0.0, 1.0) * 0.3, 0.0)
    row = np.concatenate([image_io.srgb_encode(ref), image_io.srgb_encode(ours), heat], axis=1)
    suffix = "" if SEGMENTS == 256 else f"-{SEGMENTS}"
    rel = f"images/texture-thickness-{name}{suffix}.png"
    image_io.write_png(pathlib.Path(common.ROOT) / "docs" / rel, row)
    return rel


def main(argv=None) -> int:
    """Run both cases and write docs/texture-thickness.md."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=128)
    parser.add_argument("--samples", type=int, default=256)
    parser.add_argument("--roughness", type=float, default=ROUGHNESS)
    parser.add_argument("--segments", type=int, default=SEGMENTS, help="UV sphere segments (rings: half)")
    parser.add_argument("--out", default="texture-thickness.md", help="the report, relative to docs/")
    parser.add_argument("--cases", nargs="+", choices=sorted(CASES), default=list(CASES))
    args = parser.parse_args(argv)
    globals()["ROUGHNESS"] = args.roughness  # read by the scene builders
    globals()["SEGMENTS"] = args.segments
    import bpy  # Blender as a module: both renders need it

    rows = []
    with tempfile.TemporaryDirectory() as tmp, linked_extension(pathlib.Path(tmp)) as package:
        for name in args.cases:
            folder = pathlib.Path(tmp) / name
            folder.mkdir()
            ref, ours, mask, times, messages = run_case(bpy, package, name, args.size, args.samples, folder)
            de = np.zeros(mask.shape)
            de[mask] = delta_e_2000(ours[mask], ref[mask], xyz="E")
            mean, p95 = float(np.mean(de[mask])), float(np.percentile(de[mask], 95))
            rows.append((name, mean, p95, times, write_pictures(name, ref, ours, de, mask), messages))
            print(
                f"{name}: mean ΔE2000 {mean:.2f}, p95 {p95:.2f}; "
                f"Cycles {times[0]:.1f} s, ours {times[1]:.1f} s"
            )
    lines = [
        "# Thickness from textures against Cycles",
        "",
        "Generated by `.venv/bin/python -m benchmarks.texture_thickness"
        f" --size {args.size} --samples {args.samples} --roughness {args.roughness:g}"
        f" --segments {args.segments}` (issue 21).",
        f"Code: {common.code_version()}.",
        "",
        "Spheres whose film thickness varies through a texture, each rendered by Cycles (CPU,",
        f"{args.samples} samples, box filter, one bounce) and by the extension's headless frame",
        "(`addon/headless/render.py`, `render_scene`: the viewport's shader on Mesa llvmpipe, default "
        "quality, the",
        "Cycles-matching per-channel colour mode of a Principled preview), "
        f"{args.size}×{args.size} pixels, under bpy's",
        f"`{HDRI}` studio light, roughness {args.roughness:g}. ΔE2000 (route E) over the sphere, its edge",
        f"pixel eroded; a UV sphere of {args.segments} × {args.segments // 2} segments. The extension",
        "evaluates the linked thickness per face corner and per pixel (`addon/thickness/linked.py`,",
        "`noise_graph.py`, `maps.py`): the Noise Texture (→ Map Range 150–850 nm; *ramp*: through a",
        "Color Ramp of three coloured stops first, its Color's luminance; *distorted*: Distortion 1)",
        "computed in the shader per",
        "pixel (`tf_perlin.glsl`, the ramp from Cycles' table of it) and in numpy at the corners, with",
        "no bake and no map; the glTF import graph (Image → Separate Color G → Mix) directly in numpy",
        "(at the corners, and at the image's pixels: the map).",
        "",
        "| Scene | mean ΔE2000 | 95th pct | limit | Cycles | ours (incl. bake) |",
        "|---|---|---|---|---|---|",
    ]
    for name, mean, p95, times, _, _ in rows:
        verdict = "✓" if mean <= LIMIT else "✗"
        lines.append(
            f"| {name} | {mean:.2f} {verdict} | {p95:.2f} | {LIMIT} | {times[0]:.1f} s | {times[1]:.1f} s |"
        )
    lines += [
        "",
        "Roughness 0.15 is where the product's constant-film figures are ≤ 1.4 (cycles-comparison.md).",
        "At roughness 0.3 (`--roughness 0.3`, same size and samples, commit 1642c89): noise 1.99",
        "(p95 5.25), glTF 1.57 (p95 4.62), both within the limit. Before issue 22's colour pipeline",
        "and anti-aliased frame a 64×64, 64-sample run at commit 641fe1b measured noise 2.72 and glTF",
        "1.97 there.",
        "",
        "Left to right: Cycles, the extension, ΔE2000 (red = 10).",
        "",
    ]
    for name, *_, pic, messages in rows:
        lines += [f"**{name}**", "", f"![{name}]({pic})", ""]
        lines += [f"- {m}" for m in messages if "thickness" in m]
    lines += [
        "",
        "## What Blender's glTF importer loses, and what the extension recovers",
        "",
        "Blender 5.2's bundled importer builds Image → Separate Color (G) → Mix(min, max) → *Thin Film",
        "Thickness* for `iridescenceThicknessTexture`, but reads the draft key `iridescenceThickness`",
        "instead of the spec's `iridescenceThicknessMaximum` (every such file gets 400 nm), and sets",
        "neither `iridescenceIor` nor `iridescenceFactor` when a thickness texture is present. With the",
        "extension enabled, its import hook (`addon/materials/gltf.py`, `glTF2ImportUserExtension`) "
        "writes the",
        "file's values into the nodes the importer left and keeps them in the material's custom",
        "property `KHR_materials_iridescence`; a file imported without the extension keeps the",
        "importer's losses (re-import it). The preview does not apply `iridescenceFactor` (Cycles",
        "does not either); the panel says so when it is not 1. Export writes the extension for every",
        "film material and warns for what glTF cannot carry (several layers, a metal's n + ik,",
        "dispersion, an ambient index); a thickness that varies without an image (a Noise Texture, the",
        "extension's own source) is baked by Cycles into `iridescenceThicknessTexture` at the first",
        "user's UVs (512², 8-bit), with the evaluated range as min and max.",
        "",
        *common.machine_lines(),
    ]
    path = common.write_doc(args.out, "\n".join(lines))
    print("wrote", path)
    return 0 if all(mean <= LIMIT for _, mean, *_ in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
