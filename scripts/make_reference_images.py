"""Regenerate the sample scenes' reference images, README pictures and docs/sample-scenes.md.

    .venv/bin/python scripts/make_reference_images.py                # everything
    .venv/bin/python scripts/make_reference_images.py --only-references   # just tests/data/reference
    .venv/bin/python scripts/make_reference_images.py --scenes soap_bubble oil_slick

Builds every scene of ``sample_scenes/make_scenes.py`` in a temporary folder, then writes

- ``tests/data/reference/<scene>.png``: the headless render at 96×72 (8-bit sRGB, "Standard"
  view), what ``tests/headless/test_sample_scenes.py`` compares against;
- ``docs/images/<scene>.png``: the headless render at 320×240;
- ``docs/images/<scene>_cycles.png``: Cycles (CPU, 128 samples, no denoising) of the same file at
  320×240: the Principled scene as it is, the extension's single-film materials after
  ``addon.materials.principled.write_back_to_principled`` (a varying thickness written as nodes); a
  multilayer has no Cycles equivalent (Cycles has one film);
- ``docs/sample-scenes.md``: the pictures side by side and the commands.

The helpers (:func:`headless_render`, :func:`cycles_render`, :func:`object_mask`) are also used
by the tests. Run it after a change that alters the pictures on purpose, and look at them.
"""

from __future__ import annotations

import argparse
import importlib.util
import io
import pathlib
import sys
import tempfile
import time

import numpy as np

REPO = pathlib.Path(__file__).resolve().parent.parent
REFERENCE_DIR = REPO / "tests" / "data" / "reference"
DOCS_IMAGES = REPO / "docs" / "images"
DOCS_PAGE = REPO / "docs" / "sample-scenes.md"
EXTENSION_ID = "thinfilm_sh"

#: Size of the test references (small: they are stored in git) and of the README pictures.
REFERENCE_SIZE = (96, 72)
DOCS_SIZE = (320, 240)
CYCLES_SAMPLES = 128
#: The Principled scene against Cycles (the test's settings): size, samples, roughnesses. At
#: 128 samples Cycles' own noise adds ≈ 0.4 to the mean ΔE2000; 512 keeps it to ≈ 0.1.
COMPARE_SIZE = (96, 72)
COMPARE_SAMPLES = 512
COMPARE_ROUGHNESS = (0.5, 0.15)
#: docs/images files must stay below this (bytes).
DOCS_IMAGE_LIMIT = 150 * 1024

REGENERATE = ".venv/bin/python scripts/make_reference_images.py"


def _load(name: str, path: pathlib.Path):
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def make_scenes_module():
    """``sample_scenes/make_scenes.py`` as a module."""
    return _load("thinfilm_sh_make_scenes", REPO / "sample_scenes" / "make_scenes.py")


def headless_script():
    """``scripts/thinfilm_headless.py`` as a module."""
    return _load("thinfilm_sh_headless_script", REPO / "scripts" / "thinfilm_headless.py")


def extension():
    """The registered extension package (registers it from this repository if needed)."""
    return headless_script().register_extension()


def addon_module(dotted: str):
    """The extension's module ``dotted`` ("addon.headless.headless"), the extension registered first."""
    extension()
    return importlib.import_module(f"{EXTENSION_ID}.{dotted}")


# ----------------------------------------------------------------------------------------------
# Images
# ----------------------------------------------------------------------------------------------
def read_exr(path, channels="RGB") -> np.ndarray:
    """An EXR written by us (one "RGB" channel) or by Blender (R, G, B[, A] or a multilayer)."""
    import OpenEXR

    with OpenEXR.File(str(path)) as f:
        found = f.channels()
        for key in (channels, "RGBA", "RGB"):
            if key in found:
                pixels = np.array(found[key].pixels, dtype=np.float64)
                return pixels[..., : len(channels)]
        return np.stack([np.array(found[c].pixels, dtype=np.float64) for c in channels], axis=-1)


