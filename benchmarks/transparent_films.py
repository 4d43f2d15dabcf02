"""Transparent films against Cycles: a thin-wall soap bubble and a coated glass sphere.

Two scenes built by script (the sphere, camera and HDRI of tests/_cycles_scenes.py
``build_sphere_blend``, 256×256):

- **bubble**: a Principled BSDF with *Thin Wall* on, *Transmission Weight* 1, IOR 1 (the wall is
  the film alone), Roughness 0, Thin Film IOR 1.33 and a thickness varying 200–900 nm across the
  sphere (object x, a Map Range), in front of the studio HDRI: Cycles' thin wall, the extension's
  Cycles-matching mode (per-channel colour, ``WALL_CYCLES``);
- **glass**: a solid glass sphere (Transmission 1, IOR 1.5, Roughness 0) with a 300 nm film of
  IOR 1.33, over a checker-textured ground, same HDRI.

Cycles (CPU, no denoising, 16 bounces, no sample clamping) is rendered once per (scene, size,
samples, Blender) and cached in ``benchmarks/.cache/transparent_films/``; the headless render
runs in-process. Mean and 95th-percentile ΔE2000 over the sphere's pixels (one pixel of
silhouette left out), and a picture ours | Cycles | ΔE (×10 grey).

Run: ``.venv/bin/python -m benchmarks.transparent_films [--samples N] [--size N]`` →
``docs/transparent-films-cycles.md`` and ``docs/images/transparent_films.png``.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import pathlib
import sys
import tempfile
import time

import numpy as np

from benchmarks import common
from precompute.colour.colour_difference import delta_e_2000
from precompute.output import image_io, render

sys.path.insert(0, str(pathlib.Path(common.ROOT) / "tests"))
sys.path.insert(0, str(pathlib.Path(common.ROOT) / "scripts"))

import _cycles_scenes as cc  # noqa: E402

CACHE = pathlib.Path(common.ROOT) / "benchmarks" / ".cache" / "transparent_films"
SIZE = 256
SAMPLES = 1024
#: The seed of the second Cycles render that ``--seed-check`` scores against the reference (whose
#: seed is 1): the reference's own noise.
OTHER_SEED = 2
HDRI = "studio"
#: Issue 34's acceptance: mean ΔE2000 over the object, per scene, in the default frame (EEVEE
#: behind) and over a Cycles background pass.
LIMITS = {
    ("bubble", "EEVEE"): 2.0,
    ("bubble", "CYCLES"): 2.0,
    ("glass", "EEVEE"): 3.0,
    ("glass", "CYCLES"): 2.0,
    ("cube", "EEVEE"): 5.0,
    ("cube", "CYCLES"): 5.0,
    ("wineglass", "EEVEE"): 5.0,
    ("wineglass", "CYCLES"): 5.0,
    ("lamps", "EEVEE"): 3.0,  # no issue's limit: the ball's
    ("lamps", "CYCLES"): 2.0,
}
SCENES = ("bubble", "glass", "cube", "wineglass", "lamps")
#: Scenes whose object is the sphere (the ball or the bubble): masked and cut into regions as one.
SPHERES = ("bubble", "glass", "lamps")
#: Each scene's version, part of its reference's cache key. 2: Cycles' sample clamps off (Blender's
#: default indirect clamp of 10 dimmed the glass sphere's internal glints 30×: 0.3–0.5 instead of
#: 10–15, a biased reference). 3 (glass): roughness 0.05, the scene of issue 34's comparison.
#: 2 (cube, wine glass): lifted CONTACT_GAP off the ground (below).
SCENE_VERSION = {"bubble": 2, "glass": 3, "cube": 2, "wineglass": 2, "lamps": 1}
#: The "lamps" scene: the glass ball lit by a point light (position, power W, radius) and a
#: square area light (position, power W, size), both aimed at the ball, the World dimmed to this.
LAMP_POINT = ((1.2, 2.4, 2.6), 400.0, 0.1)
LAMP_AREA = ((-2.6, 1.0, 2.2), 300.0, 0.8)
LAMP_WORLD = 0.05
#: The cube and the wine glass stand this far (m) above the ground, not in its plane: with the
#: bottom face coplanar with the ground, Cycles lit the ground under the glass 9× darker than with
#: a 0.02 gap (a 6 × 6 × 2 block, IOR 1.5, white ground, uniform sky, 64 spp: 0.040 vs 0.351), a
#: ray-offset artefact of coincident surfaces, not light through glass.
CONTACT_GAP = 0.01
#: The glass objects' roughness (issue 34's independent comparison: 0.05).
GLASS_ROUGHNESS = 0.05
#: The cube: its side, the height of its centre (it stands on the ground at z = −1) and its turn
#: about the vertical (degrees), so that two of its faces and its top face the camera.
CUBE_SIDE, CUBE_Z, CUBE_TURN = 1.2, -0.4, 30.0
#: The wine glass: a lathe of this (radius, height) outline, closed, about the vertical; solid
#: glass between its outer and inner surfaces (a thick foot and stem, a bowl of 0.05 walls).
WINEGLASS_PROFILE = (
    (0.0, -1.0),
    (0.55, -1.0),
    (0.55, -0.96),
    (0.12, -0.92),
    (0.06, -0.82),
    (0.05, -0.45),
    (0.12, -0.32),
    (0.42, -0.1),
    (0.56, 0.15),
    (0.58, 0.45),
    (0.55, 0.7),
    (0.5, 0.7),
    (0.53, 0.45),
    (0.51, 0.17),
    (0.38, -0.06),
    (0.1, -0.25),
    (0.0, -0.27),
)
WINEGLASS_SEGMENTS = 96


def _bubble(bsdf, nt):
    bsdf.inputs["Base Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    bsdf.inputs["IOR"].default_value = 1.0
    bsdf.inputs["Transmission Weight"].default_value = 1.0
    bsdf.inputs["Thin Wall"].default_value = True
    bsdf.inputs["Thin Film IOR"].default_value = 1.33
    nt.links.new(cc._thickness_socket(nt, (200.0, 900.0)), bsdf.inputs["Thin Film Thickness"])


def _glass(bsdf, nt):
    bsdf.inputs["Base Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    bsdf.inputs["IOR"].default_value = 1.5
    bsdf.inputs["Roughness"].default_value = GLASS_ROUGHNESS
    bsdf.inputs["Transmission Weight"].default_value = 1.0
    bsdf.inputs["Thin Film IOR"].default_value = 1.33
    bsdf.inputs["Thin Film Thickness"].default_value = 300.0


def _ground(bpy):
    bpy.ops.mesh.primitive_plane_add(size=40.0, location=(0.0, 0.0, -1.0))
    plane = bpy.context.active_object
    mat = bpy.data.materials.new("ground")
    nt = mat.node_tree
    checker = nt.nodes.new("ShaderNodeTexChecker")
    checker.inputs["Scale"].default_value = 24.0
    checker.inputs["Color1"].default_value = (0.8, 0.25, 0.1, 1.0)
    checker.inputs["Color2"].default_value = (0.9, 0.9, 0.85, 1.0)
    bsdf = nt.nodes["Principled BSDF"]
    bsdf.inputs["Roughness"].default_value = 0.8
    nt.links.new(checker.outputs["Color"], bsdf.inputs["Base Color"])
    mat.diffuse_color = (0.85, 0.6, 0.5, 1.0)
    plane.data.materials.append(mat)


def _lathe(bm, profile, segments: int) -> None:
    """The closed (radius, height) ``profile`` turned about the z axis in ``segments`` steps, into
    ``bm``: quads between neighbouring rings, the axis points shared (triangle fans there)."""
    rings = []
    for k in range(segments):
        a = 2.0 * math.pi * k / segments
        rings.append([(r * math.cos(a), r * math.sin(a), z) for r, z in profile])
    verts = {}
    for k, ring in enumerate(rings):
        for j, co in enumerate(ring):
            key = (0, j) if profile[j][0] == 0.0 else (k, j)
            if key not in verts:
                verts[key] = bm.verts.new(co)
    count = len(profile)
    for k in range(segments):
        k2 = (k + 1) % segments
        for j in range(count - 1):
            quad = [(k, j), (k2, j), (k2, j + 1), (k, j + 1)]
            keys = [(0, jj) if profile[jj][0] == 0.0 else (kk, jj) for kk, jj in quad]
            face = list(dict.fromkeys(verts[key] for key in keys))
            if len(face) >= 3:
                bm.faces.new(face)


def _shape(bpy, name: str) -> None:
    """Give the film object the shape of the scene ``name``: the cube or the wine glass (the
    sphere stays)."""
    import bmesh

    obj = next(o for o in bpy.data.objects if o.type == "MESH" and "film" in o.data.materials)
    if name not in ("cube", "wineglass"):
        return
    bm = bmesh.new()
    if name == "cube":
        bmesh.ops.create_cube(bm, size=CUBE_SIDE)
        obj.location = (0.0, 0.0, CUBE_Z + CONTACT_GAP)
        obj.rotation_euler = (0.0, 0.0, math.radians(CUBE_TURN))
    else:
        _lathe(bm, WINEGLASS_PROFILE, WINEGLASS_SEGMENTS)
        bmesh.ops.recalc_face_normals(bm, faces=bm.faces)
        obj.location.z += CONTACT_GAP
    for face in bm.faces:
        face.smooth = name == "wineglass"
    mesh = bpy.data.meshes.new(name)
    bm.to_mesh(mesh)
    bm.free()
    mesh.materials.append(obj.data.materials[0])
    obj.data = mesh


def _lamps(bpy) -> None:
    """The "lamps" scene's lights (:data:`LAMP_POINT`, :data:`LAMP_AREA`) aimed at the ball at
    the origin, and its World dimmed to :data:`LAMP_WORLD`."""
    from mathutils import Vector

    for kind, (where, power, size) in (("POINT", LAMP_POINT), ("AREA", LAMP_AREA)):
        data = bpy.data.lights.new(kind.lower(), kind)
        data.energy = power
        if kind == "AREA":
            data.size = size
        else:
            data.shadow_soft_size = size
        obj = bpy.data.objects.new(kind.lower(), data)
        obj.location = where
        obj.rotation_euler = (-Vector(where)).to_track_quat("-Z", "Y").to_euler()
        bpy.context.scene.collection.objects.link(obj)
    background = bpy.context.scene.world.node_tree.nodes["Background"]
    background.inputs["Strength"].default_value = LAMP_WORLD


def build(
    name: str, path, size: int, samples: int, unbiased: bool = True, denoise: bool = False, seed: int = 1
):
    """The scene ``name`` (:data:`SCENES`) saved as a .blend; returns its path.
    ``unbiased``: Cycles' sample clamps off (the reference); else Blender's defaults (the
    headless frame's Cycles background pass, less noisy). ``denoise``: Cycles' denoiser on, as
    Blender sets it for a new scene's renders (OpenImageDenoise on the image, albedo and normal).
    ``seed``: Cycles' seed (the references' is 1; :data:`OTHER_SEED` for their noise floor)."""
    import bpy

    path = cc.build_sphere_blend(
        path, cc.studiolight_path(HDRI), 300.0, 1.33, 1.5, 0.0, size=size, samples=samples
    )
    scene = bpy.context.scene
    scene.cycles.max_bounces = 16
    scene.cycles.transmission_bounces = 16
    scene.cycles.transparent_max_bounces = 16
    if unbiased:
        scene.cycles.sample_clamp_direct = scene.cycles.sample_clamp_indirect = 0.0
    scene.cycles.use_denoising = bool(denoise)
    scene.cycles.seed = int(seed)
    mat = bpy.data.materials["film"]
    (_bubble if name == "bubble" else _glass)(mat.node_tree.nodes["Principled BSDF"], mat.node_tree)
    _shape(bpy, name)
    if name != "bubble":
        _ground(bpy)
    if name == "lamps":
        _lamps(bpy)
    bpy.ops.wm.save_as_mainfile(filepath=str(pathlib.Path(path).resolve()), check_existing=False)
    return path


def cycles_image(
    blend, name: str, size: int, samples: int, denoise: bool = False, seed: int = 1
) -> tuple[np.ndarray, float]:
    """Cycles' render of ``blend`` (built with ``denoise`` and ``seed``), cached: (RGB, seconds; 0
    if cached)."""
    import bpy

    key = json.dumps(
        [name, size, samples, bpy.app.version_string, SCENE_VERSION[name]]
        + (["denoised"] if denoise else [])
        + ([f"seed {seed}"] if seed != 1 else [])
    )
    path = CACHE / f"{name}_{hashlib.sha256(key.encode()).hexdigest()[:12]}.npz"
    if path.is_file():
        return np.load(path)["rgb"], 0.0
    t0 = time.perf_counter()
    rgb = cc.cycles_render_blend(blend)
    seconds = time.perf_counter() - t0
    CACHE.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, rgb=rgb)
    return rgb, seconds


def silhouette(blend, erode: int = 1) -> np.ndarray:
    """The film object's pixels (H, W) bool, a border of ``erode`` pixels left out: Workbench's
    render of it alone, no anti-aliasing, alpha > 0.5."""
    import bpy

    bpy.ops.wm.open_mainfile(filepath=str(pathlib.Path(blend).resolve()))
    scene = bpy.context.scene
    for obj in scene.objects:
        obj.hide_render = obj.type == "MESH" and "film" not in obj.data.materials
    scene.render.engine = "BLENDER_WORKBENCH"
    scene.display.render_aa = "OFF"
    scene.display.shading.light = "FLAT"
    scene.display.shading.color_type = "SINGLE"
    scene.display.shading.single_color = (1.0, 1.0, 1.0)
    scene.render.film_transparent = True
    with tempfile.TemporaryDirectory() as tmp:
        out = pathlib.Path(tmp) / "mask.exr"
        scene.render.image_settings.file_format = "OPEN_EXR"
        scene.render.filepath = str(out)
        bpy.ops.render.render(write_still=True)
        m = cc.read_exr(out).mean(axis=-1) > 0.5
    for _ in range(erode):
        m[1:-1, 1:-1] &= m[:-2, 1:-1] & m[2:, 1:-1] & m[1:-1, :-2] & m[1:-1, 2:]
        m[0, :] = m[-1, :] = m[:, 0] = m[:, -1] = False
    return m


def headless_image(blend, out_png, engine: str = "EEVEE") -> tuple[np.ndarray, float]:
    """The extension's headless render of ``blend``, in-process, the rest of the scene rendered
    by ``engine``: (RGB, seconds)."""
    import thinfilm_headless

    t0 = time.perf_counter()
    code = thinfilm_headless.run_file(str(blend), ["render", "--out", str(out_png), "--engine", engine])
    if code != 0:
        raise RuntimeError(f"headless render of {blend} failed with exit code {code}")
    return cc.read_exr(pathlib.Path(out_png).with_suffix(".exr")), time.perf_counter() - t0


def compare(
    name: str,
    workdir,
    size: int,
    samples: int,
    engine: str = "EEVEE",
    background_samples: int = 256,
    denoise: bool = False,
    seeds: int = 0,
) -> dict:
    """ΔE2000 of one scene over the sphere's pixels; ``engine`` renders the rest of the scene
    (Cycles at ``background_samples``); ``denoise``: the reference through Cycles' denoiser;
    ``seeds``: also render the same file with that many other seeds (:data:`OTHER_SEED` on):
    ``noise``, the mean ΔE2000 of the first against the reference (what Cycles itself scores);
    with two or more, ``floor``, their mean's against the reference (what a picture of that many
    times the samples scores: near what a converged one would), and ``converged``, ours against
    their mean."""
    blend = build(name, pathlib.Path(workdir) / f"{name}.blend", size, samples, denoise=denoise)
    ref, cycles_s = cycles_image(blend, name, size, samples, denoise)
    if engine == "CYCLES":
        blend = build(name, pathlib.Path(workdir) / f"{name}_ours.blend", size, background_samples, False)
    ours, ours_s = headless_image(blend, pathlib.Path(workdir) / f"{name}.png", engine)
    if name in SPHERES:
        mask = cc.object_mask(render.sphere_view(size, size, cc.DISTANCE, cc.FOV_DEG))
    else:
        mask = silhouette(blend)
    de = delta_e_2000(ours[mask], ref[mask], xyz="E")
    full = np.zeros(mask.shape)
    full[mask] = de
    parts = {
        key: float(np.sum(full[where & mask]) / max(mask.sum(), 1))
        for key, where in regions(name, ours, ref, size).items()
    }
    noise = floor = converged = None
    if seeds:
        others = [
            cycles_image(
                build(
                    name,
                    pathlib.Path(workdir) / f"{name}_seed{seed}.blend",
                    size,
                    samples,
                    denoise=denoise,
                    seed=seed,
                ),
                name,
                size,
                samples,
                denoise,
                seed,
            )[0]
            for seed in range(OTHER_SEED, OTHER_SEED + seeds)
        ]
        noise = float(np.mean(delta_e_2000(others[0][mask], ref[mask], xyz="E")))
        if seeds > 1:
            mean = np.mean(others, axis=0)
            floor = float(np.mean(delta_e_2000(mean[mask], ref[mask], xyz="E")))
            converged = float(np.mean(delta_e_2000(ours[mask], mean[mask], xyz="E")))
    around = ~mask
    around[: size // 2] = False  # the ground beside and in front of the object
    parts["ground"] = float(np.mean(delta_e_2000(ours[around], ref[around], xyz="E")))
    return dict(
        name=name,
        limit=LIMITS[(name, "CYCLES" if engine == "CYCLES" else "EEVEE")],
        engine=engine if engine != "CYCLES" else f"Cycles {background_samples} spp",
        mean=float(np.mean(de)),
        p95=float(np.percentile(de, 95)),
        cycles_s=cycles_s,
        ours_s=ours_s,
        ours=ours,
        cycles=ref,
        delta_e=full,
        parts=parts,
        noise=noise,
        floor=floor,
        converged=converged,
        seeds=seeds,
    )


#: A pixel is a glint where either picture's luminance exceeds this (the lamps' reflections).
GLINT_LUMINANCE = 2.0
#: The rim: where the sphere's normal is within this cosine of the silhouette (rays bent far).
RIM_COS = 0.35


def regions(name: str, ours, ref, size: int) -> dict:
    """Where the ΔE comes from (H, W) bool each, disjoint: ``glints`` (either picture brighter
    than :data:`GLINT_LUMINANCE`, one pixel around), then on a sphere the ``rim`` (n·v <
    :data:`RIM_COS`), and the ``upper`` and ``lower`` halves of the picture's rows (a sphere's
    halves about its centre, another object's about the picture's middle)."""
    y = np.maximum(ours @ LUMA, ref @ LUMA) > GLINT_LUMINANCE
    glints = y.copy()
    glints[1:] |= y[:-1]
    glints[:-1] |= y[1:]
    glints[:, 1:] |= y[:, :-1]
    glints[:, :-1] |= y[:, 1:]
    out = {"glints": glints}
    rest = ~glints
    if name in SPHERES:
        view = render.sphere_view(size, size, cc.DISTANCE, cc.FOV_DEG)
        cos = np.sum(view.normals * view.views, axis=-1)
        out["rim"] = rest & (cos < RIM_COS)
        rest = rest & ~out["rim"]
    upper = (np.arange(size) < size // 2)[:, None] & np.ones((1, size), dtype=bool)
    out["upper"] = rest & upper
    out["lower"] = rest & ~upper
    return out


LUMA = np.array([0.2126, 0.7152, 0.0722])
#: The regions' order in the report.
PARTS = ("glints", "rim", "upper", "lower")


def write_picture(rows, path) -> None:
    """ours | Cycles | ΔE/10 (grey), one row per scene, sRGB."""
    lines = []
    for row in rows:
        de = np.repeat(np.clip(row["delta_e"] / 10.0, 0.0, 1.0)[..., None], 3, axis=-1)
        lines.append(
            np.concatenate([image_io.srgb_encode(row[k]) for k in ("ours", "cycles")] + [de], axis=1)
        )
    image_io.write_png(path, np.concatenate(lines, axis=0))


#: What the report says about the background pass and the figures (docs/transparent-films.md).
NOTES = """\
**The background pass.** The headless frame draws the films over Blender's render of the rest
of the scene (`render --engine`, default EEVEE). EEVEE's pass is lit by the World's lamps as sun
lights (addon/headless/background_lamps.py: under this studio HDRI, a lamp of 616 in a panorama
of mean 0.55, EEVEE's own World lighting lit the checker ground 5.1× brighter than Cycles; the
lamps as suns 0.98×); thin transparent films cast no EEVEE shadow there, solid glass casts
EEVEE's opaque shadow and the suns' light through and off it is traced through its mesh, as
rough as Cycles' Filter Glossy (1, Blender's default, in these references) makes the glass on
caustic paths, and put back (addon/headless/caustics.py: its shadow and caustics on the
ground). A run with
`--engine CYCLES` renders the pass with Cycles instead: the comparison is then of the films
alone. The bubble's background is the HDRI alone, the same in every engine.

