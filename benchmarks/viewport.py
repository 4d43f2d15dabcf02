"""Viewport frame time: the extension's draw against Blender's Workbench solid draw of the same scene.

Usage (from the repository root)::

    .venv/bin/python -m benchmarks.viewport            # → docs/performance.md (about 12 min here)
    .venv/bin/python -m benchmarks.viewport --quick    # smoke run (< 1 min), writes nothing
    .venv/bin/python -m benchmarks.viewport --baseline REV
        # also draws every headline frame with revision REV's addon/gpu/ + glsl/ (a git
        # worktree), interleaved with the current code: before/after of an optimisation

Everything runs in one bpy process on whatever OpenGL bpy finds (Mesa llvmpipe on the machine
the committed report comes from), off-screen through ``gpu.types.GPUOffScreen`` (RGBA8, the
viewport's display-referred output):

- *Workbench* (the baseline): ``GPUOffScreen.draw_view3d`` of the scene in Solid shading, the
  factory settings of a 3D view (studio light, material colour, object outline, the scene's
  viewport anti-aliasing), overlays off.
- *ours*: what the viewport's draw callback does per frame: ``scene_draw.collect`` (nothing is
  baked or rendered in it) and ``gpu.draw.draw_items`` with sRGB display output, into the same
  off-screen buffer after a clear; no Workbench pass underneath.

Each timed frame ends with a 1-pixel ``read_color`` of the off-screen buffer, which waits until
the frame is finished (llvmpipe renders asynchronously on its own threads). Every cell is
warmed up first (shader variants compiled, batches built), then Workbench and ours are drawn
alternately, so a change of load during the run hits both; the figure is the median of the
repeated frames and the ratio is ours / Workbench of those medians.

Scenes: N ∈ {1, 10, 100} tori (each its own mesh, smooth shaded, quads) sharing the total
triangle count T, laid out on a grid in front of the camera, all with one thin-film material
(a 400 nm film of n = 1.33 on glass, spectral, constant thickness, rough enough to be drawn by
SH alone; its l_max forced through the material's Quality), lit by Blender's ``studio`` HDRI
as the World.
"""

from __future__ import annotations

import argparse
import importlib
import json
import math
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from precompute.material import Layer, Material
from precompute.shading import policy

from . import common

EXTENSION_ID = "thinfilm_sh"
BASELINE_ID = "thinfilm_sh_baseline"

RESOLUTIONS = {"720p": (1280, 720), "1080p": (1920, 1080), "4K": (3840, 2160)}
OBJECT_COUNTS = (1, 10, 100)
TRIANGLES = (10_000, 100_000, 1_000_000, 2_000_000)
#: 4K only for these (objects, triangles): a Workbench frame takes 6-9 s there on llvmpipe.
CELLS_4K = ((10, 10_000), (10, 2_000_000))
#: The headline is l_max = 2 (bands l ≤ 2; docs/conventions.md: "SH order" is l_max).
HEADLINE_L = 2
SWEEP_L = (*range(1, 9), 10, 12)
#: The scene of the order sweep and of the split-sum comparison: (objects, triangles).
SWEEP_SCENE = (10, 100_000)
SPLIT_SUM_L = (2, 5, 8, 12)
#: Frames of the Python-time part (per scene, after 3 warm-up frames).
PYTHON_FRAMES = 25
#: Acceptance: ours ≤ 2× Workbench at order 3, 1080p.
RATIO_LIMIT = 2.0
HDRI = "studio"
#: The last full run's measurements (``--report-only`` rewrites the report from them); not in git.
RESULTS_JSON = "out/viewport-benchmark.json"

#: The film: 400 nm of n = 1.33 on glass, constant thickness, spectral.
FILM = Material(layers=(Layer(1.33, 400.0),), substrate=1.5)


def roughness_cases() -> dict[str, float]:
    """Roughness of the SH-only, combined (both halves) and split-sum-only films (policy.SH_BLEND)."""
    lo, hi = policy.SH_BLEND
    return {"sh": min(hi + 0.1, 1.0), "combined": 0.5 * (lo + hi), "split": max(lo - 0.05, 0.0)}


