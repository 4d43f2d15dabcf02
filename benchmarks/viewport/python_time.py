"""The CPU side: Python time per frame of the draw callback, and the batch rebuild after an edit."""

from __future__ import annotations

import time

import numpy as np

from .config import HEADLINE_L, OBJECT_COUNTS, PYTHON_FRAMES, TRIANGLES
from .frames import Frame, median_ms, plain_items
from .measure import prepare_scene
from .scene import Scene


def python_time(scene: Scene, quick: bool, baseline=None, log=print) -> list[dict]:
    """Per-frame CPU work in this (Python) thread with nothing changed, by triangle count.

    ``collect``: ``scene_draw.collect`` as the draw callback calls it. ``prepare``:
    ``gpu.draw.prepare_draw`` (matrices → uniform buffers, variants, grouping). ``submit``:
    ``gpu.draw.submit`` (state, binds, draw calls); on llvmpipe this includes the driver's vertex
    processing, which runs in the calling thread, so it is listed but is not Python work.
    Thread CPU time (``time.thread_time``), median of ``runs`` frames after 3 warm-up frames.
    With a ``baseline`` module its ``draw_items`` is timed in the same frames (after ours).
    """
    import bpy
    import gpu

    gd, sd = scene.ext.gpu, scene.ext.scene_draw
    runs = 5 if quick else PYTHON_FRAMES
    rows = []
    w, h = 320, 180  # small: the fragment work does not matter here
    counts, tris = ((1, 100), (10_000, 100_000)) if quick else (OBJECT_COUNTS, TRIANGLES)
    cases = [(n, t, False) for n in counts for t in tris]
    cases.append((100, 10_000, True))  # 100 objects, each its own material
    for objects, triangles, distinct in cases:
        prepare_scene(scene, objects, triangles, HEADLINE_L, distinct=distinct)
        frame = Frame(scene, w, h)
        depsgraph = bpy.context.evaluated_depsgraph_get()
        samples = {"collect": [], "prepare": [], "submit": [], "baseline": []}
        counters = {}
        try:
            with frame.offscreen.bind():
                fb = gpu.state.active_framebuffer_get()
                for k in range(runs + 3):
                    if k == 3:  # warm: count from here
                        counters = {
                            "rebuilt": sd.CACHES.stats["batch_builds"],
                            "compiled": gd.shaders.SHADERS.compile_count,
                            "ubo_allocations": gd.draw.UNIFORMS.stats["allocations"],
                            "ubo_uploads": gd.draw.UNIFORMS.stats["uploads"],
                        }
                    fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
                    t0 = time.thread_time()
                    items, _ = sd.collect(depsgraph, allow_bake=False, allow_world=False)
                    t1 = time.thread_time()
                    prepared = gd.draw.prepare_draw(items, frame.view, frame.proj, display_srgb=True)
                    t2 = time.thread_time()
                    gd.draw.submit(prepared)
                    t3 = time.thread_time()
                    frame._finish()
                    if baseline is not None:
                        plain = plain_items(items)
                        fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
                        t4 = time.thread_time()
                        baseline.draw_items(plain, frame.view, frame.proj, display_srgb=True)
                        t5 = time.thread_time()
                        frame._finish()
                        samples["baseline"].append(t5 - t4)
                    if k >= 3:
                        samples["collect"].append(t1 - t0)
                        samples["prepare"].append(t2 - t1)
                        samples["submit"].append(t3 - t2)
            # The same Python work back to back, nothing drawn in between (caches stay warm).
            samples["collect_alone"], samples["prepare_alone"] = [], []
            for k in range(runs + 3):
                t0 = time.thread_time()
                items, _ = sd.collect(depsgraph, allow_bake=False, allow_world=False)
                t1 = time.thread_time()
                gd.draw.prepare_draw(items, frame.view, frame.proj, display_srgb=True)
                t2 = time.thread_time()
                if k >= 3:
                    samples["collect_alone"].append(t1 - t0)
                    samples["prepare_alone"].append(t2 - t1)
        finally:
            frame.free()
        row = {"objects": objects, "triangles": scene.triangles, "materials": objects if distinct else 1}
        row.update({k: median_ms(v) for k, v in samples.items() if v})
        row["rebuilt"] = sd.CACHES.stats["batch_builds"] - counters["rebuilt"]
        row["compiled"] = gd.shaders.SHADERS.compile_count - counters["compiled"]
        row["ubo_allocations"] = gd.draw.UNIFORMS.stats["allocations"] - counters["ubo_allocations"]
        row["ubo_uploads"] = gd.draw.UNIFORMS.stats["uploads"] - counters["ubo_uploads"]
        rows.append(row)
        if distinct:
            scene.assign(HEADLINE_L)  # back to the one shared material
        log(
            f"  {objects:3d} objects ({row['materials']} mat) {scene.triangles:>9,} tris:"
            f" collect {row['collect']:.3f} ms,"
            f" prepare {row['prepare']:.3f} ms, submit {row['submit']:.3f} ms; back to back: collect"
            f" {row['collect_alone']:.3f} ms, prepare {row['prepare_alone']:.3f} ms"
            + (f", baseline draw_items {row['baseline']:.3f} ms" if "baseline" in row else "")
            + f" (batches rebuilt {row['rebuilt']}, shaders compiled {row['compiled']},"
            f" uniform buffers allocated {row['ubo_allocations']} / updated {row['ubo_uploads']})"
        )
    return rows


