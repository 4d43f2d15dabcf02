"""``prepare`` (bpy): record every case at full size into OUTDIR, with Blender's own GLSL where bpy
runs on OpenGL."""

from __future__ import annotations

import hashlib
import json
import time
from pathlib import Path

import bpy  # noqa: F401 (gpu is importable once bpy is)
import gpu

from .. import common
from .config import FORMAT_VERSION, REFERENCE_ROTATION, RESOLUTION, ROOT, SCENES
from .gl import GLSources
from .record import Writer, record_cases, source_key


def _blender_sources(gd, variants: dict, sources: dict, log) -> None:
    """Add each variant's GLSL as Blender compiled it (``blender_vertex`` / ``blender_fragment``)."""
    if gpu.platform.backend_type_get() != "OPENGL":
        log(f"  Blender's own GLSL: not read back (backend {gpu.platform.backend_type_get()})")
        return
    reader = GLSources()
    for name, entry in variants.items():
        reference = None if entry.get("generated_x90", True) else REFERENCE_ROTATION
        cache = gd.shaders.ShaderCache(reference_rotation=reference)
        fields = entry["variant"]
        got = reader.during(lambda fields=fields, cache=cache: cache.get(**fields))
        if got is None:
            log(f"  Blender's own GLSL of {name}: not found among the driver's shader objects")
            continue
        entry["blender_vertex"] = source_key(sources, got["vertex"])
        entry["blender_fragment"] = source_key(sources, got["fragment"])


def prepare(outdir, log=print) -> dict:
    """Record every case at :data:`RESOLUTION` into ``outdir``; returns the manifest."""
    started = time.perf_counter()
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    writer = None
    cases = []
    ext = None
    for meta, items, view, proj, capture, ext in record_cases(RESOLUTION, log):
        writer = writer or Writer(capture)
        gd = ext.gpu
        shaders = capture.loop_shaders if meta.get("loops") else capture.shaders
        prepared = gd.draw.prepare_draw(
            items, view, proj, display_srgb=True, shaders=shaders, uniforms=capture.uniforms
        )
        cases.append(writer.case(prepared, items, meta, gd))
        log(
            f"  {meta['id']}: {len(items)} items, {prepared.draw_count} draws,"
            f" {len(prepared.groups)} group(s),"
            f" variant {cases[-1]['groups'][0]['variant']}, sh_weight {meta['sh_weight']:.2f},"
            f" lamps {meta['lamp_count']}"
        )
    capture = writer.capture
    _blender_sources(ext.gpu, capture.variants, capture.sources, log)
    manifest = {
        "format": FORMAT_VERSION,
        "resolution": list(RESOLUTION),
        "created": time.strftime("%Y-%m-%d %H:%M:%S"),
        "code": _code_state(),
        "source_digest": source_digest(),
        "prepared_on": f"{gpu.platform.renderer_get()} ({gpu.platform.backend_type_get()})",
        "scenes": {k: {"layout": list(v["layout"]), "l_max": list(v["l_max"])} for k, v in SCENES.items()},
        "variants": capture.variants,
        "meshes": writer.meshes,
        "cases": cases,
    }
    manifest["arrays"] = writer.store.save(outdir / "arrays.npz")
    (outdir / "sources.json").write_text(json.dumps(capture.sources, indent=0), encoding="utf-8")
    (outdir / "manifest.json").write_text(json.dumps(manifest, indent=1), encoding="utf-8")
    total = sum(p.stat().st_size for p in outdir.iterdir() if p.is_file())
    log(
        f"{len(cases)} cases, {len(capture.variants)} variants, {len(writer.meshes)} meshes,"
        f" {len(writer.store.arrays)} arrays: {total / 2**20:.1f} MiB in {outdir}"
        f" ({time.perf_counter() - started:.0f} s)"
    )
    return manifest


def _code_state() -> str:
    """The revision ``prepare`` records from (``common.git_describe`` of the drawing code)."""
    return common.git_describe(("addon", "glsl", "precompute"))


def source_digest() -> str:
    """sha256 over the extension's drawing code (addon/**/*.py, glsl/*.glsl, precompute/**/*.py):
    ``check`` compares it with the one ``prepare`` recorded."""
    h = hashlib.sha256()
    for pattern in ("addon/**/*.py", "glsl/*.glsl", "precompute/**/*.py"):
        for path in sorted(ROOT.glob(pattern)):
            h.update(path.relative_to(ROOT).as_posix().encode() + b"\0" + path.read_bytes())
    return h.hexdigest()
