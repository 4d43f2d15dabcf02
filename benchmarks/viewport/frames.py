"""One frame of ours and of Workbench, off-screen, and how they are timed (interleaved, medians)."""

from __future__ import annotations

import statistics
import time
from dataclasses import dataclass

import numpy as np

from .scene import Scene


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


def film_coverage(frame: Frame, items: list) -> float:
    """Fraction of the frame ``items`` cover."""
    import gpu

    gd = frame.scene.ext.gpu
    with frame.offscreen.bind():
        fb = gpu.state.active_framebuffer_get()
        fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
        gd.draw.draw_items(items, frame.view, frame.proj, display_srgb=True)
        rgba = gd.draw.read_framebuffer(fb, frame.width, frame.height)
    return float(np.mean(rgba[..., 3] > 0.5))


def drawing(frame: Frame, items: list):
    """A frame of ours that draws ``items`` instead of what ``collect`` returned (after calling it)."""
    return lambda: frame.ours(items_hook=lambda _collected: items)


def plain_items(items):
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
