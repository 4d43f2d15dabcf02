"""Generate the sample .blend files: one small scene per thin-film preset, plus Principled interop.

Run with the bpy module (the extension is registered from this repository for the run):

    .venv/bin/python sample_scenes/make_scenes.py                      # → sample_scenes/out/
    .venv/bin/python sample_scenes/make_scenes.py --out /tmp/scenes --only soap_bubble oil_slick

or inside Blender (with Thin Film SH installed and enabled, or not: it is registered from the
repository either way):

    blender -b -P sample_scenes/make_scenes.py -- --out /tmp/scenes

Every scene has a camera, a World lit by one of Blender's studio-light HDRIs (an Environment
Texture with an *absolute* path: the HDRIs ship inside Blender / the bpy package, so generated
files name them where this interpreter found them; ``--hdri-dir`` picks another folder holding
``<name>.exr``), a render size of 320×240 and, where it makes sense, a grey ground plane.

Scenes (file stem: what it shows):

- ``soap_bubble``: soap_film preset on a sphere under "studio", thickness from 3-D noise;
- ``oil_slick``: oil_on_water preset on a water plane, thickness from a mesh attribute
  ("thickness": rings and swirls of a slick, made here);
- ``coated_car_window``: the paper's coated_car_window preset on a curved glass panel;
- ``anodised_titanium``: anodised_titanium preset on a capsule, thickness from a mesh attribute
  that runs 0 → 1 along it (the gold → purple → blue → green colour chart of anodising);
- ``beetle_shell``: beetle_multilayer preset (16-layer chitin reflector) on a half-ellipsoid;
- ``principled_film``: NO extension settings, a plain Principled BSDF with Thin Film Thickness
  500 nm, Thin Film IOR 1.33, IOR 1.5, Roughness 0.5, Base Color black (Cycles interop: the
  extension previews it from the Principled sockets).

The output folder is not part of the repository (``sample_scenes/out/`` is ignored by git and
excluded from the built extension).
"""

from __future__ import annotations

import argparse
import importlib
import itertools
import math
import os
import pathlib
import sys
import tempfile

import bpy  # first: importing bpy makes bmesh and mathutils importable

# isort: split
import bmesh
from mathutils import Vector

REPO = pathlib.Path(__file__).resolve().parent.parent
EXTENSION_ID = "thinfilm_sh"
DEFAULT_OUT = REPO / "sample_scenes" / "out"
RESOLUTION = (320, 240)

#: Scene name → (HDRI, World strength). Names are the studio lights Blender ships.
HDRI = {
    "soap_bubble": ("studio", 1.0),
    "oil_slick": ("sunset", 1.0),
    "coated_car_window": ("city", 1.0),
    "anodised_titanium": ("interior", 1.0),
    "beetle_shell": ("forest", 1.0),
    "principled_film": ("courtyard", 1.0),
}
SCENE_NAMES = tuple(HDRI)


# ----------------------------------------------------------------------------------------------
# Extension and HDRIs
# ----------------------------------------------------------------------------------------------
def ensure_extension() -> None:
    """Make ``material.thinfilm_sh`` available: use an enabled install, else register this repo.

    The repository root is the extension package; it is imported as ``thinfilm_sh`` through a
    symlink in a temporary folder (what Blender does with an installed extension).
    """
    if hasattr(bpy.types.Material, "thinfilm_sh"):
        return
    module = sys.modules.get(EXTENSION_ID)
    if module is None:
        root = tempfile.mkdtemp(prefix="thinfilm_sh_ext_")
        os.symlink(REPO, os.path.join(root, EXTENSION_ID), target_is_directory=True)
        sys.path.insert(0, root)
        module = importlib.import_module(EXTENSION_ID)
    module.register()


def studiolight_dir() -> pathlib.Path:
    """Blender's studio-light World HDRIs (inside the bpy package / the Blender install)."""
    path = bpy.utils.system_resource("DATAFILES", path="studiolights/world")
    if not path or not os.path.isdir(path):
        raise FileNotFoundError(
            "Blender's studio lights (datafiles/studiolights/world) were not found; pass --hdri-dir"
        )
    return pathlib.Path(path)


def hdri_path(name: str, hdri_dir=None) -> pathlib.Path:
    folder = pathlib.Path(hdri_dir) if hdri_dir else studiolight_dir()
    path = (folder / f"{name}.exr").resolve()
    if not path.is_file():
        found = sorted(p.stem for p in folder.glob("*.exr"))
        raise FileNotFoundError(
            f"HDRI {name!r}: {path} does not exist (that folder has {found or 'no .exr'})"
        )
    return path


