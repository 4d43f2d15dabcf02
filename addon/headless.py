"""Headless bake and render: the same collection and draw code as the viewport, off-screen.

``render_scene`` draws the scene camera's view into a float off-screen buffer: the rest of the
scene first (Blender's own Solid drawing, for depth and for the objects we don't shade), then
the World as background, then every thin-film object, depth-tested. Writes a scene-linear EXR
and a PNG (sRGB "Standard" view with the scene's exposure).

The frame is anti-aliased as Cycles' is: drawn :data:`SUPERSAMPLE` times larger (over a window
widened by the filter's support, so border pixels see beyond the frame) and filtered down with
the scene's Cycles pixel filter, type and width (``scene.cycles.pixel_filter_type`` /
``filter_width``; Cycles' defaults, Blackman–Harris of ±1.5 px, without the Cycles add-on):
:func:`pixel_filter_settings`, :mod:`precompute.pixel_filter`. The viewport keeps Blender's own
anti-aliasing.

The table cache is the add-on's (:func:`.tables.table_cache`: ``THINFILM_SH_CACHE``, the
preference, the private default); every command takes ``--cache-dir`` to name another. An
unusable cache folder or a write that fails (a full disk) is an ``error: …`` line and exit
status 2, never a traceback; a table that could not be saved to the cache is still used.
"""

from __future__ import annotations

import json
import pathlib
import sys
import time

import bpy
import numpy as np
from mathutils import Matrix

from ..precompute import cli_support, effects, image_io, pixel_filter, table_io
from . import prefs, scene_draw, tables, world
from .description import description, description_key, warnings
from .gpu.context import ensure_gpu_context
from .gpu.draw import render_offscreen

#: The message of a render made while the *Show Thin Film Overlay* preference is off.
OVERLAY_OFF = "the Show Thin Film Overlay preference is off: no thin film is drawn"


def scene_materials(scene):
    """{material name: description} of the visible meshes' film materials (enabled or Principled), errors."""
    found = {}
    errors = {}
    for obj in scene.objects:
        if obj.type != "MESH" or not obj.visible_get():
            continue
        for slot in obj.material_slots:
            mat = slot.material
            if mat is None or mat.name in found or mat.name in errors:
                continue
            try:
                desc = description(mat)
            except ValueError as exc:
                errors[mat.name] = str(exc)
                continue
            if desc is not None:
                found[mat.name] = desc
    return found, errors


def bake_scene(scene, out_dir=None, progress=print, cache=None) -> dict:
    """Bake (or load from cache) every material the scene shows; optional EXR copies in ``out_dir``.

    ``cache``: as :func:`.tables.get_table_with_source` takes it (None: the add-on's). A table
    the cache could not keep is used anyway, and named in ``errors`` (with ``cache_error`` in its
    entry).

    One material's failure does not stop the others: a material that cannot be described or
    baked is recorded in ``errors`` ({material name: why}). With ``out_dir`` each material gets
    a file of its own, named by :func:`precompute.cli_support.unique_file_names` (``Mat 001``,
    ``Mat.001`` and ``Mat_001`` never share one), ``manifest`` maps material names to the files
    written, and every destination is checked (``UsageError``) before the first bake.
    """
    found, errors = scene_materials(scene)
    summary = {"materials": {}, "errors": errors, "manifest": {}}
    files = {}
    if out_dir:
        folder = cli_support.output_dir("--out-dir", out_dir)
        files = {name: folder / file for name, file in cli_support.unique_file_names(found).items()}
        for path in files.values():
            try:
                table_io.check_destination(path)
            except table_io.TableWriteError as exc:
                raise cli_support.UsageError(f"--out-dir: {exc}") from None
    shared: dict[str, str] = {}
    for i, (name, desc) in enumerate(sorted(found.items())):
        key = description_key(desc)
        t0 = time.perf_counter()
        try:
            result, source = tables.get_table_with_source(desc, cache)
        except Exception as exc:  # isolated: the other materials are still baked
            errors[name] = scene_draw.bake_failure(name, exc)
            progress(f"[{i + 1}/{len(found)}] {name}: failed")
            continue
        entry = {
            "key": key,
            "source": source,
            "seconds": time.perf_counter() - t0,
            "shape": list(result.data.shape),
            "sh_order": result.sh_order,
            "shared_with": shared.get(key),
        }
        problem = tables.cache_error(desc)
        if problem is not None:
            entry["cache_error"] = problem
            errors[name] = f"material {name!r}: {problem}"
        shared.setdefault(key, name)
        if out_dir:
            path = files[name]
            path.parent.mkdir(parents=True, exist_ok=True)
            table_io.write_table(path, result.data, result.attributes())
            entry["file"] = summary["manifest"][name] = str(path)
        summary["materials"][name] = entry
        progress(f"[{i + 1}/{len(found)}] {name}: {source} ({entry['seconds'] * 1000:.0f} ms)")
    return summary


