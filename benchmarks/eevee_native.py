"""EEVEE-native films against Cycles: Blender's own EEVEE final render, no command of ours.

Every case is a .blend built by script, the scenes of the accuracy benchmarks and the sample
scenes:

- **spheres**: the 11 Principled film spheres of ``benchmarks.cycles_compare`` (bpy's HDRIs,
  thickness 1–2500 nm, roughness 0.05–0.6);
- **lights**: the three light-object scenes of ``benchmarks.scene_lights`` (sun, point + area,
  spot on a metal);
- **texture**: the noise-driven thickness sphere of ``benchmarks.texture_thickness``;
- **transparent**: the thin-wall bubble and the coated glass sphere of
  ``benchmarks.transparent_films``;
- **scenes**: the sample scenes of ``sample_scenes/make_scenes.py`` (the extension's own materials
  written to their Principled BSDF for Cycles, as docs/sample-scenes.md does; the 16-layer beetle
  has no Cycles equivalent and is rendered but not scored).

For each: **Cycles** (CPU, no denoising, Blackman–Harris 1.5 px, cached in
``benchmarks/.cache/eevee_native/``), **EEVEE native** (the file opened with the extension
registered, which writes its films' EEVEE outputs at load, then ``bpy.ops.render.render`` with
EEVEE: what F12 and ``blender -b -a`` do) and, beside it, **the overlay** (the headless
``render`` command on the same file). Mean and 95th-percentile ΔE2000 over the film's pixels
(one pixel of silhouette left out) at the reference's exposure. Frame time: EEVEE of the same
file with the films' EEVEE outputs and with them removed (film off), medians of warm renders.

Run (heavy: under ``flock /tmp/tf/heavy.lock``): ``.venv/bin/python -m benchmarks.eevee_native
[--only GROUP ...] [--no-overlay]`` → ``docs/eevee-native.md`` and ``docs/images/eevee-native-*.png``.
"""

from __future__ import annotations

import argparse
import hashlib
import importlib
import json
import pathlib
import statistics
import sys
import tempfile
import time
from dataclasses import dataclass

import numpy as np

from benchmarks import common
from precompute.colour.colour_difference import delta_e_2000, exposure_scale
from precompute.output import image_io, render

sys.path.insert(0, str(pathlib.Path(common.ROOT) / "tests"))
sys.path.insert(0, str(pathlib.Path(common.ROOT) / "scripts"))
sys.path.insert(0, str(pathlib.Path(common.ROOT) / "sample_scenes"))

import _cycles_scenes as cc  # noqa: E402

CACHE = pathlib.Path(common.ROOT) / "benchmarks" / ".cache" / "eevee_native"
#: The issue's acceptance: mean ΔE2000 per case, and EEVEE's frame time with films / without.
LIMIT_OPAQUE, LIMIT_TRANSPARENT, LIMIT_TIME = 3.0, 4.0, 1.3
SIZE, SAMPLES = 64, 256  # spheres: Cycles' own noise at 256 spp ≈ 0.4–0.6 mean ΔE2000
#: Transparent walls converge slowly in Cycles (lamps seen through two walls, sample clamps off):
#: the bubble's 256-spp reference is 3.29 mean ΔE2000 from a 2048-spp one.
TRANSPARENT_SAMPLES = 2048
#: The sample scenes' references (the car window's 128-spp one is 0.74 from a 1024-spp one).
SCENE_SIZE, SCENE_SAMPLES = (160, 120), 1024
#: The scene samples every case's cache key was first made with: kept in the key, so raising a
#: group's samples (an extra key entry, :func:`_reference_samples`) renders only that group again.
KEY_SCENE_SAMPLES = 128
EEVEE_SAMPLES = 32
#: Version of the cases' scenes, part of the Cycles cache key.
SCENE_VERSION = 1
#: Versions of single cases' scenes, beside :data:`SCENE_VERSION` (only their references are
#: rendered again): 2, the write-back sets a transmissive film's Base Color white (Cycles tints
#: the transmission by it; Blender's default 0.8 had the bubble and the window let 0.8 through).
CASE_VERSIONS = {"soap_bubble": 2, "oil_slick": 2, "coated_car_window": 2}
CODE_PATHS = ("precompute", "addon", "benchmarks")


