"""Blender's light objects on a film sphere: the headless frame against Cycles, and frame time.

Four scenes (issue 18), each built once in bpy and rendered twice — by Cycles (CPU, box pixel
filter) and by the extension's headless ``render`` (the GLSL path on whatever OpenGL is present,
rendered at 2× and box-averaged to Cycles' pixel filter) — and compared by mean ΔE2000 over the
sphere (``precompute.colour.colour_difference.delta_e_2000``, ``"E"`` white, as
benchmarks/cycles_compare.py):

- ``sun``: an opaque film sphere (Principled, Base Color black: the film's specular layer only)
  lit by a sun and a dim HDRI;
- ``point_area``: the same kind of sphere lit by a point lamp and a rectangular area lamp in a
  dark grey World;
- ``spot_metal``: a film on a metal (Principled Metallic 1) lit by a spot lamp whose cone edge
  crosses the sphere, and a dim HDRI;
- ``paint``: a film over a diffuse base (Principled Base Color) lit by a point lamp in a dark
  grey World: the base under the film, which the light objects light as Cycles does.

The frame time with 1 / 8 / 32 point lights is measured on the same sphere (viewport draw path,
:func:`time_lights`).

Run: ``.venv/bin/python -m benchmarks.scene_lights [--size 256 --samples 1024]`` →
``docs/scene-lights.md`` and ``docs/images/scene-lights-*.png``. Cycles frames are kept in
``--cache`` (default: a folder in the temp directory) by size and samples, so a rerun only
re-renders ours.
"""

from __future__ import annotations

import argparse
import math
import pathlib
import tempfile
import time

import numpy as np

from benchmarks import common
from precompute.colour.colour_difference import delta_e_2000
from precompute.commands.cli import studiolight
from precompute.output import image_io, render
from precompute.world import hdri
from tests._cycles_scenes import DISTANCE, FOV_DEG, cycles_settings, object_mask

DOCS = pathlib.Path(common.ROOT) / "docs"
LIMIT = 2.0  # issue 18: mean ΔE2000 over the object ≤ 2

#: name → scene description (materials: Principled inputs; lights: kind, location, target, settings)
CASES = {
    "sun": {
        "what": "opaque film sphere (film 450 nm, IOR 1.33 on IOR 1.5, roughness 0.2), "
        "sun 4 W/m² (1°) + HDRI 'forest' × 0.05",
        "material": {"Roughness": 0.2, "IOR": 1.5, "Thin Film Thickness": 450.0, "Thin Film IOR": 1.33},
        "world": ("hdri", "forest", 0.05),
        "lights": [
            (
                "SUN",
                (3.0, -4.0, 3.0),
                (0.0, 0.0, 0.0),
                {"energy": 4.0, "angle": math.radians(1.0), "color": (1.0, 0.95, 0.9)},
            )
        ],
    },
    "point_area": {
        "what": "opaque film sphere (film 350 nm, IOR 1.4 on IOR 1.5, roughness 0.3), "
        "point 300 W (r 0.1 m) + rectangle 1 × 0.4 m 150 W, grey World 0.02",
        "material": {"Roughness": 0.3, "IOR": 1.5, "Thin Film Thickness": 350.0, "Thin Film IOR": 1.4},
        "world": ("grey", 0.02),
        "lights": [
            ("POINT", (2.5, -2.5, 2.0), None, {"energy": 300.0, "shadow_soft_size": 0.1}),
            (
                "AREA",
                (-2.0, -2.5, 0.5),
                (0.0, 0.0, 0.0),
                {"energy": 150.0, "shape": "RECTANGLE", "size": 1.0, "size_y": 0.4, "color": (0.8, 0.9, 1.0)},
            ),
        ],
    },
    "paint": {
        "what": "a painted sphere under a film (Principled Base Color (0.6, 0.3, 0.15), film 300 nm, "
        "IOR 1.33 on IOR 1.5, roughness 0.4), point 300 W (r 0.1 m), grey World 0.02",
        "material": {
            "Base Color": (0.6, 0.3, 0.15, 1.0),
            "Roughness": 0.4,
            "IOR": 1.5,
            "Thin Film Thickness": 300.0,
            "Thin Film IOR": 1.33,
        },
        "world": ("grey", 0.02),
        "lights": [("POINT", (2.5, -2.5, 2.0), None, {"energy": 300.0, "shadow_soft_size": 0.1})],
    },
    "spot_metal": {
        "what": "film 300 nm, IOR 1.45 on a metal (Metallic 1, base (0.9, 0.6, 0.3), roughness 0.25), "
        "spot 800 W 40° blend 0.2 + HDRI 'courtyard' × 0.05",
        "material": {
            "Roughness": 0.25,
            "Metallic": 1.0,
            "Base Color": (0.9, 0.6, 0.3, 1.0),
            "Thin Film Thickness": 300.0,
            "Thin Film IOR": 1.45,
        },
        "world": ("hdri", "courtyard", 0.05),
        "lights": [
            (
                "SPOT",
                (-1.5, -3.0, 2.5),
                (0.4, 0.0, 0.3),
                {
                    "energy": 800.0,
                    "spot_size": math.radians(40.0),
                    "spot_blend": 0.2,
                    "shadow_soft_size": 0.05,
                },
            )
        ],
    },
}