def srgb8(linear, exposure: float = 0.0) -> np.ndarray:
    """8-bit sRGB of scene-linear RGB ("Standard" view), as the headless PNG."""
    from precompute.output.image_io import srgb_encode

    return np.clip(np.rint(srgb_encode(linear, exposure) * 255.0), 0, 255).astype(np.uint8)


def save_png(path, rgb8: np.ndarray) -> int:
    """Write an 8-bit RGB PNG as small as Pillow makes it; returns its size in bytes."""
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(rgb8), "RGB").save(buf, format="PNG", optimize=True)
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(buf.getvalue())
    return len(buf.getvalue())


def read_png(path) -> np.ndarray:
    """An 8-bit RGB PNG as a (H, W, 3) uint8 array."""
    from PIL import Image

    with Image.open(path) as im:
        return np.asarray(im.convert("RGB"), dtype=np.uint8)


def object_mask(alpha, erode: int = 1) -> np.ndarray:
    """Pixels fully covered by objects (alpha ≈ 1), minus ``erode`` pixels of border."""
    m = np.asarray(alpha) > 0.999
    for _ in range(erode):
        inner = m.copy()
        inner[1:-1, 1:-1] &= m[:-2, 1:-1] & m[2:, 1:-1] & m[1:-1, :-2] & m[1:-1, 2:]
        inner[0, :] = inner[-1, :] = inner[:, 0] = inner[:, -1] = False
        m = inner
    return m


# ----------------------------------------------------------------------------------------------
# Renders
# ----------------------------------------------------------------------------------------------
def open_blend(path) -> None:
    import bpy

    extension()
    bpy.ops.wm.open_mainfile(filepath=str(pathlib.Path(path).resolve()))


def headless_render(out_png, size, background: bool = True) -> tuple[np.ndarray, dict]:
    """The open file's camera view with the thin-film shader (PNG + EXR); (linear RGB, result)."""
    import bpy

    result = addon_module("addon.headless.render").render_scene(
        bpy.context.scene, str(out_png), size[0], size[1], background=background
    )
    return read_exr(result["exr"]), result


def cycles_render(out_exr, size, samples: int = CYCLES_SAMPLES, transparent: bool = False) -> np.ndarray:
    """Cycles (CPU, no denoising, fixed seed) of the open file's scene; scene-linear RGBA.

    With ``transparent`` the World is left out of the picture (it still lights the scene), so
    alpha is the objects' coverage: the mask of the pixels to compare.
    """
    import bpy

    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    cycles = scene.cycles
    cycles.device = "CPU"
    cycles.samples = int(samples)
    cycles.use_adaptive_sampling = False
    cycles.use_denoising = False
    cycles.seed = 1
    scene.render.resolution_x, scene.render.resolution_y = size
    scene.render.resolution_percentage = 100
    # The file's own Cycles pixel filter (Blackman–Harris 1.5 px by default): the headless frame
    # applies the same one to its 4× supersampled frame (addon/headless/render.py).
    scene.render.film_transparent = transparent
    scene.render.use_compositing = False
    scene.render.use_sequencer = False
    settings = scene.render.image_settings
    settings.media_type = "IMAGE"
    settings.file_format = "OPEN_EXR"
    settings.color_mode = "RGBA"
    settings.color_depth = "32"
    scene.render.filepath = str(out_exr)
    bpy.ops.render.render(write_still=True)
    return read_exr(out_exr, "RGBA")


def delta_e_vs_cycles(workdir, size=COMPARE_SIZE, samples=COMPARE_SAMPLES, label="") -> tuple[float, float]:
    """Mean and 95th-percentile ΔE2000 between the headless render and Cycles of the open file.

    Over the pixels Cycles shows fully covered by objects (alpha of a transparent-film render),
    one pixel of silhouette eroded; both at a common exposure (reference p95 luminance 0.8).
    """
    from precompute.colour.colour_difference import delta_e_2000

    workdir = pathlib.Path(workdir)
    ours, _ = headless_render(workdir / f"ours{label}.png", size, background=False)
    cycles = cycles_render(workdir / f"cycles{label}.exr", size, samples, transparent=True)
    mask = object_mask(cycles[..., 3], erode=1)
    if not mask.any():
        raise ValueError("no object pixels to compare")
    de = delta_e_2000(ours[mask], cycles[mask][:, :3], xyz="E")
    return float(np.mean(de)), float(np.percentile(de, 95))


