"""The headless commands: ``bake``, ``render`` and ``plan`` (``blender -c thinfilm_sh …``).

``bake`` fills the table cache with every visible thin-film material's table (and ``--out-dir``
copies); ``render`` draws frames through :mod:`.frames` (each one :func:`.render.render_scene`);
``plan`` says what each material needs and costs, baking nothing. The materials are those of
the meshes the view layer renders, instances included (:func:`scene_materials`).

The table cache is the add-on's (:func:`..bakes.tables.table_cache`: ``THINFILM_SH_CACHE``, the
preference, the private default); every command takes ``--cache-dir`` to name another. An
unusable cache folder or a write that fails (a full disk) is an ``error: …`` line and exit
status 2, never a traceback; a table that could not be saved to the cache is still used.
"""

from __future__ import annotations

import json
import sys
import time

import bpy

from ...precompute.commands import cli_support
from ...precompute.effects import plan_text, plans
from ...precompute.tables import atomic_write, table_io
from ..bakes import tables
from ..materials.description import description, description_key, warnings
from ..world import world
from . import cli_args, frames


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
    a file of its own, named by :func:`precompute.commands.cli_support.unique_file_names` (``Mat 001``,
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
                atomic_write.check_destination(path)
            except atomic_write.TableWriteError as exc:
                raise cli_support.UsageError(f"--out-dir: {exc}") from None
    shared: dict[str, str] = {}
    for i, (name, desc) in enumerate(sorted(found.items())):
        key = description_key(desc)
        t0 = time.perf_counter()
        try:
            result, source = tables.get_table_with_source(desc, cache)
        except Exception as exc:  # isolated: the other materials are still baked
            errors[name] = tables.bake_failure(name, exc)
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
    atomic_write.write_bytes(path, json.dumps(summary, indent=2, allow_nan=False).encode("utf-8"))


def _run(args, scene, cache) -> int:
    """Run the parsed sub-command on ``scene``; returns the exit code."""
    if args.command == "bake":
        return _run_bake(args, scene, cache)
    if args.command == "render":
        return frames.run_render(args, scene)
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
    plan = plans.scene_plan(found, coeffs, cached=cached)
    print(plan_text.format_plan(plan))
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