def _aim(obj, target) -> None:
    import mathutils

    direction = mathutils.Vector(target) - obj.location
    obj.rotation_euler = direction.to_track_quat("-Z", "Y").to_euler()


def build_scene(case: dict, size: int) -> object:
    """The case's scene in the current (factory) file: sphere, material, lights, World, camera."""
    import bpy

    scene = bpy.context.scene
    scene.render.resolution_x = scene.render.resolution_y = size
    scene.render.resolution_percentage = 100
    scene.view_settings.view_transform = "Standard"
    world = bpy.data.worlds.new("world")
    nt = world.node_tree
    background = nt.nodes["Background"]
    if case["world"][0] == "hdri":
        env = nt.nodes.new("ShaderNodeTexEnvironment")
        env.image = bpy.data.images.load(str(studiolight(case["world"][1])))
        nt.links.new(env.outputs["Color"], background.inputs["Color"])
        background.inputs["Strength"].default_value = case["world"][2]
    else:
        grey = case["world"][1]
        background.inputs["Color"].default_value = (grey, grey, grey, 1.0)
    scene.world = world
    bpy.ops.mesh.primitive_uv_sphere_add(segments=256, ring_count=128, radius=1.0)
    sphere = bpy.context.active_object
    bpy.ops.object.shade_smooth()
    mat = bpy.data.materials.new("film")
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    for name, value in case["material"].items():
        bsdf.inputs[name].default_value = value
    sphere.data.materials.append(mat)
    for i, (kind, location, target, settings) in enumerate(case["lights"]):
        light = bpy.data.lights.new(f"light{i}", kind)
        for key, value in settings.items():
            setattr(light, key, value)
        obj = bpy.data.objects.new(f"light{i}", light)
        scene.collection.objects.link(obj)
        obj.location = location
        if target is not None:
            _aim(obj, target)
        obj.visible_camera = False
    cam_data = bpy.data.cameras.new("cam")
    cam_data.angle = math.radians(FOV_DEG)
    cam = bpy.data.objects.new("cam", cam_data)
    cam.location = (0.0, -DISTANCE, 0.0)
    cam.rotation_euler = (math.pi / 2, 0.0, 0.0)
    scene.collection.objects.link(cam)
    scene.camera = cam
    bpy.context.view_layer.update()
    return scene


def cycles_frame(scene, samples: int) -> np.ndarray:
    """Cycles' scene-linear RGB of the scene (CPU, box filter, no denoising), top row first."""
    import bpy

    cycles_settings(scene, samples)
    with tempfile.TemporaryDirectory() as tmp:
        out = pathlib.Path(tmp) / "cycles.exr"
        scene.render.image_settings.file_format = "OPEN_EXR"
        scene.render.image_settings.color_depth = "32"
        scene.render.filepath = str(out)
        bpy.ops.render.render(write_still=True)
        return hdri.read_equirect(out)[..., :3]


SUPERSAMPLE = 2