def rebuild_time(scene: Scene, quick: bool, log=print) -> list[dict]:
    """Time to rebuild a batch after an edit: one vertex of one torus moved.

    The edit goes through Blender as a user's would (``foreach_set`` on the mesh, ``update``,
    the depsgraph's update handlers mark the object), then ``scene_draw.collect`` rebuilds that
    object's batch. Listed beside: Blender's own depsgraph update for the edit, and the first
    Workbench frame after it (Workbench re-extracts its batches of the mesh) against a steady one.
    """
    import bpy

    sd = scene.ext.scene_draw
    rows = []
    for triangles in (10_000, 100_000) if quick else TRIANGLES:
        repeats = 1 if quick else (2 if triangles >= 1_000_000 else 3)
        prepare_scene(scene, 1, triangles, HEADLINE_L)
        obj = scene.objects[0]
        mesh = obj.data
        co = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
        mesh.vertices.foreach_get("co", co)
        frame = Frame(scene, 320, 180)
        samples = {"depsgraph": [], "collect": [], "workbench_first": [], "workbench_steady": []}
        builds_before = sd.CACHES.stats["batch_builds"]
        try:
            frame.workbench()
            for k in range(repeats):
                co[2] += 1e-3 * (1 if k % 2 == 0 else -1)
                mesh.vertices.foreach_set("co", co)
                mesh.update()
                t0 = time.perf_counter()
                bpy.context.view_layer.update()
                t1 = time.perf_counter()
                sd.collect(bpy.context.evaluated_depsgraph_get(), allow_bake=False, allow_world=False)
                t2 = time.perf_counter()
                frame.workbench()
                t3 = time.perf_counter()
                frame.workbench()
                t4 = time.perf_counter()
                samples["depsgraph"].append(t1 - t0)
                samples["collect"].append(t2 - t1)
                samples["workbench_first"].append(t3 - t2)
                samples["workbench_steady"].append(t4 - t3)
        finally:
            frame.free()
        row = {"triangles": scene.triangles, **{k: median_ms(v) for k, v in samples.items()}}
        row["builds"] = sd.CACHES.stats["batch_builds"] - builds_before
        row["repeats"] = repeats
        rows.append(row)
        log(
            f"  {scene.triangles:>9,} tris: rebuild (collect) {row['collect']:.1f} ms,"
            f" depsgraph {row['depsgraph']:.1f} ms, Workbench first frame {row['workbench_first']:.1f} ms"
            f" vs {row['workbench_steady']:.1f} ms next ({row['builds']} builds in {repeats} edits)"
        )
    return rows