**Solid glass** (ball, cube, wine glass; a 300 nm film of 1.33 on glass of 1.5, roughness 0.05)
leaves through its real mesh: its nearest front and back faces per pixel (the glass buffers),
total internal reflection followed (8 faces; a path still inside then is dark, as Cycles' bounce
limit makes it), faces shaded smooth met as Cycles meets them (its correction of a normal
tilted past its face), refracted over the background pass's depth (overscanned on
each side; a ray leaving the picture sees its edge if it heads into it, else the World), up to
four reflections inside (the glints)
and the ground mirrored (docs/transparent-films.md#solid-glass-refraction). The film seen from
inside is Cycles' back-face film (its index divided by the glass's). *glints*, *rim*, *upper*,
*lower*: the mean ΔE2000 over the object's pixels contributed by its glints (either picture's
luminance above 2, one pixel around), a ball's rim (n·v < 0.35; – for other shapes) and the
rest of its upper and lower halves: they add up to the mean. *lamps*: the same ball under a
point light (400 W, radius 0.1 m) and a 0.8 m square area light (300 W), both aimed at it, the
World dimmed to 0.05: its shadow and caustics traced from the lights' centre and the area's
cells (precompute/optics/sources.py).

**Unclamped Cycles.** Blender's default indirect clamp (10 per sample) dimmed the ball's glints
30× in the first references (a reflection chosen with probability F ≈ 0.03 carries 1/F of the
lamp's 400 and is clamped), so the references are rendered with the clamps off
(`SCENE_VERSION` 2). Not in our frame: a concave glass's spans beyond its second (the glass
buffers hold two front and two back faces per pixel), light inside the glass after more than
four reflections, light
the ground sends back onto itself through the glass (a second diffuse bounce). The cube and
the wine glass stand 1 cm above the ground (`CONTACT_GAP`, `SCENE_VERSION` 2 for both): with
their bottom faces in the ground's plane Cycles lit the ground under them 9× too dark (a probe:
a 6 × 6 × 2 glass block, IOR 1.5, roughness 0.05, on a white ground under a uniform sky, 64 spp,
lights the ground under it 0.040 in contact and 0.351 with a 0.02 gap), which gave 3.3 of the
cube's 8.2 and 9.3 of the wine glass's 23.8.