def _view3d_for_depth():
    """A VIEW_3D space and WINDOW region from any screen (available in background mode)."""
    for screen in bpy.data.screens:
        for area in screen.areas:
            if area.type == "VIEW_3D":
                region = next((r for r in area.regions if r.type == "WINDOW"), None)
                if region is not None:
                    return area.spaces.active, region
    return None, None


def camera_matrices(scene, depsgraph, width: int, height: int):
    """View and projection matrices of the scene's camera for a *width* × *height* frame."""
    cam = scene.camera
    if cam is None:
        raise ValueError(f"scene '{scene.name}' has no camera: set one to render")
    view = np.array(cam.matrix_world.inverted(), dtype=np.float64)
    proj = np.array(cam.calc_matrix_camera(depsgraph, x=width, y=height), dtype=np.float64)
    return view, proj


#: Samples per pixel along each axis of the headless frame (4 × 4 per pixel), filtered with the
#: scene's pixel filter. Against Cycles (issue 22's spheres under studio HDRIs) 4× lowered the
#: mean ΔE2000 from 1.36 to 1.20 (edges, lamp highlights and reflected detail alias without).
SUPERSAMPLE = 4


def pixel_filter_settings(scene) -> tuple[str, float]:
    """The scene's Cycles pixel filter (type, width in pixels), Cycles' defaults without the add-on."""
    cycles = getattr(scene, "cycles", None)
    kind = getattr(cycles, "pixel_filter_type", pixel_filter.DEFAULT_FILTER)
    width = float(getattr(cycles, "filter_width", pixel_filter.DEFAULT_WIDTH))
    if kind not in pixel_filter.FILTERS:
        kind = pixel_filter.DEFAULT_FILTER
    return kind, width


def widened_projection(projection, width: int, height: int, pad: int) -> np.ndarray:
    """The projection of the window ``pad`` pixels wider on each side: the frame's pixel grid
    continues outside it (NDC scaled by W/(W + 2 pad) and H/(H + 2 pad))."""
    scale = np.diag([width / (width + 2.0 * pad), height / (height + 2.0 * pad), 1.0, 1.0])
    return scale @ np.asarray(projection, dtype=np.float64)


def _max_texture_size() -> int:
    import gpu

    try:
        return int(gpu.capabilities.max_texture_size_get())
    except (AttributeError, SystemError):
        return 16384


