"""The headless render against Cycles: Principled thin-film spheres under bpy's studio HDRIs.

For each case a .blend is built by script (tests/_cycles_scenes.py ``build_sphere_blend``: a
Principled BSDF sphere with Thin Film Thickness / IOR, IOR and Roughness, a studio HDRI as the
World, a camera; Base Color black, so only the film shows). Cycles renders the file as it is
(CPU, no denoising, the default Blackman–Harris 1.5 px pixel filter), and the extension's
headless command renders the same file in-process (``thinfilm_headless.py FILE render``: the
draw collection, bake, lamps, prefilter and GLSL shader of the add-on, anti-aliased with the
scene's pixel filter). ΔE2000 between the two EXRs over the sphere, one pixel of silhouette left
out (``precompute.colour.colour_difference.delta_e_2000``, route "E").

Cycles' renders are cached in ``benchmarks/.cache/cycles_compare/`` by the case, size, sample
count and Blender version, so a rerun renders only the headless frames.

Run: ``.venv/bin/python -m benchmarks.cycles_compare [--quick]`` → ``docs/cycles-comparison.md``;
``--case N`` (repeatable) runs only those cases, ``--out NAME`` writes the report elsewhere.
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
from precompute.colour.colour_difference import delta_e_2000, exposure_scale
from precompute.output import image_io, render

sys.path.insert(0, str(pathlib.Path(common.ROOT) / "tests"))
sys.path.insert(0, str(pathlib.Path(common.ROOT) / "scripts"))

import _cycles_scenes as cc  # noqa: E402

CACHE = pathlib.Path(common.ROOT) / "benchmarks" / ".cache" / "cycles_compare"
#: Issue 22's acceptance: every case ≤ 1.5 mean ΔE2000, the mean over cases ≤ 1.0.
CASE_LIMIT = 1.5
MEAN_LIMIT = 1.0
SIZE = 96
SAMPLES = 1024
#: The folders whose state the report names.
CODE_PATHS = ("precompute", "addon", "glsl", "benchmarks")

CASES = [
    # (hdri, thickness nm, film ior, base ior, roughness): thickness 1–2500, film IOR 1.33–2.0,
    # base IOR 1.0 and 1.5, roughness 0.05–0.6, several of bpy's studio lights. The headless
    # command previews no film of 0 nm (the bare Principled BSDF, which Blender draws itself), so
    # the nearly bare case is 1 nm: the thinnest film Cycles takes at its full index.
    ("studio", 500.0, 1.33, 1.0, 0.05),
    ("courtyard", 250.0, 1.5, 1.5, 0.05),
    ("studio", 500.0, 1.33, 1.0, 0.15),
    ("courtyard", 300.0, 1.5, 1.5, 0.15),
    ("sunset", 2500.0, 1.33, 1.0, 0.15),
    ("courtyard", 800.0, 1.33, 1.5, 0.3),
    ("forest", 400.0, 2.0, 1.5, 0.3),
    ("courtyard", 800.0, 1.33, 1.5, 0.5),
    ("forest", 1.0, 1.33, 1.5, 0.5),  # nearly bare: a 0 nm film is not previewed (Blender draws it)
    ("studio", 400.0, 2.0, 1.5, 0.6),
    ("sunset", 2500.0, 1.33, 1.0, 0.6),
]


def _blender_version() -> str:
    import bpy

    return bpy.app.version_string


def _key(case, size: int, samples: int) -> str:
    text = json.dumps(
        {
            "case": case,
            "size": size,
            "spp": samples,
            "blender": _blender_version(),
            "scene": cc.SPHERE_SCENE_VERSION,
        },
        sort_keys=True,
    )
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def cycles_image(blend, case, size: int, samples: int) -> tuple[np.ndarray, float]:
    """Cycles' render of ``blend`` (cached by the case's parameters): (RGB, seconds; 0 if cached)."""
    path = CACHE / f"{_key(case, size, samples)}.npz"
    if path.is_file():
        return np.load(path)["rgb"], 0.0
    t0 = time.perf_counter()
    rgb = cc.cycles_render_blend(blend)
    seconds = time.perf_counter() - t0
    CACHE.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, rgb=rgb)
    return rgb, seconds


def headless_image(blend, out_png) -> tuple[np.ndarray, float, list]:
    """The extension's headless command on ``blend``, in-process: (RGB of its EXR, seconds, notes)."""
    import thinfilm_headless  # scripts/: registers this repository as the extension

    t0 = time.perf_counter()
    code = thinfilm_headless.run_file(str(blend), ["render", "--out", str(out_png)])
    seconds = time.perf_counter() - t0
    if code != 0:
        raise RuntimeError(f"headless render of {blend} failed with exit code {code}")
    return cc.read_exr(pathlib.Path(out_png).with_suffix(".exr")), seconds


def compare_case(case, workdir, size: int, samples: int) -> dict:
    hdri_name, thickness_nm, film_ior, base_ior, roughness = case
    blend = cc.build_sphere_blend(
        workdir / f"case_{len(list(workdir.glob('*.blend')))}.blend",
        cc.studiolight_path(hdri_name),
        thickness_nm,
        film_ior,
        base_ior,
        roughness,
        size=size,
        samples=samples,
    )
    ref, cycles_s = cycles_image(blend, case, size, samples)
    ours, ours_s = headless_image(blend, workdir / "ours.png")
    mask = cc.object_mask(render.sphere_view(size, size, cc.DISTANCE, cc.FOV_DEG))
    de = delta_e_2000(ours[mask], ref[mask], xyz="E")
    return {
        "case": case,
        "mean": float(np.mean(de)),
        "p95": float(np.percentile(de, 95)),
        "cycles_s": cycles_s,
        "ours_s": ours_s,
        "cycles": ref,
        "ours": ours,
    }