def our_frame(ext, scene, size: int) -> tuple[np.ndarray, dict]:
    """The headless ``render`` command's frame (2× and box-averaged), and its summary."""
    with tempfile.TemporaryDirectory() as tmp:
        out = pathlib.Path(tmp) / "ours.png"
        summary = ext.render.render_scene(scene, str(out), size * SUPERSAMPLE, size * SUPERSAMPLE)
        image = hdri.read_equirect(out.with_suffix(".exr"))[..., :3]
    return render.box_downsample(image, SUPERSAMPLE), summary


def compare(name: str, size: int, samples: int, cache: pathlib.Path, ext) -> dict:
    """One case: Cycles (cached) and ours on the same scene; ΔE2000 over the sphere."""
    import bpy

    case = CASES[name]
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    ext.package.register()
    scene = build_scene(case, size)
    cached = cache / f"{name}_{size}_{samples}.npy"
    t0 = time.perf_counter()
    if cached.exists():
        ref = np.load(cached)
    else:
        ref = cycles_frame(scene, samples)
        cache.mkdir(parents=True, exist_ok=True)
        np.save(cached, ref)
    t_cycles = time.perf_counter() - t0
    ours, summary = our_frame(ext, scene, size)
    mask = object_mask(render.sphere_view(size, size, DISTANCE, FOV_DEG))
    de = delta_e_2000(ours[mask], ref[mask], xyz="E")
    return {
        "name": name,
        "what": case["what"],
        "mean": float(np.mean(de)),
        "p95": float(np.percentile(de, 95)),
        "ratio": (ours[mask].mean(0) / np.maximum(ref[mask].mean(0), 1e-12)).tolist(),
        "cycles_s": t_cycles,
        "ours_s": summary["seconds"],
        "messages": summary["messages"],
        "ref": ref,
        "ours": ours,
        "de": np.where(mask, 0.0, 0.0) + _scatter(mask, de),
    }


def _scatter(mask, values) -> np.ndarray:
    out = np.zeros(mask.shape)
    out[mask] = values
    return out


TIMED = ((0, "POINT"), (1, "POINT"), (8, "POINT"), (32, "POINT"), (8, "AREA"))


def time_lights(ext, cases=TIMED, size: int = 256, frames: int = 5) -> list[dict]:
    """Median headless frame time (ms; collect + draw + read-back of a float frame) of the film
    sphere with ``count`` lights of ``kind`` around it, after a warm-up frame."""
    import bpy

    rows = []
    for count, kind in cases:
        bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
        ext.package.register()
        case = dict(CASES["point_area"])
        rng = np.random.default_rng(count)
        lights = []
        for _ in range(count):
            d = rng.normal(size=3)
            d = 3.0 * d / np.linalg.norm(d)
            d[1] = -abs(d[1])
            settings = {"energy": 100.0, "shadow_soft_size": 0.1} if kind == "POINT" else {"energy": 100.0}
            lights.append((kind, tuple(d), (0.0, 0.0, 0.0), settings))
        case["lights"] = lights
        scene = build_scene(case, size)
        with tempfile.TemporaryDirectory() as tmp:
            out = pathlib.Path(tmp) / "t.png"
            ext.render.render_scene(scene, str(out), size, size, background=False)  # warm-up: bake, compile
            times = []
            for _ in range(frames):
                t0 = time.perf_counter()
                ext.render.render_scene(scene, str(out), size, size, background=False)
                times.append(time.perf_counter() - t0)
        rows.append({"lights": count, "kind": kind, "ms": 1000.0 * float(np.median(times))})
    return rows