@dataclass(frozen=True)
class Case:
    """One scene: its group, name, what it shows, how it is built, whether the film is transparent."""

    group: str
    name: str
    what: str
    build: object
    transparent: bool = False
    sphere: bool = True  # the sphere mask of tests/_cycles_scenes.py, else the films' own


def _bpy():
    import bpy

    return bpy


def _extension():
    import thinfilm_headless  # scripts/: registers this repository as the extension

    return thinfilm_headless.register_extension()


def _save(path) -> pathlib.Path:
    bpy = _bpy()
    path = pathlib.Path(path).resolve()
    path.parent.mkdir(parents=True, exist_ok=True)
    bpy.ops.wm.save_as_mainfile(filepath=str(path), check_existing=False)
    return path


def _sphere_case(values):
    hdri_name, d, nf, nb, r = values

    def build(path):
        return cc.build_sphere_blend(
            path, cc.studiolight_path(hdri_name), d, nf, nb, r, size=SIZE, samples=SAMPLES
        )

    what = f"{hdri_name}, {d:g} nm, film {nf:g} on {nb:g}, roughness {r:g}"
    return Case("spheres", f"{hdri_name}-{d:g}-{nf:g}-{nb:g}-{r:g}", what, build)


def _lights_case(name):
    def build(path):
        from benchmarks import scene_lights

        bpy = _bpy()
        bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
        scene = scene_lights.build_scene(scene_lights.CASES[name], SIZE)
        cc.cycles_settings(scene, SAMPLES, size=SIZE, pixel_filter=("BLACKMAN_HARRIS", 1.5))
        return _save(path)

    from benchmarks import scene_lights

    return Case("lights", name, scene_lights.CASES[name]["what"], build)


def _texture_case():
    def build(path):
        from benchmarks import texture_thickness as tt

        bpy = _bpy()
        bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
        scene = bpy.context.scene
        tt._world_and_camera(bpy, scene, cc.studiolight_path(tt.HDRI), SIZE, SAMPLES)
        scene.cycles.pixel_filter_type, scene.cycles.filter_width = "BLACKMAN_HARRIS", 1.5
        scene.view_settings.view_transform = "Standard"
        tt.build_noise(bpy, pathlib.Path(path).parent)
        return _save(path)

    return Case("texture", "noise", "Noise Texture → Map Range 150–850 nm into Thin Film Thickness", build)


def _transparent_case(name):
    def build(path):
        from benchmarks import transparent_films

        path = transparent_films.build(name, path, SIZE, TRANSPARENT_SAMPLES)
        bpy = _bpy()
        bpy.context.scene.cycles.pixel_filter_type = "BLACKMAN_HARRIS"
        bpy.context.scene.cycles.filter_width = 1.5
        return _save(path)

    what = {"bubble": "thin-wall Principled soap bubble, 200–900 nm", "glass": "coated solid glass sphere"}[
        name
    ]
    return Case("transparent", name, what, build, transparent=True)


def _scene_case(name):
    def build(path):
        import make_scenes

        bpy = _bpy()
        made = make_scenes.make_scene(name, pathlib.Path(path).parent / "made", resolution=SCENE_SIZE)
        bpy.ops.wm.open_mainfile(filepath=str(made))
        principled = importlib.import_module("thinfilm_sh.addon.materials.principled")
        for mat in bpy.data.materials:
            props = getattr(mat, "thinfilm_sh", None)
            if props is not None and props.enabled and len(props.layers) == 1:
                principled.write_back_to_principled(mat)
        scene = bpy.context.scene
        scene.cycles.samples = SCENE_SAMPLES
        scene.cycles.use_adaptive_sampling = False
        scene.cycles.seed = 1
        return _save(path)

    transparent = name in ("soap_bubble", "coated_car_window", "oil_slick")
    return Case("scenes", name, f"sample scene {name}", build, transparent=transparent, sphere=False)


def cases() -> list[Case]:
    """Every case, in report order."""
    from benchmarks import cycles_compare

    out = [_sphere_case(c) for c in cycles_compare.CASES]
    out += [_lights_case(n) for n in ("sun", "point_area", "spot_metal")]
    out += [_texture_case(), _transparent_case("bubble"), _transparent_case("glass")]
    import make_scenes

    out += [_scene_case(n) for n in make_scenes.SCENE_NAMES]
    return out


# ----------------------------------------------------------------------------------------------
# Renders
# ----------------------------------------------------------------------------------------------
def _read(path) -> np.ndarray:
    return cc.read_exr(path)