def principled_vs_cycles(blend, workdir, roughnesses=COMPARE_ROUGHNESS) -> dict[float, tuple[float, float]]:
    """{roughness: (mean, p95) ΔE2000} of the Principled scene at each roughness."""
    import bpy

    open_blend(blend)
    bsdf = next(
        n
        for m in bpy.data.materials
        if m.node_tree is not None
        for n in m.node_tree.nodes
        if n.bl_idname == "ShaderNodeBsdfPrincipled" and n.inputs["Thin Film Thickness"].default_value > 0
    )
    out = {}
    for roughness in roughnesses:
        bsdf.inputs["Roughness"].default_value = roughness
        out[roughness] = delta_e_vs_cycles(workdir, label=f"_r{roughness:g}")
    return out


def film_materials(bpy):
    """Materials of the open file that the extension previews from its own settings."""
    return [
        m for m in bpy.data.materials if getattr(m, "thinfilm_sh", None) is not None and m.thinfilm_sh.enabled
    ]


def cycles_equivalent() -> tuple[bool, list[str]]:
    """Prepare the open file for Cycles: (possible?, notes). Single films are written back."""
    import bpy

    principled = addon_module("addon.materials.principled")
    notes = []
    for mat in film_materials(bpy):
        if len(mat.thinfilm_sh.layers) > 1:
            return False, [f"'{mat.name}' has {len(mat.thinfilm_sh.layers)} layers; Cycles has one film"]
        notes += [f"{mat.name}: {n}" for n in principled.write_back_to_principled(mat)]
    return True, notes


# ----------------------------------------------------------------------------------------------
# The page
# ----------------------------------------------------------------------------------------------
DESCRIPTIONS = {
    "soap_bubble": "`soap_film` preset on a sphere, thickness 0–1000 nm from 3-D noise, HDRI *studio*",
    "oil_slick": "`oil_on_water` preset on a water plane, thickness 100–800 nm from the mesh attribute "
    "`thickness`, HDRI *sunset*",
    "coated_car_window": "`coated_car_window` preset (MgF₂ on glass) on a curved panel, "
    "100–300 nm from noise, HDRI *city*",
    "anodised_titanium": "`anodised_titanium` preset on a capsule, oxide 20–150 nm from the "
    "attribute `oxide` (a gradient along it), HDRI *interior*",
    "beetle_shell": "`beetle_multilayer` preset (16 chitin layers) on a half-ellipsoid, HDRI *forest*",
    "principled_film": "no extension settings: Principled BSDF, Thin Film 500 nm / IOR 1.33, IOR 1.5, "
    "Roughness 0.5, Base Color black, HDRI *courtyard*",
}


PAGE_HEAD = """\
# Sample scenes

`sample_scenes/make_scenes.py` builds one small .blend per preset (plus a Principled thin film
for Cycles interop), each with a camera, a World lit by one of Blender's studio-light HDRIs and,
where it makes sense, a ground plane. Left: the extension's headless render (the viewport
shader drawn off-screen over Blender's Solid drawing of the other objects, with the World as
background); right: Cycles of the same file. The extension's materials are rendered by Cycles
after *Write to Principled* (`addon.materials.principled.write_back_to_principled`): a varying
thickness is written as nodes (the preview's value noise as Blender's Noise Texture, the same
range in another pattern), a transparent film as *Transmission* 1 with a white *Base Color*
(Cycles tints what passes through by it), and a 16-layer stack has no Cycles equivalent (Cycles
has a single film). The headless pictures draw a transparent film over what lies behind it (the
soap bubble, the window); the ground is Blender's flat Solid grey rather than a shaded surface
(`render --engine EEVEE` renders the rest of the scene with EEVEE instead).

| Scene | Thin Film SH (headless) | Cycles | |
|---|---|---|---|
"""