def area_accuracy(samples=(2, 3, 4, 6), roughnesses=(0.1, 0.2, 0.3, 0.6), distances=(0.7, 1.5, 4.0)):
    """The sampled rectangle against a 160 × 160 grid (numpy, precompute.shading.lights): mean
    relative per-pixel error over 300 points of a plane lit by a 1 × 0.6 m light, uniform and
    lobe-following cells, per roughness, distance and cells per axis."""
    from precompute.bakes import bake
    from precompute.colour import film_colour
    from precompute.materials.material import Layer, Material, Quality
    from precompute.shading import lights as light_shading
    from precompute.shading import policy

    material = Material(
        layers=(Layer(1.33, 400.0),),
        substrate=1.5,
        roughness=0.3,
        colour_mode="per_channel",
        quality=Quality(sh_order=4, view_samples=16, wavelength_count=48),
    )
    film = film_colour.film_table(bake.bake(material))
    rng = np.random.default_rng(1)
    count = 300
    p = np.concatenate([rng.uniform(-1, 1, (count, 2)), np.zeros((count, 1))], -1)
    normals = np.tile([0.0, 0.0, 1.0], (count, 1))
    v = np.array([0.0, -0.5, 1.0]) / np.linalg.norm([0.0, -0.5, 1.0])
    views = np.tile(v, (count, 1))
    saved = policy.AREA_SAMPLES, policy.AREA_LOBE_SCALE
    rows = []
    try:
        for rough in roughnesses:
            for z in distances:
                m = np.eye(4)
                c, s_ = math.cos(math.radians(20.0)), math.sin(math.radians(20.0))
                m[:3, :3] = [[1, 0, 0], [0, c, -s_], [0, s_, c]]
                m[:3, 3] = (0.0, 0.5, z)
                row = light_shading.light_from_blender(
                    "AREA", m, (1, 1, 1), 100.0, shape="RECTANGLE", size=1.0, size_y=0.6
                )
                lights = light_shading.Lights.from_rows([row])

                def shade(n_cells, lobe_scale, lights=lights, rough=rough):
                    policy.AREA_SAMPLES, policy.AREA_LOBE_SCALE = n_cells, lobe_scale
                    return light_shading.shade(film, lights, rough, p, normals, views)

                ref = shade(160, 1e9)
                entry = {"roughness": rough, "distance": z}
                for n_cells in samples:
                    for name, scale in (("uniform", 1e9), ("lobe", saved[1])):
                        out = shade(n_cells, scale)
                        entry[(name, n_cells)] = float(np.mean(np.abs(out - ref)) / np.mean(ref))
                rows.append(entry)
    finally:
        policy.AREA_SAMPLES, policy.AREA_LOBE_SCALE = saved
    return rows


def _picture(row, path: pathlib.Path) -> None:
    """Cycles | ours | ΔE2000 (0 … 10 as grey) side by side, sRGB."""
    ref = image_io.srgb_encode(row["ref"], 0.0)
    ours = image_io.srgb_encode(row["ours"], 0.0)
    de = np.clip(row["de"] / 10.0, 0.0, 1.0)[..., None] * np.ones(3)
    image_io.write_png(path, np.concatenate([ref, ours, de], axis=1))


AREA_TEXT = [
    "## Area samples",
    "",
    "A rectangle is integrated with S × S cells, one sample each; the GGX D of each sample is widened",
    "by the cell's footprint (α'² = α² + Ω/4). *Uniform*: equal cells. *Lobe*: cells holding equal",
    "shares of a Cauchy of width `AREA_LOBE_SCALE` · α around where the mirror ray meets the light",
    "(policy.py), so they are small where the film's lobe is and wide elsewhere — the same cost.",
    "Mean relative per-pixel error against 160 × 160 cells, a 1 × 0.6 m light tilted 20°, 300 points",
    "of a film plane (benchmarks/scene_lights.py `area_accuracy`; tests/parity/test_scene_lights.py checks",
    "the 4 × 4 figure at roughness 0.3, 1.5 m). The product uses 4 × 4 lobe cells (16 samples per light);",
    "at roughness ≤ 0.1 close to a large light the highlight's edge is still visibly approximate.",
    "",
]

