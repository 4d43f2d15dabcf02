"""What Cycles' *Filter Glossy* adds to rough solid glass under a studio HDRI: a study tool.

Builds the glass ball of benchmarks/transparent_films.py (a 300 nm film of 1.33 on glass of
1.5, roughness 0.05) without its ground, under the studio HDRI alone, and renders it with
Cycles (CPU, 16 bounces, clamps off) three ways: roughness 0.05 with Blender's default Filter
Glossy (1), the same with Filter Glossy 0, and roughness 0; then the headless frame over a
Cycles background pass. It prints the luminance down the ball's middle columns and the mean
ΔE2000 over the ball between the pictures.

Why: over the glass benchmark's lower half, where the paths through the ball leave towards the
World, the headless frame reads 3–4 % darker than Cycles. Cycles' Filter Glossy (kernel: a
closure is blurred to α = ½ √(1 − filter × min ray pdf) once an earlier bounce had a pdf
below 1 / filter) makes the exit of every path whose entry sampled GGX's far tail rough, and
those paths see the World's lamps blurred. The extension follows the paths as smooth glass
plus their lamps' tails (docs/transparent-films.md#rough-glass-tails), which is Cycles with
Filter Glossy 0.

    .venv/bin/python scripts/glass_filter_glossy.py [--size 128] [--samples 1024]
"""

from __future__ import annotations

import argparse
import pathlib
import sys
import tempfile

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT), str(ROOT / "tests"), str(ROOT / "scripts")]

import _cycles_scenes as cc  # noqa: E402

from benchmarks import transparent_films as tf  # noqa: E402
from precompute.colour.colour_difference import delta_e_2000  # noqa: E402
from precompute.output import render  # noqa: E402

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
#: Bands of the picture's rows (fractions of its height): the upper half, then the lower half's
#: three parts down to the ball's bottom.
BANDS = ((0.15, 0.47), (0.52, 0.63), (0.63, 0.75), (0.75, 0.88))


def build(
    path, size: int, samples: int, roughness: float, filter_glossy: float, seed: int = 1
) -> pathlib.Path:
    """The ball under the studio HDRI alone, Cycles' ``seed``, saved to ``path``."""
    import bpy

    hdri = cc.studiolight_path(tf.HDRI)
    cc.build_sphere_blend(path, hdri, 300.0, 1.33, 1.5, 0.0, size=size, samples=samples)
    scene = bpy.context.scene
    cycles = scene.cycles
    cycles.max_bounces = cycles.transmission_bounces = cycles.transparent_max_bounces = 16
    cycles.glossy_bounces = 16
    cycles.sample_clamp_direct = cycles.sample_clamp_indirect = 0.0
    cycles.blur_glossy = float(filter_glossy)
    cycles.seed = int(seed)
    bsdf = bpy.data.materials["film"].node_tree.nodes["Principled BSDF"]
    tf._glass(bsdf, None)
    bsdf.inputs["Roughness"].default_value = float(roughness)
    tf._shape(bpy, "glass")
    bpy.ops.wm.save_as_mainfile(filepath=str(pathlib.Path(path).resolve()), check_existing=False)
    return pathlib.Path(path)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=128)
    parser.add_argument("--samples", type=int, default=1024)
    args = parser.parse_args(argv)
    size = args.size
    pictures = {}
    with tempfile.TemporaryDirectory() as tmp:
        folder = pathlib.Path(tmp)
        for label, roughness, filter_glossy, seed in (
            ("Cycles, Filter Glossy 1", tf.GLASS_ROUGHNESS, 1.0, 1),
            ("Cycles, Filter Glossy 1, seed 2", tf.GLASS_ROUGHNESS, 1.0, 2),
            ("Cycles, Filter Glossy 0", tf.GLASS_ROUGHNESS, 0.0, 1),
            ("Cycles, roughness 0", 0.0, 1.0, 1),
        ):
            blend = build(
                folder / f"ball{len(pictures)}.blend", size, args.samples, roughness, filter_glossy, seed
            )
            pictures[label] = cc.cycles_render_blend(str(blend))
        blend = folder / "ball0.blend"  # the first: Filter Glossy 1, seed 1, as the references
        pictures["ours (Cycles pass)"] = tf.headless_image(blend, folder / "ours.png", "CYCLES")[0][..., :3]
    import thinfilm_headless

    thinfilm_headless.release()
    mask = cc.object_mask(render.sphere_view(size, size, cc.DISTANCE, cc.FOV_DEG))
    labels = list(pictures)
    # medians over bands of the ball's rows: robust against the rare bright samples (a lamp
    # seen through a blurred path) that make a few pixels' means noisy
    print("Median luminance over the ball's pixels, by band of rows:")
    print("| rows | " + " | ".join(labels) + " |")
    print("|---|" + "---|" * len(labels))
    for lo, hi in BANDS:
        rows = slice(round(lo * size), round(hi * size))
        band = np.zeros_like(mask)
        band[rows] = mask[rows]
        cells = [f"{float(np.median(pictures[k][band] @ LUMINANCE)):.4f}" for k in labels]
        print(f"| {rows.start}–{rows.stop - 1} | " + " | ".join(cells) + " |")
    print("\nMean ΔE2000 over the ball:")
    for i, a in enumerate(labels):
        for b in labels[i + 1 :]:
            de = float(np.mean(delta_e_2000(pictures[a][mask], pictures[b][mask], xyz="E")))
            print(f"- {a} against {b}: {de:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