PAGE_TAIL = """\

Pictures are 320×240: headless renders on Mesa llvmpipe (4×4 samples per pixel, filtered with
the file's Cycles pixel filter, docs/headless.md), Cycles on the CPU with {samples} samples and
no denoising. Seconds at the last regeneration (two CPU cores, shared): the first
headless render of a file (96×72, the test reference) includes the World's panorama (a small
Cycles render, kept while the World does not change), reading or baking the tables and
compiling shaders; the 320×240 picture that follows reuses them.

| Scene | headless, first (96×72) | headless 320×240 | Cycles 320×240 |
|---|---|---|---|
{timings}

## Principled scene vs Cycles

The `principled_film` file rendered both ways at {cmp_w}×{cmp_h} (Cycles {cmp_spp} samples), mean
(95th percentile) ΔE2000 over the sphere, one pixel of silhouette left out, at a common exposure
(`precompute.colour.colour_difference.delta_e_2000`):

| Roughness | mean ΔE2000 | p95 |
|---|---|---|
{delta_e}

`tests/headless/test_sample_scenes.py` asserts a mean ≤ 3 at the file's roughness 0.5; 0.15 is reported
only. With SH order ≤ 8 most of the error was in the outer ring of the sphere (grazing views)
and the interior agreed to about ΔE 1.2–1.5.

## Commands

Build the scenes into `sample_scenes/out/` (git ignores it; `--out DIR` puts them elsewhere and
`--hdri-dir DIR` names another folder of `<name>.exr` HDRIs):

```sh
.venv/bin/python sample_scenes/make_scenes.py --out sample_scenes/out
# or inside Blender:
blender -b -P sample_scenes/make_scenes.py -- --out sample_scenes/out
```

Render, bake or plan one file, or render a whole folder, with the bpy module:

```sh
S=sample_scenes/out
.venv/bin/python scripts/thinfilm_headless.py $S/soap_bubble.blend render --out out/bubble.png
.venv/bin/python scripts/thinfilm_headless.py $S/soap_bubble.blend bake --json out/bake.json
.venv/bin/python scripts/thinfilm_headless.py $S/soap_bubble.blend plan
.venv/bin/python scripts/thinfilm_headless.py --all-scenes $S --out-dir out/renders
```

The same commands in Blender, with the extension installed:

```sh
blender -b sample_scenes/out/soap_bubble.blend -c thinfilm_sh render --out out/bubble.png
```

Regenerate these pictures, this page and the test references (`tests/data/reference/*.png`,
96×72):

```sh
{regenerate}
```

`tests/headless/test_sample_scenes.py` renders every scene at 96×72 and compares it with its reference:
mean absolute difference ≤ 2/255 and 99th percentile ≤ 12/255 (llvmpipe and other GPUs round
differently, mostly on silhouettes).
"""


def write_page(rows: list[dict], delta_e: dict) -> None:
    table = []
    for row in rows:
        name = row["name"]
        ours = f"![{name}](images/{name}.png)"
        cycles = f"![{name} in Cycles](images/{name}_cycles.png)" if row["cycles"] else "no Cycles equivalent"
        table.append(f"| `{name}` | {ours} | {cycles} | {DESCRIPTIONS.get(name, '')} |")
    timings = []
    for row in rows:
        cycles_s = f"{row['cycles_s']:.1f}" if row["cycles"] else "–"
        timings.append(f"| `{row['name']}` | {row['first_s']:.1f} | {row['headless_s']:.1f} | {cycles_s} |")
    tail = PAGE_TAIL.format(
        samples=CYCLES_SAMPLES,
        timings="\n".join(timings),
        cmp_w=COMPARE_SIZE[0],
        cmp_h=COMPARE_SIZE[1],
        cmp_spp=COMPARE_SAMPLES,
        delta_e="\n".join(f"| {r:g} | {m:.2f} | {p:.2f} |" for r, (m, p) in delta_e.items()),
        regenerate=REGENERATE,
    )
    DOCS_PAGE.write_text(PAGE_HEAD + "\n".join(table) + "\n" + tail, encoding="utf-8")