STATIC_TEXT = [
    "## How Blender's lights become radiance (as Cycles)",
    "",
    "From Cycles' `scene/light.cpp` and `kernel/light/*.h`, checked against Cycles renders by",
    "tests/parity/test_scene_lights.py (white Lambertian plane and white mirror, 16 × 16 pixels: every ratio",
    "within 0.7 %; the acceptance is 2 %):",
    "",
    "| light | Blender setting | what the film receives |",
    "|---|---|---|",
    "| sun | strength S (W/m²), angle | irradiance S (disc of radiance S / (π sin²(angle/2))) |",
    "| point | power P (W), radius r | sphere of radiance P / (4π² r²): intensity P / (4π) |",
    "| spot | as point, size, blend | × smoothstep((cos ψ − cos(size/2)) / ((1 − cos(size/2)) · blend)) |",
    "| area | power P, shape, size | radiance P / (π A), A = u·v (× π/4 for disk and ellipse), one-sided |",
    "| all | colour, exposure, Specular | × colour (× temperature colour) × 2^exposure × Specular factor |",
    "",
    "*Normalize* off drops the division by the area (Cycles' `normalize`). Area *spread* is Cycles'",
    "attenuation (tan(spread/2) − tan θ) × its normalisation. A light object with *Glossy* ray",
    "visibility off, or Specular 0, does not reach the film; a light with a receiver collection",
    "(light linking) lights only the objects it includes.",
    "",
    "## How the film is shaded",
    "",
    "Each sample is shaded like the World's lamps: D G₂ F(ωo·h) / (4 cos θo) × E⊥ with the film's",
    "reflectance F at that sample's own half vector (precompute/shading/lights.py, the numpy mirror",
    "of glsl/tf_lights.glsl; tests/drawing/test_scene_lights_draw.py compares them per pixel). Suns, points",
    "and spots are one sample at their centre (the sphere's exact irradiance above the horizon); a",
    "light below the surface's horizon, or an area light seen from behind, contributes nothing.",
    "Up to 32 lights (`policy.MAX_LIGHTS`) in a uniform buffer; moving or editing a light changes",
    "only that buffer (no bake, no World analysis: tests/viewport/test_scene_lights_viewport.py).",
    "",
    "**A diffuse base** under the film (a Principled BSDF's Base Color, the panel's *Diffuse Base*)",
    "is lit by every sample too: E⊥ cos θi times the base's BRDF at the view",
    "(`film_colour.diffuse_view`, a layer of the film texture): Base Color / π × the specular",
    "layer's layering weight at the view angle, as Cycles' Principled BSDF layers it (per-channel",
    "mode; spectral mode: Base Color / π × (1 − R) per channel on the way in and out). A Principled",
    "plane under a sun against Cycles: tests/parity/test_scene_lights.py (≤ 3 %; the film's",
    "specular layer alone is 1–6 % of it); the `paint` case above.",
    "",
    "**Not yet:** shadows cast by other objects (every light reaches every film surface facing it);",
    "a light's Diffuse factor (the base takes its Specular factor; both 1 by default); blocker and",
    "shadow linking; Cycles' soft falloff of a point light closer than its radius; a spot's",
    "non-uniform scale.",
    "",
    "## Linearly transformed cosines: not used",
    "",
    "An earlier, unfinished LTC attempt (untracked `precompute/ltc.py`, `scripts/fit_ltc.py`) was",
    "evaluated and left out: it has no fitted table, no shader and no tests, needs scipy to fit,",
    "and applies the film's reflectance at one dominant direction per light — the per-view-angle",
    "simplification this extension exists to avoid for broad lobes. The cell samples keep the film",
    "at every sample's half vector, are exact for rough films (errors above) and cost 16 samples",
    "per rectangle; an LTC would pay off for glossy films close to large lights, where the cells",
    "are weakest, if the film were applied per lobe region (future work).",
    "",
]