def write_picture(rows, path, size: int) -> None:
    """One row per case: Cycles | ours (headless) | ΔE2000 map (white = 10), at the comparison's exposure."""
    mask = cc.object_mask(render.sphere_view(size, size, cc.DISTANCE, cc.FOV_DEG))
    strips = []
    for r in rows:
        ref, ours = r["cycles"], r["ours"]
        scale = exposure_scale(ref[mask], xyz="E")
        de = np.zeros(mask.shape)
        de[mask] = delta_e_2000(ours[mask], ref[mask], scale=scale, xyz="E")
        grey = np.repeat(np.clip(de / 10.0, 0.0, 1.0)[..., None], 3, axis=-1)
        strips.append(
            np.concatenate(
                [image_io.srgb_encode(ref * scale), image_io.srgb_encode(ours * scale), grey], axis=1
            )
        )
    path.parent.mkdir(parents=True, exist_ok=True)
    picture = np.concatenate(strips, axis=0)
    try:  # Pillow's optimised PNG (docs/images keeps each file under 150 KB)
        from PIL import Image

        rgb8 = np.clip(np.rint(picture * 255.0), 0, 255).astype(np.uint8)
        Image.fromarray(np.ascontiguousarray(rgb8), "RGB").save(path, format="PNG", optimize=True)
    except ImportError:
        image_io.write_png(path, picture)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="three cases, 64 px, 128 samples")
    parser.add_argument("--out", default="cycles-comparison.md")
    parser.add_argument(
        "--case",
        type=int,
        action="append",
        help="run only this case (index into CASES, from 0; repeatable); the report goes to --out "
        "without pictures, so pass a scratch name",
    )
    args = parser.parse_args(argv)
    cases = CASES[2::4] if args.quick else CASES
    if args.case:
        cases = [CASES[i] for i in args.case]
    size, samples = (64, 128) if args.quick else (SIZE, SAMPLES)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="thinfilm_cycles_compare_") as tmp:
        rows = [compare_case(c, pathlib.Path(tmp), size, samples) for c in cases]
    means = [r["mean"] for r in rows]
    overall = float(np.mean(means))
    met = all(m <= CASE_LIMIT for m in means) and overall <= MEAN_LIMIT
    cached = sum(r["cycles_s"] == 0.0 for r in rows)
    lines = [
        "# The headless render against Cycles (Principled thin film)",
        "",
        "Generated by `.venv/bin/python -m benchmarks.cycles_compare` "
        f"({'quick; ' if args.quick else ''}{common.git_describe(CODE_PATHS)},",
        f"Blender {_blender_version()}, {time.perf_counter() - t0:.0f} s; {cached} of {len(rows)} Cycles "
        "renders from the cache).",
        "",
        *common.machine_lines(),
        "",
        f"A {size}×{size} sphere with a Principled BSDF thin film (Base Color black: the film alone) under",
        "one of bpy's studio HDRIs, pinhole camera, built as a .blend by script",
        "(tests/_cycles_scenes.py `build_sphere_blend`). **Cycles**: that file as it is, CPU,",
        f"{samples} samples, no denoising, its default Blackman–Harris 1.5 px pixel filter. **Ours**: the",
        "extension's headless command on the same file, in-process (`scripts/thinfilm_headless.py FILE",
        "render`): the add-on's draw collection, table bake, World lamps, prefilter and GLSL shader on",
        "Mesa llvmpipe, drawn 4× larger and filtered with the scene's pixel filter "
        "(addon/headless/render.py).",
        "The Principled film is previewed in the Cycles-matching colour mode (Cycles' film pipeline,",
        "docs/white-furnace.md). ΔE2000 between the two EXRs over the sphere, one pixel of silhouette",
        "left out, at a common exposure (the reference's p95 luminance at 0.8). Cycles' own noise at",
        "1024 samples is ≈ 0.2–0.3 mean ΔE2000 (half its noise at 256).",
        "",
        f"Acceptance (issue 22): every case ≤ {CASE_LIMIT:g} mean ΔE2000 and the mean over cases ≤ "
        f"{MEAN_LIMIT:g}: **{'met' if met else 'not met'}** (mean **{overall:.2f}**, worst "
        f"{max(means):.2f}).",
        "",
        "| HDRI | thickness nm | film IOR | base IOR | roughness | **mean ΔE2000** | p95 | headless s | "
        "Cycles s |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        h, d, nf, nb, rough = r["case"]
        cyc = f"{r['cycles_s']:.0f}" if r["cycles_s"] else "cached"
        lines.append(
            f"| {h} | {d:g} | {nf:g} | {nb:g} | {rough:g} | **{r['mean']:.2f}** | {r['p95']:.1f} | "
            f"{r['ours_s']:.0f} | {cyc} |"
        )
    lines.append(f"| **mean** | | | | | **{overall:.2f}** | | | |")
    if not args.quick and not args.case:
        lines += [
            "",
            "Per case (rows in table order), left to right: Cycles, the headless frame, ΔE2000 (white = 10).",
        ]
        for group, keep in (("glossy", lambda r: r <= 0.15), ("rough", lambda r: r > 0.15)):
            chosen = [r for r in rows if keep(r["case"][4])]
            picture = pathlib.Path(common.ROOT) / "docs" / "images" / f"cycles-comparison-{group}.png"
            write_picture(chosen, picture, size)
            lines += ["", f"![Cycles, the headless frame and ΔE2000, {group} cases](images/{picture.name})"]
    path = common.write_doc(args.out, "\n".join(lines))
    print("\n".join(lines))
    print(f"wrote {path}")
    return 0 if met else 1


if __name__ == "__main__":
    raise SystemExit(main())
