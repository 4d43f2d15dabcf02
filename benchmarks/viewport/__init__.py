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