def write_report(rows, timing, size, samples, path: pathlib.Path, area=None) -> None:
    """docs/scene-lights.md: the cases, their ΔE2000, pictures, the frame times, the area-light
    sampling's accuracy and the fixed notes (:data:`AREA_TEXT`, :data:`STATIC_TEXT`)."""
    covered = int(object_mask(render.sphere_view(size, size, DISTANCE, FOV_DEG), erode=0).sum())
    lines = [
        "# Light objects on the film: against Cycles",
        "",
        f"`benchmarks/scene_lights.py` at {size}×{size}, Cycles {samples} spp (CPU, box filter), the",
        "headless `render` frame (GLSL, drawn at 2× and box-averaged), Cycles-matching colour mode",
        "(Principled materials), mean ΔE2000 over the sphere (one pixel of its edge left out).",
        "Limit (issue 18): ≤ 2.",
        "",
        "| case | scene | mean ΔE2000 | p95 | ours / Cycles (mean RGB) |",
        "|---|---|---|---|---|",
    ]
    for r in rows:
        ratio = ", ".join(f"{x:.3f}" for x in r["ratio"])
        ok = "✓" if r["mean"] <= LIMIT else "✗"
        lines.append(f"| `{r['name']}` | {r['what']} | {r['mean']:.2f} {ok} | {r['p95']:.2f} | {ratio} |")
    lines += ["", "Pictures: Cycles | ours | ΔE2000 (black 0 → white ≥ 10).", ""]
    for r in rows:
        lines.append(f"![{r['name']}](images/scene-lights-{r['name']}.png)")
        lines.append("")
    if timing:
        lines += [
            "## Frame time against the number of lights",
            "",
            f"Headless frame of the film sphere at {size}×{size} (collect, draw, read back), median of 5, on",
            f"**{common.cpu_model()} with Mesa llvmpipe (software rasterisation)**: figures for",
            "comparing light counts with each other, not a GPU's frame time. Point lights (one sample each).",
            "The headless frame's other work (Solid drawing for depth, read-back, collecting) dominates",
            "and varies by hundreds of ms on a shared machine: small differences are noise.",
            "",
            f"The sphere covers {covered} pixels; the last column is (frame − frame without lights) /",
            "(lights × covered pixels).",
            "",
            "| lights | ms per frame | ns per light per covered pixel |",
            "|---|---|---|",
        ]
        base = timing[0]["ms"]
        for t in timing:
            per = 1e6 * (t["ms"] - base) / (t["lights"] * covered) if t["lights"] else 0.0
            lines.append(f"| {t['lights']} {t['kind'].lower()} | {t['ms']:.1f} | {per:.1f} |")
        lines.append("")
    if area:
        lines += AREA_TEXT
        cells = sorted({k[1] for k in area[0] if isinstance(k, tuple)})
        head = " | ".join(f"{n}×{n} uniform | {n}×{n} lobe" for n in cells)
        lines += [f"| roughness | distance (m) | {head} |", "|---|---|" + "---|" * (2 * len(cells))]
        for r in area:
            vals = " | ".join(
                f"{100 * r[('uniform', n)]:.1f} % | {100 * r[('lobe', n)]:.1f} %" for n in cells
            )
            lines.append(f"| {r['roughness']} | {r['distance']} | {vals} |")
        lines.append("")
    lines += STATIC_TEXT
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def main(argv=None) -> int:
    """Run the cases (and the timing), write the report and pictures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--samples", type=int, default=1024)
    parser.add_argument("--cases", nargs="*", default=sorted(CASES))
    parser.add_argument("--cache", default=str(pathlib.Path(tempfile.gettempdir()) / "tf_scene_lights"))
    parser.add_argument("--no-timing", action="store_true")
    parser.add_argument("--no-area", action="store_true", help="skip the area-light sampling table")
    parser.add_argument("--report", default=str(DOCS / "scene-lights.md"))
    args = parser.parse_args(argv)
    from benchmarks.viewport.scene import Extension

    ext = Extension()
    rows = []
    for name in args.cases:
        row = compare(name, args.size, args.samples, pathlib.Path(args.cache), ext)
        print(
            f"{name}: mean ΔE2000 {row['mean']:.2f}, p95 {row['p95']:.2f}, ours/Cycles {row['ratio']}, "
            f"Cycles {row['cycles_s']:.0f} s; {row['messages']}"
        )
        rows.append(row)
        _picture(row, DOCS / "images" / f"scene-lights-{name}.png")
    timing = [] if args.no_timing else time_lights(ext)
    for t in timing:
        print(f"{t['lights']} {t['kind']} lights: {t['ms']:.1f} ms")
    area = None if args.no_area else area_accuracy()
    write_report(rows, timing, args.size, args.samples, pathlib.Path(args.report), area)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
