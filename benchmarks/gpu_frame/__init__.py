"""GPU frame time of our draw alone: the extension's shaders and data, drawn through moderngl + EGL.

Usage (from the repository root)::

    .venv/bin/python -m benchmarks.gpu_frame prepare OUTDIR
        # with bpy: the benchmark scenes of benchmarks/viewport/ → OUTDIR (every shader variant,
        # uniform buffer, texture and mesh a frame draws; about 30 MiB)
    .venv/bin/python -m benchmarks.gpu_frame check OUTDIR
        # with bpy: this harness's pictures against gpu.draw.draw_items on the same OpenGL
        # (→ OUTDIR/check.json, OUTDIR/pictures-check.npz); needs moderngl
    python3 -m benchmarks.gpu_frame measure OUTDIR --out RESULT.json [--backend egl]
        [--pictures DIR] [--rounds N] [--skip 'sweep-l12-*' …] [--budget-s S] [--no-blender-sources]
        # numpy + moderngl only (no bpy, no precompute): compile, draw and time every case
    python -m benchmarks.gpu_frame compare RESULT.json DIR/pictures-480x270.npz OUTDIR/pictures-check.npz
        # (re)compute the picture comparison of a result with the llvmpipe pictures of ``check``
    python -m benchmarks.gpu_frame report RESULT.json [--extra MORE.json …]
        # → docs/gpu-frame.md; --extra merges further measure runs (other sizes, a few cases) into
        # docs/gpu-frame.json first, which ``report docs/gpu-frame.json`` then rebuilds from

Why: the viewport benchmark (benchmarks/viewport/, docs/performance.md) runs inside bpy, and
the only OpenGL here is Mesa's llvmpipe. The GPU machine lent to some tasks cannot run bpy (its
wheel is far over what can be carried there, and it has Python 3.12 only), so ``prepare`` takes
everything a frame of ours needs out of the real extension, and ``measure`` draws it again with
nothing but numpy and moderngl:

- *Shaders*: for every variant that ``gpu.draw.prepare_draw`` picks, the create-info exactly as
  ``gpu.shaders.mesh_shader_info`` fills it (recorded by standing in for ``gpu.types``'s create-info
  classes: defines, ``TYPEDEFS``, uniform buffers and samplers with their slots, vertex inputs,
  the interface, the fragment output, the vertex and fragment bodies: ``shading_library`` and the
  chunks). ``measure`` writes the declarations Blender 5.2's OpenGL backend generates from it
  (``#version 430``, the defines, the typedefs, ``layout(binding = N, std140) uniform _name
  { Type name; };``, ``layout(binding = N) uniform sampler…``, ``layout(location = N) in …``,
  the interface block, ``layout(location = 0) out vec4 tf_frag_color``) in front of the bodies.
  Where bpy runs on OpenGL, ``prepare`` also keeps the source Blender itself compiled for each
  variant (read back from the driver), and ``measure`` compiles that too and draws the pictures
  with both: Blender's adds only its GLSL compatibility macros.
- *Data*: uniform buffers and textures as ``gpu.resources`` uploads them (recorded where it creates
  them: lighting, table and film in a uniform buffer or a 2-D array texture, the prefiltered World
  as a 3-D texture), the view and object uniform buffers as ``prepare_draw`` fills them, the draws
  in the order and grouping ``prepare_draw`` gives them, and each mesh as ``MeshBatch.from_arrays``
  receives it (stored as its distinct vertices and the map back, rebuilt bit for bit).
- *Scenes* (benchmarks/viewport/'s, the same World, film and tori): ``sweep``, 10 tori with
  100 k triangles at l = 2, 5, 8, 12, each film as SH only, combined (split sum + SH) and split
  sum only (``viewport.roughness_cases``), with the World's lamps shaded per light direction
  (the product's default) and with the films' "World Lamps" off; ``grid``, 1 torus with 1.00 M
  triangles at l_max = 4 and 2, SH only, lamps on and off. 1920×1080, the view of
  the scene camera. ``prepare`` runs on llvmpipe, where small tables are read from the uniform
  buffer; cases "<film>-tex" are the same films with the table read from its texture, as a
  hardware GPU draws them (``policy.TABLE_UBO_DEVICES``), and "sh-loops" (l = 8, 12) the SH
  film with the generic rotation loops instead of the generated X(±90°) code; ``automatic``
  (issue 16), 1 torus with 1.00 M triangles, films of roughness 0.05 / 0.3 / 0.6
  (``viewport.AUTOMATIC_ROUGHNESS``) at their automatic order with the World's lamps, as the
  product draws them (medium and rough: the SH half from the outgoing-radiance grid, an RGBA16F
  2-D array, LINEAR, REPEAT in u) and, cases "<film>-perpixel", with the per-pixel SH sum.

``measure`` draws each case as ``gpu.draw.submit`` does: into an RGBA8 framebuffer with a 24-bit
depth buffer, cleared to 0 and depth 1, depth test LEQUAL with writes, no blending, no culling,
display sRGB variants (exposure 0), one bind of each group's resources and one draw call per
object. Textures: RGBA32F; the table and film read with ``texelFetch`` (NEAREST, CLAMP_TO_EDGE:
Blender's default sampler), the prefiltered World LINEAR without mipmaps, REPEAT in u and
CLAMP_TO_EDGE in v and w (``gpu.resources.PrefilterTexture``). Each case: warm-up frames, then
rounds over the cases of one scene in alternating order; per frame the GPU time of a
``GL_TIME_ELAPSED`` query around the clear and the draws, and the wall time from the first call
to the return of ``glFinish``. Medians are reported; a case ``clear`` (the clear alone) is timed
with them. Our draw only: Blender's draw manager, the Workbench pass underneath and the Python
work per frame (``scene_draw.collect``, ``prepare_draw``) are not in it (docs/performance.md
measures those).

``check`` proves that the harness draws what the product draws: the same cases at 480×270
through ``gpu.draw.draw_items`` into a ``GPUOffScreen`` (RGBA8, display sRGB) and through
``measure`` (a subprocess) on the same OpenGL; the 8-bit pictures must agree to 1 level.
``measure`` compares its pictures with ``OUTDIR/pictures-check.npz`` when it is there (the
harness's pictures from ``check``), which gives the difference between the two drivers.

Modules: ``config`` (scenes, cases, sizes, rounds), ``store`` (the OUTDIR format), ``record`` and
``prepare`` (bpy: what the extension draws, recorded), ``gl`` (OpenGL entry points through ctypes),
``harness`` (GLSL declarations, GPU objects and frames in moderngl), ``measure``, ``pictures``
(8-bit comparisons), ``check`` (bpy + a ``measure`` subprocess), ``report``; ``__main__`` is the
command line. Only ``record``, ``prepare`` and ``check`` import bpy, the add-on or precompute (the
machine with Blender); ``measure`` needs numpy and moderngl, ``report`` and ``compare`` numpy at most.
The command line imports ``prepare``, ``check`` and ``measure`` only when their command runs.
"""