def _render(scene, path) -> tuple[np.ndarray, float]:
    bpy = _bpy()
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    scene.render.filepath = str(path)
    t0 = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    return _read(path), time.perf_counter() - t0


def _reference_samples(name: str) -> int | None:
    """The Cycles samples of case ``name`` (or of its film-off copy, ``name-bare…``) where they
    are not the spheres' :data:`SAMPLES`: the transparent cases' and the sample scenes'."""
    import make_scenes

    base = name.split("-bare")[0]
    if base in ("bubble", "glass"):
        return TRANSPARENT_SAMPLES
    return SCENE_SAMPLES if base in make_scenes.SCENE_NAMES else None


def _key(name: str) -> str:
    """The cache key of case ``name``: its scene's sizes, samples and Blender's version."""
    bpy = _bpy()
    parts = [name, SIZE, SAMPLES, SCENE_SIZE, KEY_SCENE_SAMPLES, bpy.app.version_string, SCENE_VERSION]
    own = _reference_samples(name)
    version = CASE_VERSIONS.get(name.split("-bare")[0])
    key = json.dumps(parts + ([own] if own is not None else []) + ([version] if version is not None else []))
    return f"{name}_{hashlib.sha256(key.encode()).hexdigest()[:12]}"


def cycles_image(case: Case, blend, workdir, name: str | None = None) -> tuple[np.ndarray | None, float]:
    """Cycles' render of the case (cached by the case, sizes, samples and Blender): (RGB, s)."""
    bpy = _bpy()
    path = CACHE / f"{_key(name or case.name)}.npz"
    if path.is_file():
        return np.load(path)["rgb"], 0.0
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    if any(
        getattr(m, "thinfilm_sh", None) and m.thinfilm_sh.enabled and len(m.thinfilm_sh.layers) > 1
        for m in bpy.data.materials
    ):
        return None, 0.0  # a multilayer: Cycles has one film
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    rgb, seconds = _render(scene, pathlib.Path(workdir) / "cycles.exr")
    CACHE.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, rgb=rgb)
    return rgb, seconds


def _eevee(scene) -> None:
    scene.render.engine = "BLENDER_EEVEE"
    scene.eevee.taa_render_samples = EEVEE_SAMPLES


def eevee_image(blend, workdir) -> tuple[np.ndarray, float, dict]:
    """EEVEE's final render of the file (the extension synced its films at load): (RGB, s, outcomes)."""
    bpy = _bpy()
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    sync = importlib.import_module("thinfilm_sh.addon.eevee.sync")
    outcomes = sync.sync_all()
    scene = bpy.context.scene
    _eevee(scene)
    rgb, seconds = _render(scene, pathlib.Path(workdir) / "eevee.exr")
    return rgb, seconds, outcomes


#: A substrate IOR this close to 1 is a free film (a bubble on air): its film-off floor takes the
#: film's index, else the bare surface would vanish in both engines and the floor say nothing.
FREE_FILM_IOR = 1.001


def bare_blend(blend, workdir) -> pathlib.Path:
    """The case's file with every Principled film off (Thin Film Thickness 0, unlinked) and the
    extension's film switched off where its panel had one (else its sync would keep the film's
    EEVEE output: EEVEE would render the film where Cycles does not): the same BSDF without its
    film, for EEVEE's own floor against Cycles. A free film's IOR-1 substrate takes the film's
    index (:data:`FREE_FILM_IOR`)."""
    bpy = _bpy()
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    wiring = importlib.import_module("thinfilm_sh.addon.eevee.wiring")
    for mat in bpy.data.materials:
        props = getattr(mat, "thinfilm_sh", None)
        if props is not None and props.enabled:
            props.enabled = False
        wiring.remove(mat)
        for node in getattr(mat.node_tree, "nodes", ()):
            socket = (
                node.inputs.get("Thin Film Thickness")
                if node.bl_idname == "ShaderNodeBsdfPrincipled"
                else None
            )
            if socket is not None:
                for link in list(socket.links):
                    mat.node_tree.links.remove(link)
                socket.default_value = 0.0
                ior, film_ior = node.inputs["IOR"], node.inputs["Thin Film IOR"]
                if not ior.links and ior.default_value < FREE_FILM_IOR and not film_ior.links:
                    ior.default_value = film_ior.default_value
    return _save(pathlib.Path(workdir) / "bare.blend")