*Cycles s* is 0 for a cached render: the 1024-spp ones took 876 s (glass) and 353 s (bubble) on
this machine at a load average of 6–8.
"""


#: The report's note on ``--seed-check``'s column (``--seeds``' first).
SEED_NOTE = """\
*Cycles, another seed*: Cycles' render of the same file at the same samples with seed {seed}
instead of 1, scored against the reference as ours is: the reference's own noise. A mean
ΔE2000 limit below that figure asks a render to be nearer the reference than Cycles is to
itself."""

FLOOR_NOTE = """\
*Cycles, {n} seeds' mean*: the mean of Cycles' renders with seeds {first}–{last} ({n} × the
samples), scored against the reference: about what a converged picture scores against it, the
lowest figure any renderer can reach there. *Ours against that mean*: ours scored against the
nearly converged picture instead of the reference, its own error without most of the
reference's noise."""


def report(
    rows,
    size: int,
    samples: int,
    picture: str = "transparent_films.png",
    command: str = "",
    denoise: bool = False,
) -> str:
    """The markdown report."""
    noise = "Cycles' denoiser (OpenImageDenoise, Blender's default)" if denoise else "no denoising"
    seeded = any(r.get("noise") is not None for r in rows)
    floored = [r for r in rows if r.get("floor") is not None]
    extra = (" Cycles, another seed |" if seeded else "") + (
        f" Cycles, {floored[0]['seeds']} seeds' mean | ours against that mean |" if floored else ""
    )
    lines = [
        "# Transparent films against Cycles",
        "",
        "Generated by `.venv/bin/python -m benchmarks.transparent_films"
        f"{command or f' --size {size} --samples {samples}'}` (benchmarks/transparent_films.py).",
        "",
        f"Scenes: {size}×{size}, Cycles {samples} spp (CPU, {noise}, 16 bounces, no sample clamping),"
        " studio HDRI.",
        f"Machine: {'; '.join(common.machine_lines())}. Load average: {common.load_average()}.",
        f"Code: {common.git_describe(('precompute', 'addon', 'glsl', 'benchmarks'))}.",
        "",
        "| scene | background pass | mean ΔE2000 | p95 | limit | glints | rim | upper | lower"
        " | Cycles s | ours s |" + extra,
        "|---|---|---|---|---|---|---|---|---|---|---|" + "---|" * extra.count("|"),
    ]

    def figure(value) -> str:
        return f" {value:.2f} |" if value is not None else " – |"

    for r in rows:
        lines.append(
            f"| {r['name']} | {r['engine']} | {r['mean']:.2f} | {r['p95']:.2f} | {r['limit']:.0f} | "
            + " | ".join(
                f"{r['parts'][k]:.2f}" if k in r["parts"] else "–"
                for k in ("glints", "rim", "upper", "lower")
            )
            + f" | {r['cycles_s']:.0f} | {r['ours_s']:.1f} |"
            + (figure(r.get("noise")) if seeded else "")
            + (figure(r.get("floor")) + figure(r.get("converged")) if floored else "")
        )
    if seeded:
        lines += ["", SEED_NOTE.format(seed=OTHER_SEED)]
    if floored:
        n = floored[0]["seeds"]
        lines += ["", FLOOR_NOTE.format(n=n, first=OTHER_SEED, last=OTHER_SEED + n - 1)]
    lines += ["", NOTES, f"![ours | Cycles | ΔE/10, one row per scene](images/{picture})", ""]
    return "\n".join(lines)