# ----------------------------------------------------------------------------------------------
def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="+", help="only these scenes (default: all)")
    parser.add_argument("--only-references", action="store_true", help="skip docs/ (no Cycles renders)")
    parser.add_argument("--hdri-dir", help="passed to make_scenes.py")
    args = parser.parse_args(argv)

    make_scenes = make_scenes_module()
    names = args.scenes or list(make_scenes.SCENE_NAMES)
    extension()
    rows = []
    with tempfile.TemporaryDirectory(prefix="thinfilm_sh_refs_") as tmp:
        tmp = pathlib.Path(tmp)
        paths = make_scenes.make_scenes(tmp / "scenes", args.hdri_dir, names)
        for name, blend in paths.items():
            row = {"name": name, "cycles": False}
            open_blend(blend)
            t0 = time.perf_counter()
            _, result = headless_render(tmp / f"{name}_ref.png", REFERENCE_SIZE)
            row["first_s"] = time.perf_counter() - t0
            REFERENCE_DIR.mkdir(parents=True, exist_ok=True)
            (REFERENCE_DIR / f"{name}.png").write_bytes(pathlib.Path(result["png"]).read_bytes())
            for msg in result["messages"]:
                print(f"  note: {msg}")
            print(f"{name}: reference {REFERENCE_DIR / (name + '.png')}")
            if args.only_references:
                continue
            t0 = time.perf_counter()
            _, result = headless_render(tmp / f"{name}_docs.png", DOCS_SIZE)
            row["headless_s"] = time.perf_counter() - t0
            size = save_png(DOCS_IMAGES / f"{name}.png", read_png(result["png"]))
            print(f"{name}: docs/images/{name}.png ({size // 1024} KB, {row['headless_s']:.1f} s)")
            possible, notes = cycles_equivalent()
            for note in notes:
                print(f"  write-back: {note}")
            if possible:
                import bpy

                exposure = float(bpy.context.scene.view_settings.exposure)
                t0 = time.perf_counter()
                rgba = cycles_render(tmp / f"{name}_cycles.exr", DOCS_SIZE)
                row["cycles_s"] = time.perf_counter() - t0
                row["cycles"] = True
                size = save_png(DOCS_IMAGES / f"{name}_cycles.png", srgb8(rgba[..., :3], exposure))
                print(f"{name}: docs/images/{name}_cycles.png ({size // 1024} KB, {row['cycles_s']:.1f} s)")
            else:
                stale = DOCS_IMAGES / f"{name}_cycles.png"
                stale.unlink(missing_ok=True)
                print(f"{name}: no Cycles equivalent ({'; '.join(notes)})")
            rows.append(row)
        if not args.only_references and not args.scenes:
            delta_e = principled_vs_cycles(paths["principled_film"], tmp)
            for roughness, (mean, p95) in delta_e.items():
                print(
                    f"principled_film vs Cycles, roughness {roughness:g}: ΔE2000 {mean:.2f} (p95 {p95:.2f})"
                )
            write_page(rows, delta_e)
            print(f"wrote {DOCS_PAGE}")
    if not args.only_references and rows:
        if args.scenes:
            print("docs/sample-scenes.md not rewritten (only some scenes were rendered)")
        too_big = [p.name for p in DOCS_IMAGES.glob("*.png") if p.stat().st_size > DOCS_IMAGE_LIMIT]
        if too_big:
            print(f"error: docs images over {DOCS_IMAGE_LIMIT // 1024} KB: {too_big}", file=sys.stderr)
            return 1
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(REPO))  # precompute as a top-level package
    exit_code = main()
    headless_script().release()  # free the extension while Blender is alive (no crash at exit)
    sys.exit(exit_code)
