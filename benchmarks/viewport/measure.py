"""The GPU-time measurements: the grid of scenes, the order sweep, split sum vs SH, automatic orders."""

from __future__ import annotations

from dataclasses import replace

from .config import (
    AUTOMATIC_ROUGHNESS,
    CELLS_4K,
    HEADLINE_L,
    OBJECT_COUNTS,
    RESOLUTIONS,
    SPLIT_SUM_L,
    SWEEP_L,
    SWEEP_SCENE,
    TRIANGLES,
    roughness_cases,
)
from .frames import Frame, drawing, film_coverage, interleaved, median_ms, plain_items, repeats_for
from .scene import Scene


# ----------------------------------------------------------------------------------------------
# Measurements
# ----------------------------------------------------------------------------------------------
def frame_cell(scene: Scene, res: str, repeats: int, cases=None, baseline=None) -> dict:
    """Workbench and our frame times of the current scene at ``res``; ``cases`` adds item hooks."""
    width, height = RESOLUTIONS[res]
    frame = Frame(scene, width, height)
    try:
        draws = {"workbench": frame.workbench, "ours": frame.ours}
        for name, hook in (cases or {}).items():
            draws[name] = lambda hook=hook: frame.ours(items_hook=hook)
        if baseline is not None:
            draws["baseline"] = lambda: frame.ours(items_hook=plain_items, draw_module=baseline)
        times = interleaved(draws, repeats)
        out = {name: median_ms(t) for name, t in times.items()}
        out["times"] = times
        out["coverage"] = frame.coverage()
        frame.workbench()
        out["workbench_static"] = median_ms(interleaved({"static": frame.workbench_static}, 3, 0)["static"])
        return out
    finally:
        frame.free()


def prepare_scene(
    scene: Scene, objects: int, triangles: int, l_max: int, case: str = "sh", distinct: bool = False
) -> None:
    import bpy

    scene.set_objects(objects, triangles)
    scene.assign(l_max, case, distinct)
    sd = scene.ext.scene_draw
    depsgraph = bpy.context.evaluated_depsgraph_get()
    items, messages = sd.collect(depsgraph)  # bakes (or loads) the table, renders the World once
    if len(items) != objects:
        raise RuntimeError(f"expected {objects} draw items, got {len(items)}: {messages}")


def grid(scene: Scene, quick: bool, baseline=None, log=print) -> list[dict]:
    """Objects × triangles × resolution at the headline order."""
    rows = []
    counts = (1, 10) if quick else OBJECT_COUNTS
    tris = (10_000,) if quick else TRIANGLES
    resolutions = ("720p",) if quick else tuple(RESOLUTIONS)
    for objects in counts:
        for triangles in tris:
            prepare_scene(scene, objects, triangles, HEADLINE_L)
            for res in resolutions:
                if res == "4K" and (objects, triangles) not in CELLS_4K:
                    continue
                w, h = RESOLUTIONS[res]
                base = baseline if res == "1080p" or quick else None  # before/after at 1080p only
                cell = frame_cell(scene, res, repeats_for(w, h, triangles, quick), baseline=base)
                row = {"objects": objects, "triangles": scene.triangles, "res": res, **cell}
                rows.append(row)
                log(
                    f"  l={HEADLINE_L} {objects:3d} objects {scene.triangles:>9,} tris {res:>5}:"
                    f" Workbench {cell['workbench']:7.1f} ms, ours {cell['ours']:7.1f} ms"
                    f" ({cell['ours'] / cell['workbench']:.2f}×)"
                    + (f", baseline {cell['baseline']:7.1f} ms" if "baseline" in cell else "")
                )
    return rows