def render_scene(
    scene,
    out_path,
    width: int | None = None,
    height: int | None = None,
    background: bool = True,
    supersample: int | None = None,
) -> dict:
    """Render the camera view with the thin-film shader; writes ``out_path`` (.png) and a .exr beside it.

    ``supersample``: samples per pixel along each axis (default :data:`SUPERSAMPLE`; lowered when
    the enlarged buffer would exceed the GPU's texture size), filtered with the scene's Cycles
    pixel filter; 1 draws one sample per pixel, unfiltered.
    """
    ensure_gpu_context()
    scale = scene.render.resolution_percentage / 100.0
    width = int(width or round(scene.render.resolution_x * scale))
    height = int(height or round(scene.render.resolution_y * scale))
    depsgraph = bpy.context.evaluated_depsgraph_get()
    view, proj = camera_matrices(scene, depsgraph, width, height)
    kind, filter_width = pixel_filter_settings(scene)
    factor = max(1, int(SUPERSAMPLE if supersample is None else supersample))
    pad = pixel_filter.margin(kind, filter_width) if factor > 1 else 0
    limit = _max_texture_size()
    while factor > 1 and factor * (max(width, height) + 2 * pad) > limit:
        factor -= 1
    if factor == 1:
        pad = 0
    proj = widened_projection(proj, width, height, pad)
    frame_w, frame_h = factor * (width + 2 * pad), factor * (height + 2 * pad)
    t0 = time.perf_counter()
    errors: dict[str, str] = {}  # materials drawn as the magenta fallback, and why
    if prefs.overlay_enabled():
        items, messages = scene_draw.collect(depsgraph, allow_bake=True, allow_world=True, errors=errors)
    else:  # the artist's off switch holds for renders too: Blender's own drawing only
        items, messages = [], [OVERLAY_OFF]
    env = None
    lighting = scene_draw.CACHES.world
    if background and lighting is not None and lighting.environment is not None:
        env = lighting.environment.panorama  # the panorama the split sum was prefiltered from
    space, region = _view3d_for_depth()

    film_objects = {item.name.split("/")[0] for item in items}

    def depth_from(offscreen):
        """Blender's Solid drawing of everything else, for depth and for the other objects.

        Thin-film objects are hidden during it: drawn twice, Blender's and our vertex transforms
        round differently and the depth test would let the grey Solid surface speckle through.
        """
        if space is None:
            return
        shading = space.shading
        saved = (shading.type, shading.light, shading.color_type)
        hidden = [o for o in scene.objects if o.name in film_objects and not o.hide_get()]
        try:
            for o in hidden:
                o.hide_set(True)
            bpy.context.view_layer.update()  # draw_view3d reads the evaluated depsgraph
            shading.type, shading.light, shading.color_type = "SOLID", "STUDIO", "MATERIAL"
            offscreen.draw_view3d(
                scene,
                bpy.context.view_layer,
                space,
                region,
                _mathutils_matrix(view),
                _mathutils_matrix(proj),
                do_color_management=False,
            )
        finally:
            shading.type, shading.light, shading.color_type = saved
            for o in hidden:
                o.hide_set(False)
            if hidden:
                bpy.context.view_layer.update()

    rgba = render_offscreen(items, view, proj, frame_w, frame_h, background=env, depth_from=depth_from)
    rgb = rgba.astype(np.float64)
    bad = ~np.isfinite(rgb)
    nonfinite = int(bad.any(axis=-1).sum())
    if bad.any():
        messages.append(f"{nonfinite} non-finite samples set to 0")
        rgb = np.where(bad, 0.0, rgb)
    if factor > 1:
        rgb = pixel_filter.downsample(rgb, kind, filter_width, factor, pad)
    out = pathlib.Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    # Alpha: coverage, 1 − (1 − alpha behind)·mean T over a transparent film (gpu.draw.WALL_PASSES).
    alpha = np.clip(rgb[..., 3], 0.0, 1.0)
    rgb = rgb[..., :3]
    image_io.write_exr(out.with_suffix(".exr"), rgb, None if background else alpha)
    image_io.write_png(
        out.with_suffix(".png"), image_io.srgb_encode(rgb, float(scene.view_settings.exposure))
    )
    return {
        "png": str(out.with_suffix(".png")),
        "exr": str(out.with_suffix(".exr")),
        "size": [width, height],
        "supersample": factor,
        "pixel_filter": [kind, filter_width] if factor > 1 else None,
        "objects": [item.name for item in items if not item.fallback],
        "fallback_objects": [item.name for item in items if item.fallback],
        "errors": errors,
        "world_errors": list(lighting.sh.errors) if lighting is not None else [],
        "nonfinite_pixels": nonfinite,
        "messages": messages,
        "seconds": time.perf_counter() - t0,
    }


def _mathutils_matrix(m):
    return Matrix(np.asarray(m).tolist())


def render_size(scene, width=None, height=None) -> tuple[int, int]:
    """The render's size: ``width``/``height``, else the scene's resolution × percentage;
    ``UsageError`` naming where a size outside 1–16384 pixels came from."""
    scale = scene.render.resolution_percentage / 100.0
    sizes = []
    for given, option, axis in ((width, "--width", "x"), (height, "--height", "y")):
        if given:
            sizes.append(cli_support.image_size(option, given))
        else:
            value = round(getattr(scene.render, f"resolution_{axis}") * scale)
            sizes.append(cli_support.image_size(f"the scene's resolution {axis} × percentage", value))
    return sizes[0], sizes[1]


