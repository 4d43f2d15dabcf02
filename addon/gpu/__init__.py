"""The add-on's GPU layer: ``bpy``/``gpu`` glue only, no scene logic (addon/drawing/scene_draw.py decides
what to draw; callers hand in arrays, matrices and baked tables).

- ``context``: whether drawing works now; a GPU context in background mode.
- ``shaders``: the GLSL chunks of ``glsl/`` joined by their ``#include`` lines, a
  :class:`~precompute.shading.variant.Variant`'s create-info, the shader cache.
- ``resources``: binding slots and uniform-buffer layouts (each written once), and the GPU
  objects made from arrays: table, lighting, film, prefiltered World, environment; the uniform
  buffer cache.
- ``mesh``: a mesh's arrays per face corner and its batch.
- ``draw``: view and object uniforms, draw items grouped by variant, the background, off-screen
  rendering and read-back.

The per-pixel maths is in ``glsl/`` and mirrors precompute/shading/ (``sh_sum.shade_sh`` and the
rest); tests/drawing/test_gpu_draw.py checks one against the other pixel by pixel.
"""