def order_sweep(scene: Scene, quick: bool, baseline=None, orders=None, log=print) -> list[dict]:
    objects, triangles = (1, 10_000) if quick else SWEEP_SCENE
    res = "720p" if quick else "1080p"
    rows = []
    for l_max in orders or ((1, 2) if quick else SWEEP_L):
        prepare_scene(scene, objects, triangles, l_max)
        w, h = RESOLUTIONS[res]
        cell = frame_cell(scene, res, repeats_for(w, h, triangles, quick), baseline=baseline)
        rows.append({"l_max": l_max, "objects": objects, "triangles": scene.triangles, "res": res, **cell})
        log(
            f"  l_max = {l_max} {res}: Workbench {cell['workbench']:7.1f} ms,"
            f" ours {cell['ours']:7.1f} ms ({cell['ours'] / cell['workbench']:.2f}×)"
            + (f", baseline {cell['baseline']:7.1f} ms" if "baseline" in cell else "")
        )
    return rows


def split_sum(scene: Scene, quick: bool, log=print) -> list[dict]:
    """SH-only vs combined (split sum + SH) vs split-sum-only films, same scene, same frame size.

    The three films differ only in roughness (:func:`roughness_cases`); their draw items are
    collected once each and swapped in after the per-frame ``collect`` (which still runs on the
    SH-only film, so every frame pays the same Python work).
    """
    objects, triangles = (1, 10_000) if quick else SWEEP_SCENE
    res = "720p" if quick else "1080p"
    w, h = RESOLUTIONS[res]
    rows = []
    rough = roughness_cases()
    for l_max in (2,) if quick else SPLIT_SUM_L:
        frame = None
        try:
            stored = {}
            for lamps in (False, True):  # the product's default (lamps on) is collected last
                for case in ("combined", "split", "sh"):
                    scene.material(l_max, case).thinfilm_sh.world_lamps = lamps
                    prepare_scene(scene, objects, triangles, l_max, case)
                    if frame is None:
                        frame = Frame(scene, w, h)
                    stored[case if lamps else case + "_nolamps"] = frame.items()
            # The combined film drawn by SH alone (its own table and lighting, no prefiltered
            # World: the SH variant): the split sum's own cost, with the film's table the same.
            stored["sh_same"] = [replace(it, prefiltered=None, sh_weight=1.0) for it in stored["combined"]]
            stored["sh_same_nolamps"] = [
                replace(it, prefiltered=None, sh_weight=1.0) for it in stored["combined_nolamps"]
            ]
            draws = {
                "workbench": frame.workbench,
                "sh": frame.ours,
                "sh_same": drawing(frame, stored["sh_same"]),
                "sh_same_nolamps": drawing(frame, stored["sh_same_nolamps"]),
                "combined": drawing(frame, stored["combined"]),
                "split": drawing(frame, stored["split"]),
                "sh_nolamps": drawing(frame, stored["sh_nolamps"]),
                "combined_nolamps": drawing(frame, stored["combined_nolamps"]),
                "split_nolamps": drawing(frame, stored["split_nolamps"]),
            }
            times = interleaved(draws, repeats_for(w, h, triangles, quick) + (0 if quick else 2))
        finally:
            if frame is not None:
                frame.free()
        cell = {name: median_ms(t) for name, t in times.items()}
        cell.update(l_max=l_max, res=res, triangles=scene.triangles, objects=objects)
        cell["weights"] = {c: float(stored[c][0].sh_weight) for c in rough}
        cell["table_ubo"] = {c: stored[c][0].table.ubo is not None for c in rough}
        cell["view_samples"] = {c: int(stored[c][0].table.view_samples) for c in rough}
        cell["split_used"] = {c: stored[c][0].prefiltered is not None for c in rough}
        cell["lamps"] = {c: stored[c][0].lighting.lamp_count for c in rough}
        cell["lamps_off"] = {c: stored[c + "_nolamps"][0].lighting.lamp_count for c in rough}
        rows.append(cell)
        log(
            f"  l={l_max}: SH only {cell['sh']:.1f} ms, combined {cell['combined']:.1f} ms"
            f" ({cell['combined'] / cell['sh']:.2f}×), split only {cell['split']:.1f} ms"
            f" ({cell['split'] / cell['sh']:.2f}×); World lamps off: SH only {cell['sh_nolamps']:.1f} ms,"
            f" combined {cell['combined_nolamps']:.1f} ms"
            f" ({cell['combined_nolamps'] / cell['sh_nolamps']:.2f}×),"
            f" split only {cell['split_nolamps']:.1f} ms ({cell['split_nolamps'] / cell['sh_nolamps']:.2f}×)"
        )
        log(
            f"  l={l_max}, the combined film by SH alone: {cell['sh_same']:.1f} ms, combined ÷ that"
            f" {cell['combined'] / cell['sh_same']:.2f}×; World lamps off: {cell['sh_same_nolamps']:.1f} ms,"
            f" {cell['combined_nolamps'] / cell['sh_same_nolamps']:.2f}×"
        )
    return rows