# ----------------------------------------------------------------------------------------------
# Building blocks
# ----------------------------------------------------------------------------------------------
def new_file(resolution=RESOLUTION):
    """An empty file (factory startup, user preferences kept) set up for small renders."""
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = resolution
    scene.render.resolution_percentage = 100
    scene.render.film_transparent = False
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    # Ready for a Cycles render of the Principled side (the preview does not depend on it).
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 128
    scene.cycles.use_denoising = False
    return scene


def studio_world(scene, hdri: pathlib.Path, strength: float = 1.0, name: str = "Studio"):
    world = bpy.data.worlds.new(name)
    tree = world.node_tree
    background = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeBackground")
    env = tree.nodes.new("ShaderNodeTexEnvironment")
    env.location = (background.location.x - 300.0, background.location.y)
    env.image = bpy.data.images.load(str(hdri), check_existing=True)
    tree.links.new(env.outputs["Color"], background.inputs["Color"])
    background.inputs["Strength"].default_value = strength
    world.color = (0.05, 0.05, 0.05)
    scene.world = world
    return world


def add_object(scene, name: str, mesh):
    obj = bpy.data.objects.new(name, mesh)
    scene.collection.objects.link(obj)
    return obj


def bm_to_mesh(bm, name: str, smooth: bool = True):
    mesh = bpy.data.meshes.new(name)
    bm.to_mesh(mesh)
    bm.free()
    if smooth:
        mesh.shade_smooth()
    else:
        mesh.shade_flat()
    return mesh


def uv_sphere(name: str, radius: float = 1.0, segments: int = 96, rings: int = 48):
    """A UV sphere (poles on z, ``rings`` bands, ``segments`` around from +x), built vertex by
    vertex and face by face, each face's corners in one order, its normal outward. Blender 5.2's
    ``bmesh.ops.create_uvsphere`` gives the same vertices but starts a face's corners
    differently from one call to the next at this size: the quads were split along other
    diagonals, so two runs of this script rendered different glints."""
    bm = bmesh.new()
    top = bm.verts.new((0.0, 0.0, radius))
    bands = []
    for i in range(1, rings):
        theta = math.pi * i / rings
        z, r = radius * math.cos(theta), radius * math.sin(theta)
        bands.append(
            [
                bm.verts.new((r * math.cos(phi), r * math.sin(phi), z))
                for phi in (2.0 * math.pi * j / segments for j in range(segments))
            ]
        )
    bottom = bm.verts.new((0.0, 0.0, -radius))
    for j in range(segments):
        k = (j + 1) % segments
        bm.faces.new((top, bands[0][j], bands[0][k]))
        for upper, lower in itertools.pairwise(bands):
            bm.faces.new((upper[j], lower[j], lower[k], upper[k]))
        bm.faces.new((bottom, bands[-1][k], bands[-1][j]))
    bm.normal_update()
    return bm


def grid(size_x: float, size_y: float, nx: int, ny: int):
    bm = bmesh.new()
    bmesh.ops.create_grid(bm, x_segments=nx, y_segments=ny, size=0.5)
    for v in bm.verts:
        v.co.x *= size_x
        v.co.y *= size_y
    return bm


def camera(scene, location, target, lens: float = 50.0, name: str = "Camera"):
    data = bpy.data.cameras.new(name)
    data.lens = lens
    data.clip_start, data.clip_end = 0.05, 200.0
    obj = add_object(scene, name, data)
    obj.location = location
    direction = Vector(target) - Vector(location)
    obj.rotation_euler = direction.to_track_quat("-Z", "Y").to_euler()
    scene.camera = obj
    return obj


def ground(scene, z: float = 0.0, size: float = 30.0, grey: float = 0.35, name: str = "Ground"):
    mesh = bm_to_mesh(grid(size, size, 1, 1), name, smooth=False)
    obj = add_object(scene, name, mesh)
    obj.location.z = z
    mat = bpy.data.materials.new(name)
    bsdf = mat.node_tree.nodes.get("Principled BSDF")
    bsdf.inputs["Base Color"].default_value = (grey, grey, grey, 1.0)
    bsdf.inputs["Roughness"].default_value = 0.6
    mat.diffuse_color = (grey, grey, grey, 1.0)  # what Solid shading (the preview's backdrop) shows
    mesh.materials.append(mat)
    return obj


def film_material(name: str, preset: str, **settings):
    """A material previewed by the extension with ``preset`` (an enum id, e.g. "SOAP_FILM")."""
    mat = bpy.data.materials.new(name)
    tf = mat.thinfilm_sh
    tf.preset = preset  # fills layers, substrate, roughness, thickness range
    tf.enabled = True
    for key, value in settings.items():  # non-physical settings (source, noise) keep the preset
        setattr(tf, key, value)
    return mat


