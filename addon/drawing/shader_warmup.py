"""Shader variants compiled ahead, one per idle step, never inside the draw callback.

The viewport's draw (:func:`.viewport.draw_callback`) draws with ``compile_now=False``: a
variant that is not compiled yet is asked for (``gpu.shaders.SHADERS.want``) and its film is
drawn by the variant's stand-in meanwhile (variant.stand_in: order ≤ policy.STAND_IN_L, no
grid; it compiles in a fraction of the time). :func:`schedule` starts a ``bpy.app.timers`` step
that compiles the oldest wanted variant, asks the 3D viewports for a redraw and comes back
until none is left; the header says "compiling shaders" meanwhile (:func:`activity`). One step
blocks Blender for one compilation: on llvmpipe seconds for the grid and low-order variants,
77–83 s for a per-pixel l = 12 variant (docs/performance.md), now needed only where the
thickness varies.
"""

from __future__ import annotations

import logging

import bpy

from ..gpu.shaders import SHADERS
from ..workers import tag_view3d as _tag_redraw

log = logging.getLogger(__name__)


def activity() -> str:
    """A few words for the viewport header while variants wait to be compiled, else ""."""
    count = len(SHADERS.wanted())
    return f"compiling shaders ({count} left)" if count else ""


def step() -> float | None:
    """Timer: compile one wanted variant, redraw; again shortly while any is left."""
    try:
        done = SHADERS.compile_next()
    except Exception as exc:  # a variant that fails to compile must not stop the timer forever
        log.error("Thin Film SH: shader compile failed: %s", exc)
        done = None
    if done is not None:
        _tag_redraw()
    return 0.05 if SHADERS.wanted() else None


def schedule() -> None:
    """Start the compile step if variants are wanted and it is not running."""
    if SHADERS.wanted() and not bpy.app.timers.is_registered(step):
        bpy.app.timers.register(step, first_interval=0.05)


def unregister() -> None:
    """Stop the compile step."""
    if bpy.app.timers.is_registered(step):
        bpy.app.timers.unregister(step)
