"""Asking Blender to redraw the 3D views once background work has changed what they show.

Shared by the viewport's timer (:mod:`.viewport`), the radiance-grid worker's timer
(:mod:`.radiance_grids`) and the idle shader compile (:mod:`.shader_warmup`); each imports
:func:`tag_view3d` as its own ``_tag_redraw``, so a test or benchmark can replace one module's.
"""

from __future__ import annotations

import bpy


def tag_view3d() -> None:
    """Tag every 3D view of every window for a redraw (none in background mode)."""
    for window in getattr(bpy.context.window_manager, "windows", []):
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                area.tag_redraw()