def _overlay_cache() -> dict:
    path = CACHE / "overlay.json"
    return json.loads(path.read_text()) if path.is_file() else {}


def _overlay_key(name: str) -> str:
    """The overlay's cache key of case ``name``: :func:`_key` and the product's source
    (common.source_digest): the overlay is our own output, measured again after a change."""
    return f"{_key(name)}_{common.source_digest()[:12]}"


def overlay_image(blend, workdir) -> tuple[np.ndarray, float]:
    """The headless ``render`` command on the file (the SH overlay over EEVEE's background)."""
    import thinfilm_headless

    out = pathlib.Path(workdir) / "overlay.png"
    t0 = time.perf_counter()
    code = thinfilm_headless.run_file(str(blend), ["render", "--out", str(out)])
    if code not in (0, 1):
        raise RuntimeError(f"headless render of {blend} failed with exit code {code}")
    return _read(out.with_suffix(".exr")), time.perf_counter() - t0


def film_mask(blend, workdir) -> np.ndarray:
    """The pixels the film objects cover (alpha of a Workbench render of them alone on a
    transparent film: opaque whatever their material, so a bubble or a window counts), one pixel
    of silhouette left out."""
    bpy = _bpy()
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    films = {
        m.name
        for m in bpy.data.materials
        if importlib.import_module("thinfilm_sh.addon.materials.description").description(m)
    }
    for obj in bpy.data.objects:
        if obj.type == "MESH":
            obj.hide_render = not any(
                s.material is not None and s.material.name in films for s in obj.material_slots
            )
    scene = bpy.context.scene
    scene.render.engine = "BLENDER_WORKBENCH"
    scene.display.render_aa = "OFF"
    scene.render.film_transparent = True
    path = pathlib.Path(workdir) / "mask.exr"
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_mode = "RGBA"
    scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    image = bpy.data.images.load(str(path))
    w, h = image.size
    alpha = np.array(image.pixels[:]).reshape(h, w, 4)[::-1, :, 3]
    bpy.data.images.remove(image)
    view = type("View", (), {"mask": alpha > 0.999})()
    return cc.object_mask(view)


def frame_times(blend, workdir, runs: int = 3) -> dict:
    """EEVEE's frame time of the file with its films' EEVEE outputs, then with them removed,
    interleaved: ``runs`` rounds, each opening the file twice (films, then films removed) and
    timing one warm render of each (after one untimed: shaders compiled, caches warm). Medians
    of wall seconds (``time_film``, ``time_off``) and process CPU seconds (``cpu_film``,
    ``cpu_off``). llvmpipe renders on this process's own threads, so its CPU time counts the
    frame's work whatever else the shared machine runs; but the same render's CPU seconds moved
    by up to 1.7× between processes here, and drift within one, so the two are interleaved."""
    bpy = _bpy()
    sync = importlib.import_module("thinfilm_sh.addon.eevee.sync")
    wiring = importlib.import_module("thinfilm_sh.addon.eevee.wiring")
    out = pathlib.Path(workdir) / "timed.exr"
    found = {True: [], False: []}
    for _ in range(runs):
        for film in (True, False):
            bpy.ops.wm.open_mainfile(filepath=str(blend))  # the films are synced at load
            scene = bpy.context.scene
            _eevee(scene)
            if not film:
                sync.unregister()  # render_pre would write them back
            try:
                if not film:
                    for mat in bpy.data.materials:
                        wiring.remove(mat)
                _render(scene, out)
                found[film].append(common.time_once_cpu(lambda scene=scene: _render(scene, out))[:2])
            finally:
                if not film:
                    sync.register()

    def median(film: bool, index: int) -> float:
        return statistics.median(t[index] for t in found[film])

    wall, cpu = 0, 1
    return dict(
        time_film=median(True, wall),
        time_off=median(False, wall),
        cpu_film=median(True, cpu),
        cpu_off=median(False, cpu),
    )