def main(argv=None) -> int:
    """Build, render and compare the two scenes; write the report and picture."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=SIZE)
    parser.add_argument("--samples", type=int, default=SAMPLES)
    parser.add_argument("--scenes", nargs="+", default=list(SCENES), choices=SCENES)
    parser.add_argument(
        "--engine",
        default="EEVEE",
        choices=("EEVEE", "CYCLES", "WORKBENCH"),
        help="the engine of the headless frame's background pass (render --engine)",
    )
    parser.add_argument("--background-samples", type=int, default=256, help="with --engine CYCLES")
    parser.add_argument("--out", default="transparent-films-cycles.md")
    parser.add_argument("--picture", default="transparent_films.png", help="under docs/images/")
    parser.add_argument("--dump", help="also save each scene's pictures and ΔE here (.npz), to study")
    parser.add_argument(
        "--denoise", action="store_true", help="the references through Cycles' denoiser (cached apart)"
    )
    parser.add_argument(
        "--seed-check",
        action="store_true",
        help=f"also render each reference with seed {OTHER_SEED} (cached) and score it against the "
        "reference: the reference's own noise (--seeds 1)",
    )
    parser.add_argument(
        "--seeds",
        type=int,
        default=0,
        help=f"also render each reference with this many other seeds ({OTHER_SEED} on, cached); with "
        "2 or more, their mean is scored against the reference (about a converged picture's figure) "
        "and ours against their mean",
    )
    args = parser.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.scenes:
            row = compare(
                name,
                pathlib.Path(tmp),
                args.size,
                args.samples,
                args.engine,
                args.background_samples,
                args.denoise,
                max(args.seeds, int(args.seed_check)),
            )
            split = ", ".join(f"{k} {v:.2f}" for k, v in row["parts"].items())
            seeded = (
                f"; Cycles with seed {OTHER_SEED}: {row['noise']:.2f}" if row["noise"] is not None else ""
            )
            if row["floor"] is not None:
                seeded += (
                    f"; the mean of {row['seeds']} seeds: {row['floor']:.2f}, ours against it "
                    f"{row['converged']:.2f}"
                )
            print(
                f"{name}: mean ΔE2000 {row['mean']:.2f}, p95 {row['p95']:.2f} ({split}){seeded}", flush=True
            )
            rows.append(row)
            if args.dump:
                keep = {k: row[k] for k in ("ours", "cycles", "delta_e")}
                pathlib.Path(args.dump).mkdir(parents=True, exist_ok=True)
                np.savez_compressed(pathlib.Path(args.dump) / f"{name}_{args.engine}.npz", **keep)
    import thinfilm_headless

    thinfilm_headless.release()  # GPU data freed while Blender lives (else a crash at exit)
    write_picture(rows, pathlib.Path(common.ROOT) / "docs" / "images" / args.picture)
    command = " " + " ".join(sys.argv[1:] if argv is None else argv)
    text = report(rows, args.size, args.samples, args.picture, command, args.denoise)
    print(common.write_doc(args.out, text))
    return 0


if __name__ == "__main__":
    sys.exit(main())