def automatic_orders(scene: Scene, quick: bool, log=print, per_pixel: bool = True) -> list[dict]:
    """Glossy, medium and rough films at their automatic SH order, per covered pixel.

    The product's draw (a constant-thickness film's SH half from its outgoing-radiance grid,
    policy.uses_grid) against the same items drawn with the per-pixel SH (``grid`` removed), on
    the order sweep's scene. Each film is collected once (the bake, the World and the grid are
    made there) and swapped in after the per-frame ``collect``, as :func:`split_sum` does.
    """
    import bpy

    objects, triangles = (1, 10_000) if quick else SWEEP_SCENE
    res = "720p" if quick else "1080p"
    w, h = RESOLUTIONS[res]
    scene.set_objects(objects, triangles)
    stored, facts = {}, {}
    frame = None
    try:
        for case, rough in AUTOMATIC_ROUGHNESS.items():
            mat = scene.automatic_film(case)
            scene.materials[("auto", case)] = mat
            for obj in scene.objects:
                obj.data.materials.clear()
                obj.data.materials.append(mat)
            bpy.context.view_layer.update()
            items, messages = scene.ext.scene_draw.collect(bpy.context.evaluated_depsgraph_get())
            if len(items) != objects:
                raise RuntimeError(f"expected {objects} draw items, got {len(items)}: {messages}")
            if frame is None:
                frame = Frame(scene, w, h)
            stored[case] = items
            if per_pixel:  # the l = 12 frames dominate the run's time (seconds each on llvmpipe)
                stored[case + "_per_pixel"] = [replace(it, grid=None) for it in items]
            facts[case] = {
                "roughness": rough,
                "l_max": int(items[0].table.l_max),
                "sh_weight": float(items[0].sh_weight),
                "grid": items[0].grid is not None,
            }
        draws = {"workbench": frame.workbench}
        for name, items in stored.items():
            draws[name] = drawing(frame, items)
        coverage = {}
        for case in AUTOMATIC_ROUGHNESS:  # the same tori: one coverage, measured per film anyway
            coverage[case] = film_coverage(frame, stored[case])
        times = interleaved(draws, repeats_for(w, h, triangles, quick) + (0 if quick else 2))
    finally:
        if frame is not None:
            frame.free()
    cell = {name: median_ms(t) for name, t in times.items()}
    rows = []
    pixels = w * h
    glossy = cell["glossy"] / (coverage["glossy"] * pixels)
    for case in AUTOMATIC_ROUGHNESS:
        row = dict(facts[case], case=case, res=res, objects=objects, triangles=scene.triangles)
        row.update(
            ms=cell[case], ms_per_pixel=cell.get(case + "_per_pixel", float("nan")), coverage=coverage[case]
        )
        row["ns_per_covered_pixel"] = 1e6 * cell[case] / (coverage[case] * pixels)
        row["ratio_to_glossy"] = row["ns_per_covered_pixel"] / (1e6 * glossy)
        row["workbench"] = cell["workbench"]
        rows.append(row)
        log(
            f"  {case} (r = {row['roughness']}, l_max {row['l_max']}, SH weight {row['sh_weight']:.2f},"
            f" grid {row['grid']}): {row['ms']:.1f} ms ({row['ratio_to_glossy']:.2f}× glossy per covered"
            f" pixel); per-pixel SH {row['ms_per_pixel']:.1f} ms; coverage {100 * row['coverage']:.1f} %"
        )
    return rows
