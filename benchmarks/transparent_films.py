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
HDRI = "studio"
#: Issue 17's acceptance (mean ΔE2000 over the object, Cycles-matching mode).
LIMITS = {"bubble": 3.0, "glass": 5.0}
#: 2: Cycles' sample clamps off (Blender's default indirect clamp of 10 dimmed the glass sphere's
#: internal glints 30×: 0.3–0.5 instead of 10–15, a biased reference).
SCENE_VERSION = 2


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


def build(name: str, path, size: int, samples: int, unbiased: bool = True):
    """The scene ``name`` ("bubble" or "glass") saved as a .blend; returns its path.
    ``unbiased``: Cycles' sample clamps off (the reference); else Blender's defaults (the
    headless frame's Cycles background pass, less noisy)."""
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
    mat = bpy.data.materials["film"]
    (_bubble if name == "bubble" else _glass)(mat.node_tree.nodes["Principled BSDF"], mat.node_tree)
    if name == "glass":
        _ground(bpy)
    bpy.ops.wm.save_as_mainfile(filepath=str(pathlib.Path(path).resolve()), check_existing=False)
    return path


def cycles_image(blend, name: str, size: int, samples: int) -> tuple[np.ndarray, float]:
    """Cycles' render of ``blend``, cached: (RGB, seconds; 0 if cached)."""
    import bpy

    key = json.dumps([name, size, samples, bpy.app.version_string, SCENE_VERSION])
    path = CACHE / f"{name}_{hashlib.sha256(key.encode()).hexdigest()[:12]}.npz"
    if path.is_file():
        return np.load(path)["rgb"], 0.0
    t0 = time.perf_counter()
    rgb = cc.cycles_render_blend(blend)
    seconds = time.perf_counter() - t0
    CACHE.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, rgb=rgb)
    return rgb, seconds


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
    name: str, workdir, size: int, samples: int, engine: str = "EEVEE", background_samples: int = 256
) -> dict:
    """ΔE2000 of one scene over the sphere's pixels; ``engine`` renders the rest of the scene
    (Cycles at ``background_samples``)."""
    blend = build(name, pathlib.Path(workdir) / f"{name}.blend", size, samples)
    ref, cycles_s = cycles_image(blend, name, size, samples)
    if engine == "CYCLES":
        blend = build(name, pathlib.Path(workdir) / f"{name}_ours.blend", size, background_samples, False)
    ours, ours_s = headless_image(blend, pathlib.Path(workdir) / f"{name}.png", engine)
    mask = cc.object_mask(render.sphere_view(size, size, cc.DISTANCE, cc.FOV_DEG))
    de = delta_e_2000(ours[mask], ref[mask], xyz="E")
    full = np.zeros(mask.shape)
    full[mask] = de
    return dict(
        name=name,
        engine=engine if engine != "CYCLES" else f"Cycles {background_samples} spp",
        mean=float(np.mean(de)),
        p95=float(np.percentile(de, 95)),
        cycles_s=cycles_s,
        ours_s=ours_s,
        ours=ours,
        cycles=ref,
        delta_e=full,
    )


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
of the scene (`render --engine`, default EEVEE). Under this studio HDRI (a lamp of 616 in a
panorama of mean 0.55) EEVEE lights the checker ground 2–5× brighter than Cycles (its orange
squares: EEVEE 1.78/0.74/0.42, Cycles 0.38/0.19/0.13, the HDRI's irradiance from above times
their albedo / π 0.33/0.12/0.05; EEVEE's sun extraction off still doubles Cycles), so the glass sphere,
which now shows that ground refracted, is measured over a **Cycles background pass**
(`--engine CYCLES --background-samples 128`): the comparison is of the films, not of EEVEE's
lighting. The bubble's background is the HDRI alone, the same in every engine.

**The glass sphere** refracts the background pass in screen space (the sphere about its origin,
the exit ray marched over the pass's depth, overscanned on each side), adds one internal
reflection (the lamps' glints) and mirrors the ground in its lower half
(docs/transparent-films.md#solid-glass-refraction).

**Unclamped Cycles.** Blender's default indirect clamp (10 per sample) dimmed the ball's glints
30× in the first references (0.3–0.5 where the unclamped render shows 10–15: a reflection
chosen with probability F ≈ 0.03 carries 1/F of the lamp's 400 and is clamped), so the references
are rendered with the clamps off (`SCENE_VERSION` 2); the background pass keeps Blender's
defaults (less noise). What remains: Cycles' glints are cyan where ours are tinted by the film's
reflectance r (pink): at a back face Cycles divides the film's index by the glass's
(`adjust_thin_film_ior_at_backface`) at the same wavelengths, an optically thinner film
(r ≈ 0.03/0.04/0.04 by our evaluation of that configuration), while a lossless film reflects the
same from both sides; rays bent out of the overscanned picture at the rim see the World instead
of the ground; Cycles' caustics on the ground under the ball are not in the pass.

*Cycles s* is 0 for a cached render: the 1024-spp ones took 876 s (glass) and 353 s (bubble) on
this machine at a load average of 6–8.
"""


def report(rows, size: int, samples: int, picture: str = "transparent_films.png", command: str = "") -> str:
    """The markdown report."""
    lines = [
        "# Transparent films against Cycles",
        "",
        "Generated by `.venv/bin/python -m benchmarks.transparent_films"
        f"{command or f' --size {size} --samples {samples}'}` (benchmarks/transparent_films.py).",
        "",
        f"Scenes: {size}×{size}, Cycles {samples} spp (CPU, no denoising, 16 bounces, no sample clamping),"
        " studio HDRI.",
        f"Machine: {'; '.join(common.machine_lines())}. Load average: {common.load_average()}.",
        f"Code: {common.git_describe(('precompute', 'addon', 'glsl', 'benchmarks'))}.",
        "",
        "| scene | background pass | mean ΔE2000 | p95 | limit | Cycles s | ours s |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['name']} | {r['engine']} | {r['mean']:.2f} | {r['p95']:.2f} | {LIMITS[r['name']]:.0f} | "
            f"{r['cycles_s']:.0f} | {r['ours_s']:.1f} |"
        )
    lines += ["", NOTES, f"![ours | Cycles | ΔE/10, one row per scene](images/{picture})", ""]
    return "\n".join(lines)


def main(argv=None) -> int:
    """Build, render and compare the two scenes; write the report and picture."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=SIZE)
    parser.add_argument("--samples", type=int, default=SAMPLES)
    parser.add_argument("--scenes", nargs="+", default=list(LIMITS))
    parser.add_argument(
        "--engine",
        default="EEVEE",
        choices=("EEVEE", "CYCLES", "WORKBENCH"),
        help="the engine of the headless frame's background pass (render --engine)",
    )
    parser.add_argument("--background-samples", type=int, default=256, help="with --engine CYCLES")
    parser.add_argument("--out", default="transparent-films-cycles.md")
    parser.add_argument("--picture", default="transparent_films.png", help="under docs/images/")
    args = parser.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.scenes:
            row = compare(
                name, pathlib.Path(tmp), args.size, args.samples, args.engine, args.background_samples
            )
            print(f"{name}: mean ΔE2000 {row['mean']:.2f}, p95 {row['p95']:.2f}", flush=True)
            rows.append(row)
    write_picture(rows, pathlib.Path(common.ROOT) / "docs" / "images" / args.picture)
    command = " " + " ".join(sys.argv[1:] if argv is None else argv)
    print(common.write_doc(args.out, report(rows, args.size, args.samples, args.picture, command)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