def compare(case: Case, workdir, overlay: bool, timed: bool) -> dict:
    """One case: build, Cycles (cached), EEVEE native, the overlay; ΔE2000 over the film."""
    workdir = pathlib.Path(workdir)
    blend = case.build(workdir / f"{case.name}.blend")
    ref, cycles_s = cycles_image(case, blend, workdir)
    ours, eevee_s, outcomes = eevee_image(blend, workdir)
    if case.sphere:
        mask = cc.object_mask(render.sphere_view(SIZE, SIZE, cc.DISTANCE, cc.FOV_DEG))
    else:
        mask = film_mask(blend, workdir)
    row = dict(
        case=case, ours=ours, ref=ref, mask=mask, eevee_s=eevee_s, cycles_s=cycles_s, outcomes=outcomes
    )
    if ref is not None:
        de = delta_e_2000(ours[mask], ref[mask], xyz="E")
        row.update(mean=float(np.mean(de)), p95=float(np.percentile(de, 95)))
    if ref is not None:
        bare = bare_blend(blend, workdir)
        bare_ref, bare_s = cycles_image(
            case, bare, workdir, name=case.name + "-bare2"
        )  # 2: IOR 1 → the film's
        bare_ours = eevee_image(bare, workdir)[0]
        row["cycles_s"] += bare_s
        row["floor"] = float(np.mean(delta_e_2000(bare_ours[mask], bare_ref[mask], xyz="E")))
    cached = _overlay_cache().get(_overlay_key(case.name))
    if cached is not None:
        row.update(cached)
    elif overlay:
        drawn, overlay_s = overlay_image(blend, workdir)
        found = {"overlay_s": overlay_s}
        if ref is not None:
            found["overlay_mean"] = float(np.mean(delta_e_2000(drawn[mask], ref[mask], xyz="E")))
        older = _key(case.name)  # the case's figures for other code, and those keyed without it
        store = {k: v for k, v in _overlay_cache().items() if k != older and not k.startswith(older + "_")}
        store[_overlay_key(case.name)] = found
        CACHE.mkdir(parents=True, exist_ok=True)
        (CACHE / "overlay.json").write_text(json.dumps(store, indent=1))
        row.update(found)
    if timed:
        row.update(frame_times(blend, workdir))
    return row


# ----------------------------------------------------------------------------------------------
# Report
# ----------------------------------------------------------------------------------------------
def _strip(row) -> np.ndarray:
    ours, ref, mask = row["ours"], row["ref"], row["mask"]
    base = ref if ref is not None else ours
    scale = exposure_scale(base[mask], xyz="E")
    de = np.zeros(mask.shape)
    if ref is not None:
        de[mask] = delta_e_2000(ours[mask], ref[mask], scale=scale, xyz="E")
    grey = np.repeat(np.clip(de / 10.0, 0.0, 1.0)[..., None], 3, axis=-1)
    shown = ref if ref is not None else np.zeros_like(ours)
    return np.concatenate(
        [image_io.srgb_encode(ours * scale), image_io.srgb_encode(shown * scale), grey], axis=1
    )


def write_picture(rows, path: pathlib.Path, columns: int = 2) -> None:
    """EEVEE native | Cycles | ΔE2000 (white = 10), ``columns`` cases per line."""
    strips = [_strip(r) for r in rows]
    blank = np.ones_like(strips[0])
    while len(strips) % columns:
        strips.append(blank)
    lines = [np.concatenate(strips[i : i + columns], axis=1) for i in range(0, len(strips), columns)]
    picture = np.concatenate(lines, axis=0)
    path.parent.mkdir(parents=True, exist_ok=True)
    from PIL import Image  # optimised PNG: docs/images keeps each file small

    rgb8 = np.clip(np.rint(picture * 255.0), 0, 255).astype(np.uint8)
    Image.fromarray(np.ascontiguousarray(rgb8), "RGB").save(path, format="PNG", optimize=True)


def _limit(row) -> float:
    return LIMIT_TRANSPARENT if row["case"].transparent else LIMIT_OPAQUE