def main(argv) -> int:
    """The CLI behind ``blender -b file.blend -c thinfilm_sh …`` and scripts/thinfilm_headless.py.

    Exit codes (docs/cli-exit-codes.md): 0 done; 1 partial (a material or the World could not
    be evaluated and was replaced by its fallback, each reported); 2 refused before any work (a
    bad option, path, size or scene value, named); 3 internal error (traceback in the log file
    named); 4 an output could not be written. Never a traceback.
    """
    return cli_support.run(lambda: _main(argv), prog="thinfilm_sh")


def _main(argv) -> int:
    parser = cli_support.ArgumentParser(
        prog="thinfilm_sh", description="Thin Film SH: headless bake and render of the open .blend file."
    )
    sub = parser.add_subparsers(dest="command", required=True)
    b = sub.add_parser("bake", help="bake every thin-film material the scene shows (uses the cache)")
    b.add_argument("--out-dir", help="also write each table as an EXR here (one file per material)")
    b.add_argument("--json", help="write a JSON summary here (errors and a manifest of the files)")
    r = sub.add_parser("render", help="render the scene camera's view with the thin-film shader to PNG + EXR")
    r.add_argument("--out", required=True, help="output .png (an .exr is written beside it)")
    r.add_argument("--width", type=cli_support.image_size_arg("--width"))
    r.add_argument("--height", type=cli_support.image_size_arg("--height"))
    r.add_argument("--no-background", action="store_true", help="leave the World out of the background")
    r.add_argument(
        "--supersample",
        type=cli_support.supersample_arg("--supersample"),
        default=SUPERSAMPLE,
        help=f"samples per pixel along each axis, filtered with the scene's Cycles pixel filter "
        f"(default {SUPERSAMPLE}; 1: one sample per pixel, no filter)",
    )
    r.add_argument("--json", help="write a JSON summary here (objects, fallbacks, errors, messages)")
    p = sub.add_parser(
        "plan",
        help="print what each visible material needs simulated (effects, table size, orders, estimated "
        "bake time and shader cost) and why; bakes nothing",
    )
    for command in (b, r, p):
        command.add_argument(
            "--cache-dir",
            help="the table cache's folder (default: $THINFILM_SH_CACHE, else the add-on's preference, "
            "else a private per-user folder); tables go in its thinfilm_sh_tables subfolder",
        )
    args = parser.parse_args(argv)
    with tables.cache_dir_override(args.cache_dir):
        cache = tables.open_cache()
        if not isinstance(cache, tables.UnusableCache):
            try:
                cache.size_bytes()  # checks the folder: no symbolic link, yours, private
            except OSError as exc:
                cache = tables.UnusableCache(f"table cache unusable: {exc}")
        if isinstance(cache, tables.UnusableCache):
            if args.command == "bake":  # filling the cache is what it is for: refused before work
                raise cli_support.UsageError(cache.reason)
            print(f"note: {cache.reason}; tables are baked but not kept on disk")
        return _run(args, bpy.context.scene, cache)


def _write_json(path, summary) -> None:
    table_io.write_bytes(path, json.dumps(summary, indent=2, allow_nan=False).encode("utf-8"))


def _run(args, scene, cache) -> int:
    """Run the parsed sub-command on ``scene``; returns the exit code."""
    if args.command == "bake":
        return _run_bake(args, scene, cache)
    if args.command == "render":
        return _run_render(args, scene)
    return _run_plan(scene, cache)


def _run_bake(args, scene, cache) -> int:
    """`bake`: every visible thin-film material's table into the cache (and --out-dir)."""
    with cli_support.refusing():  # before any bake: a refusal is exit 2
        json_path = cli_support.output_file("--json", args.json) if args.json else None
        if args.out_dir:
            cli_support.output_dir("--out-dir", args.out_dir)
    summary = bake_scene(scene, args.out_dir, cache=cache)
    if json_path is not None:
        json_path.parent.mkdir(parents=True, exist_ok=True)
        _write_json(json_path, summary)
    for err in summary["errors"].values():
        print(f"error: {err}", file=sys.stderr)
    return cli_support.EXIT_PARTIAL if summary["errors"] else cli_support.EXIT_OK