def add_point_attribute(mesh, name: str, values) -> None:
    attribute = mesh.attributes.new(name, "FLOAT", "POINT")
    attribute.data.foreach_set("value", [float(v) for v in values])


def _smoothstep(x: float) -> float:
    x = min(1.0, max(0.0, x))
    return x * x * (3.0 - 2.0 * x)


# ----------------------------------------------------------------------------------------------
# The scenes
# ----------------------------------------------------------------------------------------------
def soap_bubble(scene):
    mesh = bm_to_mesh(uv_sphere("Bubble"), "Bubble")
    obj = add_object(scene, "Bubble", mesh)
    obj.location = (0.0, 0.0, 1.2)
    mesh.materials.append(
        film_material("Soap Film", "SOAP_FILM", thickness_source="NOISE", noise_scale=1.2, noise_seed=3)
    )
    camera(scene, (0.0, -5.2, 1.5), (0.0, 0.0, 1.2), lens=50.0)


def oil_slick(scene):
    bm = grid(24.0, 24.0, 192, 192)
    values = []
    for v in bm.verts:
        x, y = v.co.x, v.co.y
        r = math.hypot(x - 0.3, y + 0.4)
        swirl = math.atan2(y + 0.4, x - 0.3)
        # A thick centre thinning outwards, with rings and a swirl: a spreading slick.
        fade = math.exp(-r * r / 30.0)
        value = 0.55 * math.exp(-r * r / 6.0) + 0.25 * fade * math.sin(3.2 * r + 1.5 * math.sin(2.0 * swirl))
        values.append(min(1.0, max(0.0, value + 0.3)))
    mesh = bm_to_mesh(bm, "Water")
    add_point_attribute(mesh, "thickness", values)
    add_object(scene, "Water", mesh)
    mesh.materials.append(
        film_material(
            "Oil on Water", "OIL_ON_WATER", thickness_source="ATTRIBUTE", thickness_attribute="thickness"
        )
    )
    # Dark water below the surface: what Cycles sees through the transmissive water (the preview
    # draws the film's reflection over it).
    ground(scene, z=-0.6, size=30.0, grey=0.02, name="Sea Bed")
    camera(scene, (0.0, -6.0, 3.2), (0.0, 0.5, 0.0), lens=35.0)


def coated_car_window(scene):
    bm = grid(2.4, 1.2, 64, 32)
    for v in bm.verts:
        x, y = v.co.x, v.co.y
        v.co.z = 0.22 * (1.0 - (x / 1.2) ** 2) + 0.08 * (1.0 - (y / 0.6) ** 2)  # curved in both directions
    mesh = bm_to_mesh(bm, "Windshield")
    obj = add_object(scene, "Windshield", mesh)
    obj.rotation_euler = (math.radians(62.0), 0.0, 0.0)  # raked like a windshield, facing the camera
    obj.location = (0.0, 0.0, 0.75)
    mesh.materials.append(
        film_material(
            "Coated Glass",
            "COATED_CAR_WINDOW",
            thickness_source="NOISE",
            noise_scale=0.6,
            noise_seed=1,
            transparency="SHEET",  # a window: the ground seen through it
        )
    )
    ground(scene, z=0.0)
    camera(scene, (1.6, -3.6, 1.6), (0.0, 0.0, 0.75), lens=40.0)


def anodised_titanium(scene):
    radius, half = 0.45, 1.1
    bm = uv_sphere("Bar", radius=radius, segments=96, rings=48)
    for v in bm.verts:  # a capsule: hemispherical caps pushed apart along x
        v.co.x += math.copysign(half, v.co.x) if abs(v.co.x) > 1e-6 else 0.0
    xs = [v.co.x for v in bm.verts]
    lo, hi = min(xs), max(xs)
    values = [_smoothstep((x - lo) / (hi - lo)) * 0.9 + 0.05 for x in xs]
    mesh = bm_to_mesh(bm, "Titanium Bar")
    add_point_attribute(mesh, "oxide", values)
    obj = add_object(scene, "Titanium Bar", mesh)
    obj.location = (0.0, 0.0, radius)
    obj.rotation_euler.z = math.radians(-12.0)
    mesh.materials.append(
        film_material(
            "Anodised Titanium",
            "ANODISED_TITANIUM",
            thickness_source="ATTRIBUTE",
            thickness_attribute="oxide",
        )
    )
    ground(scene, z=0.0)
    camera(scene, (0.6, -4.4, 2.3), (0.0, 0.0, 0.35), lens=50.0)