# ----------------------------------------------------------------------------------------------
# The extension in this process
# ----------------------------------------------------------------------------------------------
class Extension:
    """The repository imported as the extension package (``thinfilm_sh``) and registered."""

    def __init__(self):
        import bpy

        self.root = Path(tempfile.mkdtemp(prefix="tf_viewport_bench_"))
        os.symlink(common.ROOT, self.root / EXTENSION_ID, target_is_directory=True)
        sys.path.insert(0, str(self.root))
        self.package = importlib.import_module(EXTENSION_ID)
        self.package.register()
        for dotted in (
            "addon.drawing.scene_draw",
            "addon.materials.props",
            "addon.materials.conversion",
            "addon.headless.headless",
            "addon.headless.render",
        ):
            setattr(self, dotted.rpartition(".")[2], importlib.import_module(f"{EXTENSION_ID}.{dotted}"))
        self.gpu = common.gpu_layer(EXTENSION_ID)
        self.gpu.context.ensure_gpu_context()
        bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
        self.package.register()  # harmless when registered; the file load cleared the caches

    def baseline(self, rev: str):
        """The draw module of git revision ``rev`` (``addon.gpu.draw``, ``addon.gpu_draw`` before the
        GPU layer was a package) as a second package (a detached worktree)."""
        tree = self.root / "baseline_tree"
        subprocess.run(
            ["git", "worktree", "add", "--detach", str(tree), rev],
            cwd=common.ROOT,
            check=True,
            capture_output=True,
        )
        os.symlink(tree, self.root / BASELINE_ID, target_is_directory=True)
        name = "addon.gpu.draw" if (tree / "addon" / "gpu" / "draw.py").is_file() else "addon.gpu_draw"
        module = importlib.import_module(f"{BASELINE_ID}.{name}")
        commit = subprocess.run(
            ["git", "log", "-1", "--format=%h %s", rev], cwd=common.ROOT, capture_output=True, text=True
        ).stdout.strip()
        return module, tree, commit

    def remove_baseline(self, tree) -> None:
        subprocess.run(
            ["git", "worktree", "remove", "--force", str(tree)],
            cwd=common.ROOT,
            check=False,
            capture_output=True,
        )