def _run_render(args, scene) -> int:
    """`render`: the scene's frame through the camera, to --out's PNG and EXR."""
    with cli_support.refusing():  # before any work: a refusal is exit 2
        out = cli_support.output_file("--out", args.out)
        cli_support.output_file("--out (the .png)", out.with_suffix(".png"))
        cli_support.output_file("--out (the .exr beside it)", out.with_suffix(".exr"))
        json_path = cli_support.output_file("--json", args.json) if args.json else None
        width, height = render_size(scene, args.width, args.height)
        cli_support.exposure("the scene's exposure (Color Management)", scene.view_settings.exposure)
        if scene.camera is None:
            raise ValueError(f"scene '{scene.name}' has no camera: set one to render")
    result = render_scene(
        scene, args.out, width, height, background=not args.no_background, supersample=args.supersample
    )
    if json_path is not None:
        json_path.parent.mkdir(parents=True, exist_ok=True)
        _write_json(json_path, result)
    for msg in result["messages"]:
        print(f"note: {msg}")
    aa = (
        f"{result['supersample']}×{result['supersample']} samples per pixel, "
        f"{result['pixel_filter'][0].replace('_', '-').title()} {result['pixel_filter'][1]:g} px"
        if result["pixel_filter"]
        else "1 sample per pixel"
    )
    print(
        f"wrote {result['png']} and {result['exr']} ({result['size'][0]}×{result['size'][1]}, {aa}, "
        f"{len(result['objects'])} thin-film objects, {result['seconds']:.1f} s)"
    )
    failed = [*result["errors"].values(), *result["world_errors"]]
    for err in failed:
        print(f"error: {err}", file=sys.stderr)
    partial = failed or result["nonfinite_pixels"]
    return cli_support.EXIT_PARTIAL if partial else cli_support.EXIT_OK


def _run_plan(scene, cache) -> int:
    """`plan`: what each visible material needs and costs; nothing is baked."""
    # Materials of visible objects only; nothing is baked. The World's SH (cached by its key)
    # sets the World order; tables already in memory or in the disk cache cost no bake.
    found, errors = scene_materials(scene)
    sh = world.world_sh(scene) if found else None
    coeffs = sh.coeffs if sh is not None else None
    keys = {name: description_key(desc) for name, desc in found.items()}
    on_disk = not isinstance(cache, tables.UnusableCache)
    cached = {
        keys[name]
        for name, desc in found.items()
        if tables.peek_table(desc) is not None or (on_disk and cache.path_for(keys[name]).is_file())
    }
    plan = effects.scene_plan(found, coeffs, cached=cached)
    print(effects.format_plan(plan))
    for name, mp in plan.materials.items():  # one JSON line per material, for scripts
        first = plan.tables[mp.key][0]
        summary = {
            "material": name,
            "sh_order": mp.plan.sh_order,
            "view_samples": mp.plan.view_samples,
            "thickness_samples": mp.plan.thickness_samples,
            "wavelengths": mp.plan.wavelength_count,
            "shared_with": first if first != name else None,
            "world_order": plan.world_order,
            **mp.to_dict(),
        }
        # What the preview cannot follow, and what drives a linked thickness at what resolution.
        summary["notes"] = warnings(bpy.data.materials[name]) if name in bpy.data.materials else []
        for note in summary["notes"]:
            print(f"note: material {name!r}: {note}")
        print("plan-json " + json.dumps(summary))
    failed = [*errors.values(), *(sh.errors if sh is not None else ())]
    for err in failed:
        print(f"error: {err}", file=sys.stderr)
    return cli_support.EXIT_PARTIAL if failed else cli_support.EXIT_OK


def _cli(argv) -> int:
    return main(list(argv))


_cli_handle = None


def register() -> None:
    """Register the `thinfilm_sh` command-line command (blender -c thinfilm_sh)."""
    global _cli_handle
    if _cli_handle is None and hasattr(bpy.utils, "register_cli_command"):
        _cli_handle = bpy.utils.register_cli_command("thinfilm_sh", _cli)


def unregister() -> None:
    """Unregister the command-line command."""
    global _cli_handle
    if _cli_handle is not None:
        bpy.utils.unregister_cli_command(_cli_handle)
        _cli_handle = None
