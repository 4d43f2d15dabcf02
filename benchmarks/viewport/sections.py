"""The report's sections: the grid, the order sweep, split sum, Python time, rebuild, automatic orders."""

from __future__ import annotations

from .config import HEADLINE_L, PYTHON_FRAMES, RESOLUTIONS


def fmt_fps(ms: float) -> str:
    """Frames per second of a frame time in ms."""
    return f"{1e3 / ms:.1f}" if ms > 0 else "—"


def fmt_objects(n: int) -> str:
    return f"{n} object" if n == 1 else f"{n} objects"


def fmt_tri(n: int) -> str:
    return f"{n / 1e6:.2f} M" if n >= 1_000_000 else f"{n / 1e3:.0f} k"


def _grid_section(res: dict) -> list[str]:
    rows = res.get("grid")
    if not rows:
        return []
    resolutions = [r for r in RESOLUTIONS if any(x["res"] == r for x in rows)]
    out = [
        f"## Frame time at l_max = {HEADLINE_L}: objects × triangles × resolution",
        "",
        "Median frame time in ms, Workbench / ours, and the ratio ours ÷ Workbench.",
        "",
        "| objects | triangles | " + " | ".join(f"{r} WB | {r} ours | {r} ratio" for r in resolutions) + " |",
        "|---|---|" + "---|---|---|" * len(resolutions),
    ]
    keys = sorted({(r["objects"], r["triangles"]) for r in rows})
    for objects, tris in keys:
        cells = []
        for res_name in resolutions:
            c = next(
                (r for r in rows if (r["objects"], r["triangles"], r["res"]) == (objects, tris, res_name)),
                None,
            )
            if c is None:
                cells += ["—"] * 3
            else:
                cells += [f"{c['workbench']:.0f}", f"{c['ours']:.0f}", f"{c['ours'] / c['workbench']:.2f}×"]
        out.append(f"| {objects} | {fmt_tri(tris)} | " + " | ".join(cells) + " |")
    cov = [r["coverage"] for r in rows]
    out += ["", f"The films cover {100 * min(cov):.0f}–{100 * max(cov):.0f} % of the frame.", ""]
    slopes = []
    for res_name in resolutions:
        cells = sorted(
            (r for r in rows if r["res"] == res_name and r["objects"] == 1), key=lambda r: r["triangles"]
        )
        if len(cells) >= 2 and cells[-1]["triangles"] > cells[0]["triangles"]:
            per_m = 1e6 / (cells[-1]["triangles"] - cells[0]["triangles"])
            wb = (cells[-1]["workbench"] - cells[0]["workbench"]) * per_m
            ours = (cells[-1]["ours"] - cells[0]["ours"]) * per_m
            slopes.append(f"{res_name}: Workbench {wb:+.0f} ms, ours {ours:+.0f} ms")
    if slopes:
        out.append(
            "Per extra million triangles (1 object, from the smallest to the largest mesh): "
            + "; ".join(slopes)
            + ". On llvmpipe a Workbench frame that draws the scene is expensive in both pixels and"
            " triangles: it runs several full-screen passes (depth/G-buffer prepass, studio lighting,"
            " object outline, anti-aliasing) and its geometry costs far more per triangle than ours here."
            " On a GPU the balance is different (those passes are cheap there, our per-pixel SH work is"
            " not), so these ratios do not carry over to GPUs."
        )
        out.append("")
    for res_name in resolutions:
        static = [r["workbench_static"] for r in rows if r["res"] == res_name and "workbench_static" in r]
        if static:
            out.append(
                f"`WB static` at {res_name} (`draw_view3d` with nothing changed since the previous call, a"
                f" re-display): {min(static):.0f}–{max(static):.0f} ms, whatever the triangle count."
            )
            out.append("")
    if any("baseline" in r for r in rows):
        out += ["", f"Baseline revision ({res.get('baseline')}), drawn in the same rounds, 1080p:", ""]
        out += ["| objects | triangles | baseline ms | ours ms | ours ÷ baseline |", "|---|---|---|---|---|"]
        for r in rows:
            if r["res"] == "1080p" and "baseline" in r:
                out.append(
                    f"| {r['objects']} | {fmt_tri(r['triangles'])} | {r['baseline']:.0f} | {r['ours']:.0f} |"
                    f" {r['ours'] / r['baseline']:.2f}× |"
                )
    return out + [""]