def beetle_shell(scene):
    bm = uv_sphere("Shell", radius=1.0, segments=96, rings=48)
    bmesh.ops.delete(bm, geom=[v for v in bm.verts if v.co.z < -1e-6], context="VERTS")
    for v in bm.verts:
        v.co.x *= 1.25
        v.co.y *= 0.8
        v.co.z *= 0.6
    mesh = bm_to_mesh(bm, "Beetle Shell")
    obj = add_object(scene, "Beetle Shell", mesh)
    obj.rotation_euler.z = math.radians(25.0)
    mesh.materials.append(film_material("Beetle Multilayer", "BEETLE_MULTILAYER"))
    ground(scene, z=0.0)
    camera(scene, (2.2, -3.4, 2.6), (0.0, 0.0, 0.2), lens=45.0)


def principled_film(scene):
    mesh = bm_to_mesh(uv_sphere("Sphere"), "Sphere")
    add_object(scene, "Sphere", mesh)
    mat = bpy.data.materials.new("Principled Thin Film")
    bsdf = mat.node_tree.nodes.get("Principled BSDF")
    bsdf.inputs["Base Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    bsdf.inputs["Roughness"].default_value = 0.5
    bsdf.inputs["IOR"].default_value = 1.5
    bsdf.inputs["Thin Film Thickness"].default_value = 500.0
    bsdf.inputs["Thin Film IOR"].default_value = 1.33
    mat.diffuse_color = (0.0, 0.0, 0.0, 1.0)
    mesh.materials.append(mat)
    camera(scene, (0.0, -4.5, 0.0), (0.0, 0.0, 0.0), lens=50.0)


BUILDERS = {
    "soap_bubble": soap_bubble,
    "oil_slick": oil_slick,
    "coated_car_window": coated_car_window,
    "anodised_titanium": anodised_titanium,
    "beetle_shell": beetle_shell,
    "principled_film": principled_film,
}


def make_scene(name: str, out_dir, hdri_dir=None, resolution=RESOLUTION) -> pathlib.Path:
    """Build scene ``name`` in a fresh file and save it as ``out_dir/<name>.blend``."""
    if name not in BUILDERS:
        raise ValueError(f"unknown scene {name!r}; choose from {', '.join(SCENE_NAMES)}")
    ensure_extension()
    hdri, strength = HDRI[name]
    path = hdri_path(hdri, hdri_dir)  # fail before building anything
    scene = new_file(resolution)
    scene.name = name
    studio_world(scene, path, strength, name=f"Studio {hdri}")
    BUILDERS[name](scene)
    out = pathlib.Path(out_dir).resolve() / f"{name}.blend"
    out.parent.mkdir(parents=True, exist_ok=True)
    bpy.ops.wm.save_as_mainfile(filepath=str(out), check_existing=False, compress=True, relative_remap=False)
    return out


def make_scenes(
    out_dir=DEFAULT_OUT, hdri_dir=None, names=None, resolution=RESOLUTION
) -> dict[str, pathlib.Path]:
    """Build every scene (or ``names``); returns {name: path of the .blend}.

    Each scene starts from an empty factory file (``read_homefile``): whatever was open is
    replaced. User preferences are kept.
    """
    names = list(names or SCENE_NAMES)
    return {name: make_scene(name, out_dir, hdri_dir, resolution) for name in names}


def _argv(argv):
    if argv is not None:
        return list(argv)
    # Inside Blender the script's own arguments follow "--".
    return sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else sys.argv[1:]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(DEFAULT_OUT), help="output folder (default: sample_scenes/out)")
    parser.add_argument(
        "--hdri-dir",
        help="folder with the studio-light HDRIs <name>.exr "
        "(default: Blender's datafiles/studiolights/world)",
    )
    parser.add_argument(
        "--only",
        nargs="+",
        choices=SCENE_NAMES,
        metavar="SCENE",
        help=f"build only these ({', '.join(SCENE_NAMES)})",
    )
    parser.add_argument("--resolution", nargs=2, type=int, default=RESOLUTION, metavar=("W", "H"))
    args = parser.parse_args(_argv(argv))
    try:
        made = make_scenes(args.out, args.hdri_dir, args.only, tuple(args.resolution))
    except (FileNotFoundError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for name, path in made.items():
        print(f"{name}: {path}")
    return 0


if __name__ == "__main__":
    code = main()
    if code:  # inside Blender a plain return would let it carry on
        sys.exit(code)
