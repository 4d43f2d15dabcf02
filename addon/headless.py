"""Headless bake and render: the same collection and draw code as the viewport, off-screen.

``render_scene`` draws the scene camera's view into a float off-screen buffer: the rest of the
scene first (Blender's own Solid drawing, for depth and for the objects we don't shade), then
the World as background, then every thin-film object, depth-tested. Writes a scene-linear RGBA
EXR in the file's working space (with its chromaticities) and an RGBA PNG through Blender's own
colour management of the scene (:func:`.display.save_png`: display, view, look, exposure, gamma).

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

import dataclasses
import json
import pathlib
import sys
import time

import bpy
import numpy as np
from mathutils import Matrix

from ..precompute import cli_support, effects, image_io, pixel_filter, table_io
from . import cli_args, display, frames, prefs, scene_draw, tables, world
from .background import (
    behind_texture,
    composite,
    film_layers,
    refraction_margin,
    render_background,
    view_depth,
    wall_objects,
)
from .description import description, description_key, warnings
from .gpu.context import ensure_gpu_context
from .gpu.draw import render_offscreen
from .world_key import working_space

#: The message of a render made while the *Show Thin Film Overlay* preference is off.
OVERLAY_OFF = "the Show Thin Film Overlay preference is off: no thin film is drawn"


def rendered(inst) -> bool:
    """Whether a depsgraph instance is rendered: neither it nor its instancer is ``hide_render``."""
    if inst.object.original.hide_render:
        return False
    parent = inst.parent if inst.is_instance else None
    return parent is None or not parent.original.hide_render


def _rendered_objects(scene):
    """The evaluated mesh objects ``scene``'s view layer renders, instances included (collection
    instances from excluded collections, Geometry Nodes, particles: ``depsgraph.object_instances``)."""
    depsgraph = bpy.context.evaluated_depsgraph_get()  # the context's scene and view layer
    for inst in depsgraph.object_instances:
        if inst.object.type == "MESH" and rendered(inst):
            yield inst.object


def _hidden_in_render(item) -> bool:
    """Whether a draw item's object is ``hide_render`` (the viewport's depsgraph still lists it)."""
    obj = bpy.data.objects.get(item.name.split("/")[0])
    return obj is not None and obj.hide_render


def holdout_objects(view_layer) -> set:
    """Names of the objects ``view_layer`` renders as holdouts: the object's own *Holdout*
    (``is_holdout``) or a holdout collection of the view layer (``LayerCollection.holdout``)."""
    names = {o.name for o in view_layer.objects if o.is_holdout}
    stack = [view_layer.layer_collection]
    while stack:
        layer = stack.pop()
        if layer.holdout and not layer.exclude:
            names.update(o.name for o in layer.collection.all_objects)
        stack.extend(layer.children)
    return names


def _films_over(behind, items, view, proj, size, sampling, messages):
    """The final frame over the background pass ``behind``: the films' layers (opaque, walls)
    depth-tested and filtered over it, holdout films cutting transparent holes (:func:`holdout_objects`);
    (RGBA, non-finite samples zeroed). ``size``: the films' pass (w, h); ``sampling``: (filter
    kind, width, supersampling factor, pad)."""
    ensure_gpu_context()
    holdouts = holdout_objects(bpy.context.view_layer)
    hole_items = [  # drawn as opaque surfaces: only their depth is used
        dataclasses.replace(item, wall=None) for item in items if item.name.split("/")[0] in holdouts
    ]
    items = [item for item in items if item.name.split("/")[0] not in holdouts]
    refracted = behind_texture(behind, items, sampling[3])
    films, transmit, depth = film_layers(items, view, proj, *size, behind=refracted)
    films, nonfinite = _finite(films.astype(np.float64), messages)
    holes = None
    if hole_items:  # holdout films cut a transparent hole where they are in front
        holes = view_depth(render_offscreen(hole_items, view, proj, *size, with_depth=True)[1], proj)
    return composite(behind, films, view_depth(depth, proj), *sampling, transmit, holes), nonfinite


def scene_materials(scene):
    """{material name: description} of the rendered meshes' film materials (enabled or
    Principled), instances included; errors."""
    found = {}
    errors = {}
    for obj in _rendered_objects(scene):
        for slot in obj.material_slots:
            mat = slot.material
            if mat is None:
                continue
            mat = getattr(mat, "original", mat)
            if mat.name in found or mat.name in errors:
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
SUPERSAMPLE = cli_args.SUPERSAMPLE


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
    engine: str | None = None,
) -> dict:
    """Render the camera view with the thin-film shader; writes ``out_path`` (.png) and a .exr beside it.

    ``supersample``: samples per pixel along each axis (default :data:`SUPERSAMPLE`; lowered when
    the enlarged buffer would exceed the GPU's texture size), filtered with the scene's Cycles
    pixel filter; 1 draws one sample per pixel, unfiltered.

    ``engine`` ("EEVEE", "WORKBENCH", "CYCLES"): the rest of the scene is that engine's render
    (:func:`.background.render_background`, the films invisible to its camera) and the films
    are drawn over it, depth-tested per sample (:func:`.background.composite`); ``background``
    False makes its film transparent. None: Blender's Solid drawing and the World's panorama
    behind the films (the preview's look, what the tests' reference images hold).
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
        items = [item for item in items if not _hidden_in_render(item)]
    else:  # the artist's off switch holds for renders too: Blender's own drawing only
        items, messages = [], [OVERLAY_OFF]
    env = None
    lighting = scene_draw.CACHES.world
    if background and lighting is not None and lighting.environment is not None:
        env = lighting.background()  # the panorama the split sum was prefiltered from, turned and scaled
    space, region = _view3d_for_depth()

    film_objects = {item.name.split("/")[0] for item in items}

    def depth_from(offscreen):
        """Blender's Solid drawing of everything else, for depth and for the other objects.

        Thin-film objects and ``hide_render`` objects are hidden during it (film objects: drawn
        twice, Blender's and our vertex transforms round differently and the depth test would let
        the grey Solid surface speckle through). Instances of excluded collections are not in the
        view layer and cannot be hidden: they stay in this pass.
        """
        if space is None:
            return
        shading = space.shading
        saved = (shading.type, shading.light, shading.color_type)
        layer_objects = bpy.context.view_layer.objects  # instances from excluded collections are not
        hidden = [o for o in layer_objects if (o.name in film_objects or o.hide_render) and not o.hide_get()]
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

    if engine is None:
        rgba = render_offscreen(items, view, proj, frame_w, frame_h, background=env, depth_from=depth_from)
        rgba, nonfinite = _finite(rgba.astype(np.float64), messages)
        if factor > 1:
            rgba = pixel_filter.downsample(rgba, kind, filter_width, factor, pad)
    else:
        behind = render_background(
            scene,
            width,
            height,
            engine=engine,
            hidden=film_objects,
            shadowless=wall_objects(items),
            transparent=not background,
            margin=refraction_margin(items, width, height),
            world=lighting.background() if lighting is not None else None,
        )
        rgba, nonfinite = _films_over(
            behind, items, view, proj, (frame_w, frame_h), (kind, filter_width, factor, pad), messages
        )
    out = pathlib.Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    space = working_space()
    display.ocio()  # exposes Blender's bundled modules: OpenImageIO writes the EXR inside Blender
    image_io.write_exr(out.with_suffix(".exr"), rgba, image_io.CHROMATICITIES.get(space))
    display.save_png(out.with_suffix(".png"), rgba, scene)
    return {
        "png": str(out.with_suffix(".png")),
        "exr": str(out.with_suffix(".exr")),
        "size": [width, height],
        "supersample": factor,
        "pixel_filter": [kind, filter_width] if factor > 1 else None,
        "engine": engine or "SOLID",
        "objects": [item.name for item in items if not item.fallback],
        "fallback_objects": [item.name for item in items if item.fallback],
        "errors": errors,
        "world_errors": list(lighting.sh.errors) if lighting is not None else [],
        "nonfinite_pixels": nonfinite,
        "working_space": space,
        "view_transform": scene.view_settings.view_transform,
        "messages": messages,
        "seconds": time.perf_counter() - t0,
    }


def _finite(rgba, messages) -> tuple[np.ndarray, int]:
    """``rgba`` with non-finite samples set to 0 (counted in ``messages``), and their count."""
    bad = ~np.isfinite(rgba)
    count = int(bad.any(axis=-1).sum())
    if count:
        messages.append(f"{count} non-finite samples set to 0")
        rgba = np.where(bad, 0.0, rgba)
    return rgba, count


def _mathutils_matrix(m):
    return Matrix(np.asarray(m).tolist())


def main(argv) -> int:
    """The CLI behind ``blender -b file.blend -c thinfilm_sh …`` and scripts/thinfilm_headless.py.

    Exit codes (docs/cli-exit-codes.md): 0 done; 1 partial (a material or the World could not
    be evaluated and was replaced by its fallback, each reported); 2 refused before any work (a
    bad option, path, size or scene value, named); 3 internal error (traceback in the log file
    named); 4 an output could not be written. Never a traceback.
    """
    return cli_support.run(lambda: _main(argv), prog="thinfilm_sh")


def _main(argv) -> int:
    args = cli_args.parser().parse_args(argv)
    with cli_support.refusing():  # a scene, view layer, camera or frame that is not there: exit 2
        scene, layer = _chosen_scene(args)
    with tables.cache_dir_override(args.cache_dir), bpy.context.temp_override(scene=scene, view_layer=layer):
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
        if args.frame is not None:
            scene.frame_set(args.frame)
        return _run(args, scene, cache)


def _chosen_scene(args):
    """(scene, view layer) named by ``--scene`` / ``--view-layer`` (the context's by default);
    ``UsageError`` naming what exists when one is not there."""
    scene = bpy.context.scene
    if args.scene is not None:
        scene = bpy.data.scenes.get(args.scene)
        if scene is None:
            names = ", ".join(repr(s.name) for s in bpy.data.scenes)
            raise cli_support.UsageError(f"--scene: no scene {args.scene!r} in this file (it has {names})")
    layer = bpy.context.view_layer if scene == bpy.context.scene else scene.view_layers[0]
    if args.view_layer is not None:
        layer = scene.view_layers.get(args.view_layer)
        if layer is None:
            names = ", ".join(repr(v.name) for v in scene.view_layers)
            raise cli_support.UsageError(
                f"--view-layer: no view layer {args.view_layer!r} in scene {scene.name!r} (it has {names})"
            )
    return scene, layer


def _write_json(path, summary) -> None:
    table_io.write_bytes(path, json.dumps(summary, indent=2, allow_nan=False).encode("utf-8"))


def _run(args, scene, cache) -> int:
    """Run the parsed sub-command on ``scene``; returns the exit code."""
    if args.command == "bake":
        return _run_bake(args, scene, cache)
    if args.command == "render":
        return frames.run_render(args, scene, render_scene)
    return _run_plan(scene, cache)


def _run_bake(args, scene, cache) -> int:
    """`bake`: every visible thin-film material's table into the cache (and --out-dir)."""
    with cli_support.refusing():  # before any bake: a refusal is exit 2
        json_path = cli_support.output_file("--json", args.json) if args.json else None
        if args.out_dir:
            cli_support.output_dir("--out-dir", args.out_dir)
    summary = bake_scene(
        scene, args.out_dir, progress=(lambda _line: None) if args.quiet else print, cache=cache
    )
    if json_path is not None:
        json_path.parent.mkdir(parents=True, exist_ok=True)
        _write_json(json_path, summary)
    for err in summary["errors"].values():
        print(f"error: {err}", file=sys.stderr)
    return cli_support.EXIT_PARTIAL if summary["errors"] else cli_support.EXIT_OK


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