def _sweep_section(res: dict) -> list[str]:
    rows = res.get("sweep")
    if not rows:
        return []
    r0 = rows[0]
    base = any("baseline" in r for r in rows)
    out = [
        "## Every l_max",
        "",
        f"{r0['objects']} objects, {fmt_tri(r0['triangles'])} triangles, {r0['res']}."
        f" The headline is l_max = {HEADLINE_L}.",
        "",
        "| l_max | Workbench ms | ours ms | ours fps | ratio |" + (" baseline ms |" if base else ""),
        "|---|---|---|---|---|" + ("---|" if base else ""),
    ]
    for r in rows:
        mark = " **(headline)**" if r["l_max"] == HEADLINE_L else ""
        out.append(
            f"| {r['l_max']}{mark} | {r['workbench']:.0f} | {r['ours']:.0f} |"
            f" {fmt_fps(r['ours'])} | {r['ours'] / r['workbench']:.2f}× |"
            + (f" {r['baseline']:.0f} |" if base else "")
        )
    return out + [""]


def _split_sum_section(res: dict) -> list[str]:
    rows = res.get("split_sum")
    if not rows:
        return []
    rough = res["roughness"]
    r0 = rows[0]
    w = r0["weights"]
    out = [
        "## Split sum (combined path) against SH only",
        "",
        f"{r0['objects']} objects, {fmt_tri(r0['triangles'])} triangles, {r0['res']}. The same film at three"
        f" roughnesses: SH only (roughness {rough['sh']:g}, `sh_weight` {w['sh']:.2f}: the SH variant),"
        f" combined (roughness {rough['combined']:g}, `sh_weight` {w['combined']:.2f}: the `TF_SPLIT_SUM`"
        " variant runs both the prefiltered lookup and the SH sum) and split sum only (roughness"
        f" {rough['split']:g}, `sh_weight` {w['split']:.2f}: the `TF_SPLIT_ONLY` variant, no SH half)."
        " The prefiltered World is a 3-D texture, radiance and direction-moment levels"
        " (`gpu.resources.PrefilterTexture`); the combined film reads the moment (a second fetch) from"
        " l = 6 on, split-only films always (`prefilter.uses_moment`, `TF_MOMENT`). Each film is drawn"
        " twice: as the product draws it, with the"
        f" World's lamps shaded per light direction ({r0.get('lamps', {}).get('sh', 0)} lamps in this"
        " World: every variant adds the lamp loop, `glsl/tf_lamps.glsl`), and with the material's"
        ' "World Lamps" off (no lamp loop; the SH and prefilter then hold the whole World).'
        " Median frame, ms, all in the same interleaved rounds.",
        "",
        "| l | Workbench | SH only | combined | combined ÷ SH only | split only | split only ÷ SH only"
        " | lamps off: SH only | combined | combined ÷ SH only | split only | split only ÷ SH only |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        off = ""
        if "sh_nolamps" in r:
            off = (
                f" {r['sh_nolamps']:.0f} | {r['combined_nolamps']:.0f} |"
                f" **{r['combined_nolamps'] / r['sh_nolamps']:.2f}×** | {r['split_nolamps']:.0f} |"
                f" {r['split_nolamps'] / r['sh_nolamps']:.2f}× |"
            )
        else:
            off = " — | — | — | — | — |"
        out.append(
            f"| {r['l_max']} | {r['workbench']:.0f} | {r['sh']:.0f} | {r['combined']:.0f} |"
            f" **{r['combined'] / r['sh']:.2f}×** | {r['split']:.0f} | {r['split'] / r['sh']:.2f}× |" + off
        )
    if all("sh_same" in r for r in rows):
        vs = r0.get("view_samples", {})
        out += [
            "",
            "The SH-only film above is another material (rougher, so its bake has"
            f" {vs.get('sh', '?')} view angles against the combined film's {vs.get('combined', '?')}),"
            " and its table can sit in the uniform buffer where the combined film's does not"
            " (`TF_TABLE_UBO`, 16 KiB: spectral tables of l ≤ 5 at 16 angles, l ≤ 3 at 32). The"
            " split sum's own cost is the combined film drawn both ways, same table, same lighting:"
            " by SH alone (its draw items with no prefiltered World, so the SH variant) and as the"
            " product draws it.",
            "",
            "| l | table in UBO (SH only / combined film) | combined film by SH alone | combined |"
            " combined ÷ SH alone | lamps off: by SH alone | combined | combined ÷ SH alone |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for r in rows:
            u = r.get("table_ubo", {})
            flags = f"{'yes' if u.get('sh') else 'no'} / {'yes' if u.get('combined') else 'no'}" if u else "—"
            out.append(
                f"| {r['l_max']} | {flags} | {r['sh_same']:.0f} | {r['combined']:.0f} |"
                f" **{r['combined'] / r['sh_same']:.2f}×** | {r['sh_same_nolamps']:.0f} |"
                f" {r['combined_nolamps']:.0f} | **{r['combined_nolamps'] / r['sh_same_nolamps']:.2f}×** |"
            )
    same = [abs(r["split"] / r["combined"] - 1.0) < 0.05 for r in rows]
    if all(same):
        out += [
            "",
            "Split sum only costs as much as combined (within 5 % at every l): the SH half was not"
            " saved for `sh_weight` = 0.",
        ]
    else:
        out += [
            "",
            "Split sum only draws the `TF_SPLIT_ONLY` variant (`gpu.draw.prepare_draw` picks it for"
            " `sh_weight` = 0), which compiles the SH half out; a run-time branch on the weight did"
            " not save it on llvmpipe (split only then cost as much as combined, within 5 %). Glossy"
            " films (roughness ≤ 0.2) are drawn this way.",
        ]
    return out + [""]


def _object_table(rows: list[dict], counts, keys) -> list[str]:
    """Table rows, one per triangle count: ``keys`` (ms) for each object count, "—" where missing."""
    out = []
    for tris in sorted({round(r["triangles"], -4) for r in rows}):
        cells, label = [], None
        for n in counts:
            c = next((r for r in rows if r["objects"] == n and round(r["triangles"], -4) == tris), None)
            if c is None or any(k not in c for k in keys):
                cells += ["—"] * len(keys)
                continue
            label = label or fmt_tri(c["triangles"])
            cells += [f"{c[k]:.2f}" for k in keys]
        out.append(f"| {label} | " + " | ".join(cells) + " |")
    return out


def _python_section(res: dict) -> list[str]:
    rows = [r for r in res.get("python", []) if r["materials"] == 1]
    if not rows:
        return []
    counts = sorted({r["objects"] for r in rows})
    out = [
        "## Python time per frame, nothing changed",
        "",
        f"CPU time of the drawing thread (`time.thread_time`), median of {PYTHON_FRAMES} frames at l ≤ 2,"
        " one shared"
        " material: `collect` = `scene_draw.collect` (depsgraph → draw items; caches warm), `prepare` ="
        " `gpu.draw.prepare_draw` (uniform buffers, variants, grouping), `submit` = `gpu.draw.submit`"
        " (state, binds, draw calls). On llvmpipe `submit` also contains the driver's vertex shading and"
        " binning, which run in the calling thread, so it grows with the triangles; on a GPU that work"
        " is the GPU's. The Python work is `collect` + `prepare`; it depends on the number of objects"
        " (and materials), not on their triangles.",
        "",
        "| triangles | " + " | ".join(f"{n} obj: collect ms | prepare ms | submit ms" for n in counts) + " |",
        "|---|" + "---|---|---|" * len(counts),
    ]
    out += _object_table(rows, counts, ("collect", "prepare", "submit"))
    out += [
        "",
        "The step from 10 k to 100 k triangles in `collect` is not work done per triangle: the same calls"
        " back to back, with nothing drawn in between, take the same time at every triangle count"
        " (below). Between them, llvmpipe's vertex processing runs on the same CPU and evicts the"
        " interpreter's data from the caches, so the next `collect` runs colder; the more geometry,"
        " the colder, until the caches are fully replaced (from 100 k triangles on here).",
        "",
        "| triangles | " + " | ".join(f"{n} obj: collect ms | prepare ms" for n in counts) + " |",
        "|---|" + "---|---|" * len(counts),
    ]
    out += _object_table(rows, counts, ("collect_alone", "prepare_alone"))
    distinct = [r for r in res.get("python", []) if r["materials"] > 1]
    all_rows = res["python"]
    out += [""]
    for r in distinct:
        shared = next(
            (x for x in rows if x["objects"] == r["objects"] and round(x["triangles"], -4) == 10_000), None
        )
        out.append(
            f"With {r['objects']} objects each carrying its own material (equal settings, so one table):"
            f" collect {r['collect']:.2f} ms, prepare {r['prepare']:.2f} ms"
            + (
                f" (one shared material: {shared['collect']:.2f} ms, {shared['prepare']:.2f} ms)"
                if shared
                else ""
            )
            + ": each material's description is read from its settings once per frame."
        )
    out += [
        "",
        f"Over all these frames (after 3 warm-up frames each): {sum(r['rebuilt'] for r in all_rows)} batches"
        f" rebuilt, {sum(r['compiled'] for r in all_rows)} shader variants compiled,"
        f" {sum(r['ubo_allocations'] for r in all_rows)} uniform buffers allocated and"
        f" {sum(r['ubo_uploads'] for r in all_rows)} updated (`scene_draw.CACHES.stats`,"
        " `gpu.shaders.SHADERS.compile_count`, `gpu.draw.UNIFORMS.stats`);"
        " tests/drawing/test_viewport_perf_invariants.py checks each of these properties.",
    ]
    if any("baseline" in r for r in all_rows):
        out += [
            "",
            f"Baseline revision ({res.get('baseline')}): its `draw_items` (CPU time, same frames) against"
            " ours (`prepare` + `submit`):",
            "",
            "| objects | materials | triangles | baseline draw_items ms | ours prepare + submit ms |",
            "|---|---|---|---|---|",
        ]
        for r in all_rows:
            out.append(
                f"| {r['objects']} | {r['materials']} | {fmt_tri(r['triangles'])} | {r['baseline']:.2f} |"
                f" {r['prepare'] + r['submit']:.2f} |"
            )
    return out + [""]


def _rebuild_section(res: dict) -> list[str]:
    rows = res.get("rebuild")
    if not rows:
        return []
    out = [
        "## Batch rebuild after an edit",
        "",
        "One object; one vertex moved through the mesh API (`foreach_set`, `mesh.update()`), then the"
        " depsgraph update (Blender's; our handler marks the object) and `scene_draw.collect`, which"
        " rebuilds that object's batch (`mesh_arrays` → `MeshBatch.from_arrays`). Beside it, Workbench's"
        " first frame after the same edit (it re-extracts its own batches) and its next frame (view"
        " moved, no edit), at 320×180. Wall time, median of the edits.",
        "",
        "| triangles | rebuild (collect) ms | depsgraph update ms | Workbench first frame ms"
        " | Workbench next frame ms | batches built |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        out.append(
            f"| {fmt_tri(r['triangles'])} | {r['collect']:.1f} | {r['depsgraph']:.1f}"
            f" | {r['workbench_first']:.1f} | {r['workbench_steady']:.1f}"
            f" | {r['builds']} in {r['repeats']} edits |"
        )
    return out + [""]


def automatic_section(rows) -> list[str]:
    """The glossy, medium and rough films at their automatic order (:func:`automatic_orders`)."""
    if not rows:
        return []
    r0 = rows[0]
    out = [
        "## Rough films at their automatic order (outgoing-radiance grid)",
        "",
        f"{r0['objects']} tori, {fmt_tri(r0['triangles'])} triangles, {r0['res']}; films of roughness"
        " 0.05 / 0.3 / 0.6 at their automatic SH order, lit by the World with its lamps. *grid*: as"
        " the product draws them (the SH half of a constant-thickness film from its outgoing-radiance"
        " grid, precompute/shading/radiance_grid.py); *per-pixel SH*: the same items with the grid"
        " removed (the SH sum per pixel, as before). Per covered pixel = frame ms ÷ covered pixels;"
        " acceptance (issue 16): medium and rough ≤ 2× glossy.",
        "",
        "| film | roughness | l_max | SH weight | grid ms | per-pixel SH ms | ns per covered pixel"
        " | × glossy | covered |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        out.append(
            f"| {r['case']} | {r['roughness']} | {r['l_max']} | {r['sh_weight']:.2f} | {r['ms']:.1f}"
            f" | {r['ms_per_pixel']:.1f} | {r['ns_per_covered_pixel']:.0f} | {r['ratio_to_glossy']:.2f}"
            f" | {100 * r['coverage']:.1f} % |"
        )
    return out + [f"Workbench, same frames: {r0['workbench']:.1f} ms.", ""]


def _optimisation_section() -> list[str]:
    """A link to the optimisations' before/after figures: docs/performance-history.md (each from its
    own ``--baseline`` run, not from this one)."""
    return [
        "## What was optimised (before → after)",
        "",
        "Each optimisation of the draw with its before/after figures, measured in its own run with"
        " `--baseline`: [performance-history.md](performance-history.md).",
        "",
    ]