# ----------------------------------------------------------------------------------------------
# The scene
# ----------------------------------------------------------------------------------------------
def torus_mesh(name: str, triangles: int, major: float, minor: float):
    """A smooth-shaded torus of quads with about ``triangles`` triangles (numpy + foreach_set)."""
    import bpy

    quads = max(triangles // 2, 8)
    nv = max(int(round(math.sqrt(quads / 2.5))), 3)
    nu = max(int(round(quads / nv)), 3)
    u = np.arange(nu) * (2 * np.pi / nu)
    v = np.arange(nv) * (2 * np.pi / nv)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    ring = major + minor * np.cos(vv)
    co = np.stack([ring * np.cos(uu), ring * np.sin(uu), minor * np.sin(vv)], -1).reshape(-1, 3)
    i = np.arange(nu)[:, None]
    j = np.arange(nv)[None, :]
    i1, j1 = (i + 1) % nu, (j + 1) % nv
    corners = np.stack([i * nv + j, i1 * nv + j, i1 * nv + j1, i * nv + j1], -1).reshape(-1, 4)
    mesh = bpy.data.meshes.new(name)
    mesh.vertices.add(co.shape[0])
    mesh.vertices.foreach_set("co", co.astype(np.float32).ravel())
    mesh.loops.add(corners.size)
    mesh.loops.foreach_set("vertex_index", corners.astype(np.int32).ravel())
    mesh.polygons.add(corners.shape[0])
    mesh.polygons.foreach_set("loop_start", np.arange(0, corners.size, 4, dtype=np.int32))
    mesh.update(calc_edges=True)
    mesh.shade_smooth()
    return mesh


class Scene:
    """One bpy scene: the World, one film material per (l_max, case), tori and a camera."""

    def __init__(self, ext: Extension):
        import bpy

        self.ext = ext
        self.scene = bpy.context.scene
        self.scene.name = "viewport benchmark"
        self._world()
        self.materials: dict[tuple[int, str], object] = {}
        self.objects: list = []
        self.layout = (0, 0)
        cam_data = bpy.data.cameras.new("Camera")
        cam_data.lens = 50.0
        cam_data.clip_start, cam_data.clip_end = 0.1, 100.0
        self.camera = bpy.data.objects.new("Camera", cam_data)
        self.scene.collection.objects.link(self.camera)
        self.scene.camera = self.camera
        self.space, self.region = ext.render._view3d_for_depth()
        if self.space is None:
            raise RuntimeError("no VIEW_3D area in bpy.data.screens: cannot draw Workbench")
        shading = self.space.shading
        shading.type = "SOLID"
        self.space.overlay.show_overlays = False
        self.workbench_settings = (
            f"light {shading.light}, colour {shading.color_type}, outline {shading.show_object_outline},"
            f" cavity {shading.show_cavity}, shadows {shading.show_shadows}, X-ray {shading.show_xray},"
            f" viewport anti-aliasing {self.scene.display.viewport_aa}, overlays off"
        )

    def _world(self) -> None:
        import bpy

        folder = bpy.utils.system_resource("DATAFILES", path="studiolights/world")
        world = bpy.data.worlds.new(f"Studio {HDRI}")
        tree = world.node_tree
        background = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeBackground")
        env = tree.nodes.new("ShaderNodeTexEnvironment")
        env.image = bpy.data.images.load(os.path.join(folder, f"{HDRI}.exr"), check_existing=True)
        tree.links.new(env.outputs["Color"], background.inputs["Color"])
        self.scene.world = world

    def material(self, l_max: int, case: str = "sh"):
        """The film material at ``l_max`` and roughness of ``case`` (made once)."""
        import bpy

        key = (int(l_max), case)
        if key not in self.materials:
            mat = bpy.data.materials.new(f"Film l{l_max} {case}")
            tf = mat.thinfilm_sh
            self.ext.conversion.fill_from_material(tf, FILM.with_(roughness=roughness_cases()[case]))
            tf.sh_order = str(int(l_max))
            tf.enabled = True
            self.materials[key] = mat
        return self.materials[key]

    def set_objects(self, count: int, triangles: int) -> None:
        """Replace the tori by ``count`` tori with ``triangles`` in all, on a grid facing the camera."""
        import bpy

        if self.layout == (count, triangles):
            return
        for obj in self.objects:
            mesh = obj.data
            bpy.data.objects.remove(obj)
            bpy.data.meshes.remove(mesh)
        self.objects = []
        cols = math.ceil(math.sqrt(count))
        rows = math.ceil(count / cols)
        cell = 2.0 / cols
        template = torus_mesh("Torus", triangles // count, 0.32 * cell, 0.13 * cell)
        for k in range(count):
            mesh = template if k == 0 else template.copy()
            obj = bpy.data.objects.new(f"Torus.{k:03d}", mesh)
            r, c = divmod(k, cols)
            obj.location = (-1.0 + cell * (c + 0.5), 0.0, (rows / cols) - cell * (r + 0.5))
            obj.rotation_euler = (math.radians(70.0), math.radians(10.0 * (k % 5)), math.radians(25.0))
            self.scene.collection.objects.link(obj)
            self.objects.append(obj)
        self.layout = (count, triangles)
        self.camera.location = (0.0, -4.2, 0.35)
        self.camera.rotation_euler = (math.radians(85.0), 0.0, 0.0)
        bpy.context.view_layer.update()

    def assign(self, l_max: int, case: str = "sh", distinct: bool = False) -> None:
        """Give every torus the film material of ``l_max`` / ``case``; ``distinct``: each torus its
        own copy of it (equal settings, so one table, but one description per material and frame)."""
        import bpy

        mat = self.material(l_max, case)
        for k, obj in enumerate(self.objects):
            own = mat
            if distinct and k > 0:
                name = f"{mat.name} copy {k}"
                own = bpy.data.materials.get(name) or mat.copy()
                own.name = name
            if len(obj.data.materials) == 0:
                obj.data.materials.append(own)
            elif obj.data.materials[0] != own:
                obj.data.materials[0] = own
        bpy.context.view_layer.update()

    @property
    def triangles(self) -> int:
        return sum(2 * len(o.data.polygons) for o in self.objects)

    def matrices(self, width: int, height: int):
        import bpy

        depsgraph = bpy.context.evaluated_depsgraph_get()
        return self.ext.render.camera_matrices(self.scene, depsgraph, width, height)


# ----------------------------------------------------------------------------------------------
# Frames
# ----------------------------------------------------------------------------------------------
def _mathutils(m):
    from mathutils import Matrix

    return Matrix(np.asarray(m).tolist())


@dataclass
class Frame:
    """Draws of one scene at one size: Workbench, ours, and optionally ours at a baseline revision.

    Every draw moves the view by a negligible amount first (:meth:`next_view`: at most 1e-4 of
    the scene's size, sideways), as while orbiting: with an unchanged view and scene,
    ``draw_view3d`` only re-displays its previous result without drawing the scene
    (:meth:`workbench_static`), which is not a frame of the scene.
    """

    scene: Scene
    width: int
    height: int

    def __post_init__(self):
        import gpu

        self.offscreen = gpu.types.GPUOffScreen(self.width, self.height)
        self.base_view, self.proj = self.scene.matrices(self.width, self.height)
        self.mproj = _mathutils(self.proj)
        self.count = 0
        self.next_view()

    def next_view(self) -> None:
        """A view 1e-6…1e-4 to the side of the camera's, different from the previous frame's."""
        self.count += 1
        self.view = self.base_view.copy()
        self.view[0, 3] += 1e-6 * (1 + self.count % 97) * (1 if self.count % 2 else -1)
        self.mview = _mathutils(self.view)

    def free(self) -> None:
        self.offscreen.free()

    def _finish(self) -> None:
        import gpu

        gpu.state.active_framebuffer_get().read_color(0, 0, 1, 1, 4, 0, "FLOAT")

    def workbench(self, move: bool = True) -> None:
        import bpy

        if move:
            self.next_view()
        self.offscreen.draw_view3d(
            self.scene.scene,
            bpy.context.view_layer,
            self.scene.space,
            self.scene.region,
            self.mview,
            self.mproj,
            do_color_management=False,
        )
        with self.offscreen.bind():
            self._finish()

    def workbench_static(self) -> None:
        """``draw_view3d`` with the previous view and nothing changed: a re-display."""
        self.workbench(move=False)

    def items(self):
        import bpy

        sd = self.scene.ext.scene_draw
        items, messages = sd.collect(
            bpy.context.evaluated_depsgraph_get(), allow_bake=False, allow_world=False
        )
        return items

    def ours(self, items_hook=None, draw_module=None) -> None:
        """One frame of the viewport callback: collect, draw, finish."""
        import gpu

        draw = self.scene.ext.gpu.draw if draw_module is None else draw_module
        self.next_view()
        with self.offscreen.bind():
            gpu.state.active_framebuffer_get().clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
            items = self.items()
            if items_hook is not None:
                items = items_hook(items)
            draw.draw_items(items, self.view, self.proj, display_srgb=True)
            self._finish()

    def coverage(self) -> float:
        """Fraction of the frame our draw covers."""
        import gpu

        gd = self.scene.ext.gpu
        with self.offscreen.bind():
            fb = gpu.state.active_framebuffer_get()
            fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
            gd.draw.draw_items(self.items(), self.view, self.proj, display_srgb=True)
            rgba = gd.draw.read_framebuffer(fb, self.width, self.height)
        return float(np.mean(rgba[..., 3] > 0.5))


def interleaved(draws: dict, repeats: int, warmup: int = 1) -> dict[str, list[float]]:
    """Wall seconds of ``repeats`` rounds; each round calls every draw once, order alternating."""
    for _ in range(warmup):
        for fn in draws.values():
            fn()
    times = {name: [] for name in draws}
    names = list(draws)
    for r in range(repeats):
        for name in names if r % 2 == 0 else names[::-1]:
            start = time.perf_counter()
            draws[name]()
            times[name].append(time.perf_counter() - start)
    return times


def median_ms(times: list[float]) -> float:
    return 1e3 * statistics.median(times)


def repeats_for(width: int, height: int, triangles: int, quick: bool) -> int:
    """Frames per draw in a cell: fewer where a Workbench frame takes seconds on llvmpipe."""
    if quick:
        return 2
    if width * height > 4e6 or triangles >= 1_000_000:
        return 3
    if width * height > 1.5e6:
        return 5
    return 7


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
            draws["baseline"] = lambda: frame.ours(items_hook=_as_plain_items, draw_module=baseline)
        times = interleaved(draws, repeats)
        out = {name: median_ms(t) for name, t in times.items()}
        out["times"] = times
        out["coverage"] = frame.coverage()
        frame.workbench()
        out["workbench_static"] = median_ms(interleaved({"static": frame.workbench_static}, 3, 0)["static"])
        return out
    finally:
        frame.free()


def _as_plain_items(items):
    """Draw items as another revision's draw module reads them (its MeshBatch class is not ours)."""
    from types import SimpleNamespace

    return [
        SimpleNamespace(
            batch=it.batch.batch,
            has_thickness=it.batch.has_thickness,
            model_matrix=it.model_matrix,
            table=it.table,
            lighting=it.lighting,
            prefiltered=it.prefiltered,
            roughness=it.roughness,
            sh_weight=it.sh_weight,
        )
        for it in items
    ]


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
                "sh_same": _swapped(frame, stored["sh_same"]),
                "sh_same_nolamps": _swapped(frame, stored["sh_same_nolamps"]),
                "combined": _swapped(frame, stored["combined"]),
                "split": _swapped(frame, stored["split"]),
                "sh_nolamps": _swapped(frame, stored["sh_nolamps"]),
                "combined_nolamps": _swapped(frame, stored["combined_nolamps"]),
                "split_nolamps": _swapped(frame, stored["split_nolamps"]),
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


#: Roughness of the glossy, medium and rough films of :func:`automatic_orders` (issue 16).
AUTOMATIC_ROUGHNESS = {"glossy": 0.05, "medium": 0.3, "rough": 0.6}


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
            mat = bpy.data.materials.get(f"Film auto {case}")
            if mat is None:
                mat = bpy.data.materials.new(f"Film auto {case}")
                scene.ext.conversion.fill_from_material(mat.thinfilm_sh, FILM.with_(roughness=rough))
                mat.thinfilm_sh.sh_order = "AUTO"
                mat.thinfilm_sh.enabled = True
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
            draws[name] = _swapped(frame, items)
        coverage = {}
        for case in AUTOMATIC_ROUGHNESS:  # the same tori: one coverage, measured per film anyway
            coverage[case] = _coverage(frame, stored[case])
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


def _coverage(frame: Frame, items: list) -> float:
    """Fraction of the frame ``items`` cover."""
    import gpu

    gd = frame.scene.ext.gpu
    with frame.offscreen.bind():
        fb = gpu.state.active_framebuffer_get()
        fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
        gd.draw.draw_items(items, frame.view, frame.proj, display_srgb=True)
        rgba = gd.draw.read_framebuffer(fb, frame.width, frame.height)
    return float(np.mean(rgba[..., 3] > 0.5))


def _swapped(frame: Frame, items: list):
    """A frame of ours that draws ``items`` instead of what ``collect`` returned (after calling it)."""
    return lambda: frame.ours(items_hook=lambda _collected: items)


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
                        plain = _as_plain_items(items)
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


# ----------------------------------------------------------------------------------------------
# The report
# ----------------------------------------------------------------------------------------------
def _code_state() -> str:
    try:
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--", "addon", "glsl", "benchmarks/viewport.py"],
            cwd=common.ROOT,
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return "addon/, glsl/ and benchmarks/viewport.py have uncommitted changes" if dirty else "clean"


def _fps(ms: float) -> str:
    return f"{1e3 / ms:.1f}" if ms > 0 else "—"


def _objects(n: int) -> str:
    return f"{n} object" if n == 1 else f"{n} objects"


def _tri(n: int) -> str:
    return f"{n / 1e6:.2f} M" if n >= 1_000_000 else f"{n / 1e3:.0f} k"


def _headline(res: dict) -> dict:
    """The 1080p cells of the grid at the headline order: worst ratio and the sweep scene's."""
    cells = [r for r in res.get("grid", []) if r["res"] == "1080p"]
    if not cells:
        return {}
    worst = max(cells, key=lambda r: r["ours"] / r["workbench"])
    objects, triangles = SWEEP_SCENE
    typical = next(
        (r for r in cells if r["objects"] == objects and abs(r["triangles"] - triangles) < 0.05 * triangles),
        worst,
    )
    return {"cells": cells, "worst": worst, "typical": typical}


def report(res: dict) -> str:
    head = _headline(res)
    ratio = lambda r: r["ours"] / r["workbench"]  # noqa: E731
    lines = [
        "# Viewport performance: frame time against Workbench",
        "",
        f"Generated by `.venv/bin/{res.get('command', 'python -m benchmarks.viewport')}` from the repository"
        " root (benchmarks/viewport.py, where the prose around the numbers lives too) in"
        f" {res['minutes']:.1f} min. `--quick` is a smoke run of under a minute that writes nothing;"
        " `--baseline REV` adds the frames of revision REV's drawing code, interleaved (before/after);"
        f" `--report-only` rewrites this file from the last run's `{RESULTS_JSON}`.",
        "",
        "## Summary",
        "",
    ]
    if head:
        worst, typical = head["worst"], head["typical"]
        verdict = "met" if ratio(worst) <= RATIO_LIMIT else "**not met**"
        lines += [
            f"- **l_max = 2 at 1080p: ours / Workbench = {ratio(typical):.2f}×** for"
            f" {_objects(typical['objects'])} with {_tri(typical['triangles'])} triangles"
            f" ({typical['ours']:.0f} ms vs {typical['workbench']:.0f} ms, median frames, same run); over"
            f" all {len(head['cells'])} scenes at 1080p"
            f" {min(map(ratio, head['cells'])):.2f}–{ratio(worst):.2f}×"
            f" (worst: {_objects(worst['objects'])}, {_tri(worst['triangles'])} triangles). Acceptance"
            f" (≤ {RATIO_LIMIT:g}×): {verdict}.",
        ]
        static = [c["ours"] / c["workbench_static"] for c in head["cells"] if c.get("workbench_static")]
        if static:
            lines.append(
                "- For comparison only: against `draw_view3d` re-displaying an unchanged frame (which draws"
                f" no scene; see Method) ours is {min(static):.2f}–{max(static):.2f}× at 1080p. In the"
                " viewport a frame in which nothing changed is not drawn at all, by either."
            )
    if res.get("python"):
        py = [r for r in res["python"] if r["materials"] == 1]

        def spread(key_a, key_b):
            by_objects = {}
            for r in py:
                by_objects.setdefault(r["objects"], []).append(r[key_a] + r[key_b])
            return ", ".join(f"{_objects(n)}: {min(v):.2f}–{max(v):.2f} ms" for n, v in by_objects.items())

        lines.append(
            "- Python time per frame with nothing changed (`collect` + `prepare_draw`, thread CPU time),"
            f" 10 k → 2 M triangles: {spread('collect_alone', 'prepare_alone')} back to back; it does not"
            " grow with the triangle count. Inside frames, with llvmpipe's geometry work in between"
            f" evicting the caches: {spread('collect', 'prepare')} (flat from 100 k triangles on;"
            " tables below)."
        )
    if res.get("rebuild"):
        rb = res["rebuild"]
        lines.append(
            "- Batch rebuild after an edit: "
            + ", ".join(f"{r['collect']:.0f} ms at {_tri(r['triangles'])}" for r in rb)
            + " triangles (Workbench's first frame after the same edit, which re-extracts its batches: "
            + ", ".join(f"{r['workbench_first']:.0f} ms" for r in rb)
            + ")."
        )
    if res.get("split_sum"):
        lines.append(
            "- Split sum + SH (combined) against SH only at 1080p, as drawn (World lamps shaded per"
            " light direction in both): "
            + ", ".join(f"l = {r['l_max']}: {r['combined'] / r['sh']:.2f}×" for r in res["split_sum"])
            + "."
        )
        if all("sh_nolamps" in r for r in res["split_sum"]):
            lines.append(
                '- The same with the films\' "World Lamps" off (no lamp loop in either): '
                + ", ".join(
                    f"l = {r['l_max']}: {r['combined_nolamps'] / r['sh_nolamps']:.2f}×"
                    for r in res["split_sum"]
                )
                + "."
            )
        if all("sh_same" in r for r in res["split_sum"]):
            lines.append(
                "- The combined film against itself drawn by SH alone (same table and lighting: the"
                " split sum's own cost): "
                + ", ".join(
                    f"l = {r['l_max']}: {r['combined'] / r['sh_same']:.2f}×"
                    f" (lamps off {r['combined_nolamps'] / r['sh_same_nolamps']:.2f}×)"
                    for r in res["split_sum"]
                )
                + "."
            )
    lines += [
        f"- GPU: {gpu_statement(res)}",
        "",
        "## Machine",
        "",
        *res["machine"],
        f"- Renderer: {res['renderer']}, vendor {res['vendor']}; off-screen RGBA8",
        f"- addon/ and glsl/: {res['code_state']}",
        f"- Workbench settings: {res['workbench_settings']}",
        "",
        "## Method",
        "",
        *_method_lines(),
    ]
    lines += _grid_section(res)
    lines += _sweep_section(res)
    lines += _split_sum_section(res)
    lines += _python_section(res)
    lines += _rebuild_section(res)
    lines += automatic_section(res.get("automatic"))
    lines += _optimisation_section()
    return re.sub(r"\n{3,}", "\n\n", "\n".join(lines))


def gpu_statement(res: dict) -> str:
    renderer = res.get("renderer", "")
    if "llvmpipe" in renderer.lower() or "softpipe" in renderer.lower():
        return (
            f"every figure here is Mesa's software rasteriser ({renderer}) on the CPUs above: bpy"
            " cannot run on the GPU machine lent to some tasks. Our draw alone (the same shaders and"
            " data, recorded from the extension) was timed on an NVIDIA H100 by"
            " `benchmarks/gpu_frame/`: [gpu-frame.md](gpu-frame.md), including the 1 M-triangle"
            " figure (1080p, l_max = 4: 70 fps there, not the 240 asked for, on a GPU whose graphics"
            " hardware is a small part of the chip)."
        )
    return f"measured on {renderer}."


def _method_lines() -> list[str]:
    rough = roughness_cases()
    return [
        "- One bpy process, one OpenGL context; every frame off-screen (`GPUOffScreen`, RGBA8) at the"
        " listed size, from the scene camera (50 mm).",
        "- **Workbench** (the baseline): `GPUOffScreen.draw_view3d(scene, view_layer, space, region, view,"
        " projection, do_color_management=False)` with a 3D view in Solid shading, factory settings"
        " (listed above), overlays off: Blender's plain solid draw of the same objects.",
        "- **Ours**: what the viewport's draw callback does each frame: clear, `scene_draw.collect`"
        " (draw items from the depsgraph, with every cache warm: nothing is baked, rendered or rebuilt)"
        " and `gpu.draw.draw_items` (display sRGB). The Workbench pass that the viewport draws underneath"
        " is not part of it.",
        "- **The view moves by a negligible amount before every frame** (1e-6…1e-4 sideways), as while"
        " orbiting. With an unchanged view and scene `draw_view3d` does not draw the scene at all: it"
        " re-displays its previous result, at a cost that does not depend on the scene"
        " (`WB static` below). Only a frame that draws the scene is compared; our draw does the same"
        " work either way.",
        "- Every frame ends with a 1-pixel `read_color`, which waits for the frame to finish (llvmpipe"
        " rasterises on its own threads after the calls return); the timed wall time is therefore the"
        " full frame, CPU side and raster side.",
        "- Each cell: one warm-up frame of each draw (variants compiled, batches built), then rounds that"
        " draw Workbench and ours alternately (order flipped every round); the figure is the median of"
        " 7 frames (5 at 1080p, 3 at 4K or with ≥ 1 M triangles), the ratio that of the medians. 4K only"
        " for "
        + " and ".join(f"{n} objects with {_tri(t)} triangles" for n, t in CELLS_4K)
        + " (a Workbench frame takes 6–9 s there).",
        "- Scenes: N tori (each its own mesh of quads, smooth shaded) sharing T triangles on a grid"
        " facing the camera; all with one film material: 400 nm of n = 1.33 on glass, constant thickness,"
        f" spectral colour, roughness {rough['sh']:g} (drawn by SH alone: `sh_weight` = 1), l_max"
        " forced through the material's Quality; the World is Blender's"
        f" `{HDRI}` studio-light HDRI, whose small bright lamps the films shade per light direction"
        ' (the material\'s "World Lamps", on by default: a loop over 8 lamps in every variant, about'
        " 2× the SH-only frame at l = 2 on llvmpipe and +5–15 % from l = 8; see the split-sum table)."
        " Coverage = share of the frame's pixels the films cover.",
        "- Timing noise: the machine is shared with other CPU-heavy work, and llvmpipe uses every core,"
        " so both draws slow down together; compare ratios within a run.",
        "",
    ]


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
        out.append(f"| {objects} | {_tri(tris)} | " + " | ".join(cells) + " |")
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
                    f"| {r['objects']} | {_tri(r['triangles'])} | {r['baseline']:.0f} | {r['ours']:.0f} |"
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
        f"{r0['objects']} objects, {_tri(r0['triangles'])} triangles, {r0['res']}."
        f" The headline is l_max = {HEADLINE_L}.",
        "",
        "| l_max | Workbench ms | ours ms | ours fps | ratio |" + (" baseline ms |" if base else ""),
        "|---|---|---|---|---|" + ("---|" if base else ""),
    ]
    for r in rows:
        mark = " **(headline)**" if r["l_max"] == HEADLINE_L else ""
        out.append(
            f"| {r['l_max']}{mark} | {r['workbench']:.0f} | {r['ours']:.0f} |"
            f" {_fps(r['ours'])} | {r['ours'] / r['workbench']:.2f}× |"
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
        f"{r0['objects']} objects, {_tri(r0['triangles'])} triangles, {r0['res']}. The same film at three"
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
            label = label or _tri(c["triangles"])
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
        " tests/test_viewport_perf_invariants.py checks each of these properties.",
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
                f"| {r['objects']} | {r['materials']} | {_tri(r['triangles'])} | {r['baseline']:.2f} |"
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
            f"| {_tri(r['triangles'])} | {r['collect']:.1f} | {r['depsgraph']:.1f}"
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
        f"{r0['objects']} tori, {_tri(r0['triangles'])} triangles, {r0['res']}; films of roughness"
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


# ----------------------------------------------------------------------------------------------
# The run
# ----------------------------------------------------------------------------------------------
PARTS = ("grid", "sweep", "split_sum", "python", "rebuild", "automatic")


def run(
    quick: bool, baseline_rev: str | None = None, parts=PARTS, orders=None, log=print, per_pixel: bool = True
) -> dict:
    started = time.perf_counter()
    ext = Extension()  # imports bpy first: gpu and mathutils come with it
    import gpu

    scene = Scene(ext)
    baseline = tree = None
    res: dict = {"quick": quick}
    try:
        if baseline_rev:
            baseline, tree, res["baseline"] = ext.baseline(baseline_rev)
        res["renderer"] = f"{gpu.platform.renderer_get()} ({gpu.platform.backend_type_get()})"
        res["vendor"] = gpu.platform.vendor_get()
        res["workbench_settings"] = scene.workbench_settings
        log(f"renderer: {res['renderer']}; Workbench: {scene.workbench_settings}")
        if "grid" in parts:
            log("grid at the headline order …")
            res["grid"] = grid(scene, quick, baseline, log)
        if "sweep" in parts:
            log("l_max sweep …")
            res["sweep"] = order_sweep(scene, quick, baseline, orders, log)
        if "split_sum" in parts:
            log("split sum vs SH …")
            res["split_sum"] = split_sum(scene, quick, log)
        if "python" in parts:
            log("Python time per frame …")
            res["python"] = python_time(scene, quick, baseline, log)
        if "rebuild" in parts:
            log("batch rebuild after an edit …")
            res["rebuild"] = rebuild_time(scene, quick, log)
        if "automatic" in parts:
            log("glossy, medium and rough films at their automatic order …")
            res["automatic"] = automatic_orders(scene, quick, log, per_pixel=per_pixel)
    finally:
        if tree is not None:
            ext.remove_baseline(tree)
    res["roughness"] = roughness_cases()
    res["minutes"] = (time.perf_counter() - started) / 60
    return res


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="smoke run (< 1 min) that writes nothing")
    parser.add_argument("--baseline", metavar="REV", help="also draw with git revision REV's draw module")
    parser.add_argument(
        "--only", nargs="+", choices=PARTS, help="measure only these parts (prints, writes nothing)"
    )
    parser.add_argument(
        "--orders", nargs="+", type=int, metavar="L", help="l_max of the order sweep (prints, writes nothing)"
    )
    parser.add_argument(
        "--no-per-pixel",
        action="store_true",
        help="part 'automatic' without the per-pixel SH frames (prints, writes nothing)",
    )
    parser.add_argument(
        "--report-only",
        action="store_true",
        help=f"rewrite docs/performance.md from the last full run's {RESULTS_JSON} (no measuring)",
    )
    args = parser.parse_args(argv)
    path = os.path.join(common.ROOT, RESULTS_JSON)
    if args.report_only:
        with open(path, encoding="utf-8") as handle:
            res = json.load(handle)
    else:
        code_state = _code_state()  # before measuring: what was measured
        res = run(
            args.quick,
            args.baseline,
            parts=args.only or PARTS,
            orders=args.orders,
            per_pixel=not args.no_per_pixel,
        )
        res["machine"] = common.machine_lines()
        res["code_state"] = code_state
        res["command"] = " ".join(
            ["python -m benchmarks.viewport", *(argv if argv is not None else sys.argv[1:])]
        )
        if args.quick or args.only or args.orders or args.no_per_pixel:
            print(f"run done in {res['minutes']:.1f} min; nothing written")
            return 0
        os.makedirs(os.path.dirname(path), exist_ok=True)
        with open(path, "w", encoding="utf-8") as handle:
            json.dump(res, handle)
    print(common.write_doc("performance.md", report(res)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