def report_lines(rows, seconds: float, command: str) -> list[str]:
    """The markdown table of every case and the acceptance line."""
    scored = [r for r in rows if "mean" in r]
    met = all(r["mean"] <= _limit(r) for r in scored)
    timed = [r for r in rows if "time_film" in r]
    ratios = [r.get("cpu_film", r["time_film"]) / r.get("cpu_off", r["time_off"]) for r in timed]
    lines = [
        f"Generated by `.venv/bin/python -m benchmarks.eevee_native{command}` "
        f"({common.git_describe(CODE_PATHS)}, {seconds:.0f} s).",
        f"{'; '.join(common.machine_lines())}. Load average at the end: {common.load_average()}.",
        "",
        f"Spheres {SIZE}×{SIZE}, Cycles {SAMPLES} spp ({TRANSPARENT_SAMPLES} spp for the transparent "
        f"ones); sample scenes {SCENE_SIZE[0]}×{SCENE_SIZE[1]}, "
        f"Cycles {SCENE_SAMPLES} spp (CPU, no denoising, Blackman–Harris 1.5 px); EEVEE "
        f"{EEVEE_SAMPLES} TAA samples.",
        "",
        f"Acceptance: mean ΔE2000 per case ≤ {LIMIT_OPAQUE:g} (opaque) / ≤ {LIMIT_TRANSPARENT:g} "
        f"(transparent): **{'met' if met else 'not met'}** "
        f"({sum(r['mean'] <= _limit(r) for r in scored)} of {len(scored)} cases).",
    ]
    if ratios:
        lines.append(
            f"EEVEE frame time (process CPU) with the film / without ≤ {LIMIT_TIME:g}: "
            f"**{'met' if max(ratios) <= LIMIT_TIME else 'not met'}** (worst {max(ratios):.2f}×)."
        )
    lines += [
        "",
        "| group | case | EEVEE native mean ΔE2000 | p95 | limit | EEVEE's floor (no film) | overlay mean "
        "ΔE2000 | EEVEE s | overlay s | Cycles s |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        c = r["case"]
        mean = f"**{r['mean']:.2f}**" if "mean" in r else "no Cycles equivalent"
        p95 = f"{r['p95']:.2f}" if "p95" in r else "–"
        over = f"{r['overlay_mean']:.2f}" if "overlay_mean" in r else "–"
        over_s = f"{r['overlay_s']:.1f}" if "overlay_s" in r else "–"
        cyc = f"{r['cycles_s']:.0f}" if r["cycles_s"] else "cached"
        floor = f"{r['floor']:.2f}" if "floor" in r else "–"
        cells = [
            c.group,
            c.what,
            mean,
            p95,
            f"{_limit(r):g}",
            floor,
            over,
            f"{r['eevee_s']:.1f}",
            over_s,
            cyc,
        ]
        lines.append("| " + " | ".join(cells) + " |")
    if timed:
        lines += ["", *frame_time_lines(timed)]
    return lines


def frame_time_lines(rows) -> list[str]:
    """The frame-time table: wall and process CPU seconds with the film and film off."""
    lines = [
        "| frame time | with film s | film off s | ratio | CPU with film s | CPU film off s | CPU ratio |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        wall = r["time_film"] / r["time_off"]
        cells = [r["case"].what, f"{r['time_film']:.2f}", f"{r['time_off']:.2f}", f"{wall:.2f}×"]
        if "cpu_film" in r:
            cells += [f"{r['cpu_film']:.2f}", f"{r['cpu_off']:.2f}", f"{r['cpu_film'] / r['cpu_off']:.2f}×"]
        else:
            cells += ["–", "–", "–"]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def main_thread_costs(runs: int = 7) -> list[dict]:
    """What an edit costs Blender's main thread, per preset material on a sphere under the studio
    HDRI: reading its spec (:func:`addon.eevee.source.spec`), the timer's look at the World's
    analysis (:func:`addon.eevee.sync.world_of`, once per tick) and writing the computed images in place
    (:func:`addon.eevee.wiring.apply`: copy, update, pack), medians of ``runs``; and the worker's
    share (table from memory + pixels, :func:`addon.eevee.sync.compute`) for scale."""
    bpy = _bpy()
    source = importlib.import_module("thinfilm_sh.addon.eevee.source")
    sync = importlib.import_module("thinfilm_sh.addon.eevee.sync")
    wiring = importlib.import_module("thinfilm_sh.addon.eevee.wiring")
    out = []
    import make_scenes

    for preset in ("SOAP_FILM", "OIL_ON_WATER", "ANODISED_TITANIUM", "BEETLE_MULTILAYER"):
        bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
        make_scenes.studio_world(bpy.context.scene, make_scenes.hdri_path("studio"))
        bpy.ops.mesh.primitive_uv_sphere_add()
        mat = bpy.data.materials.new(preset)
        mat.thinfilm_sh.preset = preset
        mat.thinfilm_sh.enabled = True
        bpy.context.active_object.data.materials.append(mat)
        scene = bpy.context.scene
        world = sync.world_of(scene)
        spec = source.spec(mat, scene, world)
        made = sync.compute(spec)  # bakes once (or reads the cache): the worker's part
        wiring.apply(mat, spec, *made)  # the first write also makes the nodes
        read = common.time_runs(lambda: source.spec(mat, scene, world), runs=runs)  # noqa: B023
        world_s = common.time_runs(lambda: sync.world_of(scene), runs=runs)  # noqa: B023
        write = common.time_runs(lambda: wiring.apply(mat, spec, *made), runs=runs)  # noqa: B023
        worker = common.time_runs(lambda: sync.compute(spec), runs=3)  # noqa: B023
        out.append(
            dict(
                preset=preset,
                size=f"{made[0].width}×{made[0].height}",
                read_ms=1e3 * statistics.median(read),
                world_ms=1e3 * statistics.median(world_s),
                write_ms=1e3 * statistics.median(write),
                worker_ms=1e3 * statistics.median(worker),
            )
        )
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--only", nargs="+", help="only these groups (spheres, lights, texture, transparent, scenes)"
    )
    parser.add_argument("--case", nargs="+", help="only these cases (by name)")
    parser.add_argument("--no-overlay", action="store_true", help="skip the overlay's figures")
    parser.add_argument("--out", default="eevee-native-results.md", help="the report (under docs/)")
    parser.add_argument(
        "--main-thread", action="store_true", help="only measure an edit's main-thread costs and print them"
    )
    parser.add_argument(
        "--frame-times",
        action="store_true",
        help="only measure EEVEE's frame time, film on and off (the timed scenes, or --case), and print it",
    )
    args = parser.parse_args(argv)
    _extension()
    if args.main_thread:
        for row in main_thread_costs():
            print(row)
        return 0
    chosen = [
        c
        for c in cases()
        if (not args.only or c.group in args.only) and (not args.case or c.name in args.case)
    ]
    timed_names = {"principled_film", "soap_bubble", "anodised_titanium"}
    if args.frame_times:
        measured = []
        with tempfile.TemporaryDirectory(prefix="thinfilm_eevee_native_") as tmp:
            for case in [c for c in chosen if args.case or c.name in timed_names]:
                folder = pathlib.Path(tmp) / case.name
                folder.mkdir()
                row = dict(case=case, **frame_times(case.build(folder / f"{case.name}.blend"), folder))
                print(case.name, {k: round(v, 3) for k, v in row.items() if isinstance(v, float)}, flush=True)
                measured.append(row)
        print(f"Load average at the end: {common.load_average()}.")
        print("\n".join(frame_time_lines(measured)))
        return 0
    t0 = time.perf_counter()
    rows = []
    with tempfile.TemporaryDirectory(prefix="thinfilm_eevee_native_") as tmp:
        for case in chosen:
            folder = pathlib.Path(tmp) / case.name
            folder.mkdir()
            try:
                row = compare(case, folder, not args.no_overlay, case.name in timed_names)
            except Exception as exc:  # one broken case is reported, the others still run
                print(case.group, case.name, "FAILED:", repr(exc), flush=True)
                continue
            print(
                case.group,
                case.name,
                {k: round(v, 3) for k, v in row.items() if isinstance(v, float)},
                flush=True,
            )
            rows.append(row)
    command = "".join(
        [f" --only {' '.join(args.only)}" if args.only else "", " --no-overlay" if args.no_overlay else ""]
    )
    lines = [
        "# EEVEE-native films against Cycles: the figures",
        "",
        *report_lines(rows, time.perf_counter() - t0, command),
    ]
    for group in ("spheres", "lights", "texture", "transparent", "scenes"):
        chosen_rows = [r for r in rows if r["case"].group == group]
        if chosen_rows:
            name = f"eevee-native-{group}.png"
            write_picture(
                chosen_rows,
                pathlib.Path(common.ROOT) / "docs" / "images" / name,
                3 if group != "scenes" else 2,
            )
            lines += ["", f"![EEVEE native | Cycles | ΔE2000 (white = 10): {group}](images/{name})"]
    path = common.write_doc(args.out, "\n".join(lines))
    print("\n".join(lines))
    print(f"wrote {path}")
    scored = [r for r in rows if "mean" in r]
    return 0 if all(r["mean"] <= _limit(r) for r in scored) else 1


if __name__ == "__main__":
    raise SystemExit(main())
