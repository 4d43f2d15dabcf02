"""Render the user guide's EEVEE-native picture: F12 with EEVEE, films on and off.

A checker ground under the *courtyard* HDRI and a sun (shadows), with three film objects: a
Principled film sphere (500 nm, IOR 1.33 on glass, roughness 0.15), the *Soap Film* preset as a
bubble, and a coated solid glass ball (Principled Transmission 1, IOR 1.5, a 300 nm film). The
extension (registered from this repository) writes each film's EEVEE output; EEVEE, with its
ray tracing on (reflections and refraction of the other objects), renders the camera view
(``bpy.ops.render.render``, what F12 does), then again with the films' EEVEE paths
removed. Writes ``docs/images/eevee-native-showcase.png`` (left: films, right: off).

Run: ``.venv/bin/python scripts/make_eevee_native_images.py [--size W H] [--samples N]``.
"""

from __future__ import annotations

import argparse
import importlib
import math
import pathlib
import sys
import tempfile

import bpy  # first: importing bpy makes mathutils importable
import numpy as np

REPO = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "scripts"))
sys.path.insert(0, str(REPO / "sample_scenes"))

import make_scenes  # noqa: E402
import thinfilm_headless  # noqa: E402

OUT = REPO / "docs" / "images" / "eevee-native-showcase.png"


def _checker_ground(scene):
    bpy.ops.mesh.primitive_plane_add(size=30.0)
    ground = bpy.context.active_object
    mat = bpy.data.materials.new("Checker")
    tree = mat.node_tree
    checker = tree.nodes.new("ShaderNodeTexChecker")
    checker.inputs["Scale"].default_value = 40.0
    checker.inputs["Color1"].default_value = (0.7, 0.7, 0.68, 1.0)
    checker.inputs["Color2"].default_value = (0.25, 0.27, 0.3, 1.0)
    bsdf = tree.nodes["Principled BSDF"]
    bsdf.inputs["Roughness"].default_value = 0.6
    tree.links.new(checker.outputs["Color"], bsdf.inputs["Base Color"])
    ground.data.materials.append(mat)


def _sphere(location, radius, mat):
    bpy.ops.mesh.primitive_uv_sphere_add(segments=96, ring_count=48, radius=radius, location=location)
    bpy.ops.object.shade_smooth()
    bpy.context.active_object.data.materials.append(mat)


def _principled(name, thickness, film_ior, ior, roughness, transmission=0.0):
    mat = bpy.data.materials.new(name)
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (0.0, 0.0, 0.0, 1.0) if not transmission else (1, 1, 1, 1)
    bsdf.inputs["Roughness"].default_value = roughness
    bsdf.inputs["IOR"].default_value = ior
    bsdf.inputs["Transmission Weight"].default_value = transmission
    bsdf.inputs["Thin Film Thickness"].default_value = thickness
    bsdf.inputs["Thin Film IOR"].default_value = film_ior
    return mat


def build(size, samples):
    """The showcase scene in a fresh file; returns the scene."""
    scene = make_scenes.new_file(size)
    make_scenes.studio_world(scene, make_scenes.hdri_path("courtyard"), 1.0)
    scene.render.engine = "BLENDER_EEVEE"
    scene.eevee.taa_render_samples = samples
    scene.eevee.use_raytracing = True  # the films reflect (and the glass refracts) the other objects
    scene.view_settings.view_transform = "AgX"
    _checker_ground(scene)
    _sphere((-1.35, 0.3, 0.6), 0.6, _principled("Principled Film", 500.0, 1.33, 1.5, 0.15))
    bubble = make_scenes.film_material("Soap Film", "SOAP_FILM", thickness_source="NOISE", noise_scale=1.5)
    _sphere((0.0, -0.2, 0.75), 0.7, bubble)
    _sphere((1.35, 0.3, 0.55), 0.55, _principled("Coated Glass", 300.0, 1.33, 1.5, 0.0, transmission=1.0))
    sun = bpy.data.lights.new("Sun", "SUN")
    sun.energy, sun.angle = 3.0, math.radians(3.0)
    obj = bpy.data.objects.new("Sun", sun)
    obj.rotation_euler = (math.radians(40.0), 0.0, math.radians(30.0))
    scene.collection.objects.link(obj)
    make_scenes.camera(scene, (0.0, -5.6, 2.2), (0.0, 0.0, 0.45), lens=40.0)
    return scene


def _render(scene, path) -> np.ndarray:
    scene.render.image_settings.file_format = "PNG"
    scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    image = bpy.data.images.load(str(path))
    w, h = image.size
    pixels = np.array(image.pixels[:]).reshape(h, w, 4)[::-1, :, :3]
    bpy.data.images.remove(image)
    return pixels


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", nargs=2, type=int, default=(384, 216), metavar=("W", "H"))
    parser.add_argument("--samples", type=int, default=32)
    args = parser.parse_args(argv)
    thinfilm_headless.register_extension()
    sync = importlib.import_module("thinfilm_sh.addon.eevee.sync")
    wiring = importlib.import_module("thinfilm_sh.addon.eevee.wiring")
    scene = build(tuple(args.size), args.samples)
    print(sync.sync_all(scene))
    with tempfile.TemporaryDirectory() as tmp:
        films = _render(scene, pathlib.Path(tmp) / "films.png")
        sync.unregister()  # render_pre would write them back
        for mat in bpy.data.materials:
            wiring.remove(mat)
        off = _render(scene, pathlib.Path(tmp) / "off.png")
        sync.register()
    from PIL import Image  # optimised PNG: docs/images keeps each file small

    gap = np.ones((films.shape[0], 6, 3))
    rgb8 = np.clip(np.rint(np.concatenate([films, gap, off], axis=1) * 255.0), 0, 255).astype(np.uint8)
    OUT.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(np.ascontiguousarray(rgb8), "RGB").save(OUT, format="PNG", optimize=True)
    print(f"wrote {OUT}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
