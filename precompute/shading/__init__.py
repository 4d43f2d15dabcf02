"""The numpy mirror of the shader: one module per GLSL chunk, and the rules both share.

Which numpy function mirrors which GLSL function is listed once, in :mod:`.mirror` (shown in
docs/ARCHITECTURE.md and checked by tests/test_mirror.py). ``policy`` holds every shading rule
and emits them as the shaders' ``#define``s; ``variant`` decides which shader a draw compiles;
``codegen`` generates the band-by-band GLSL and counts its operations. The brute-force ground
truth these are checked against (no SH) is :func:`precompute.output.render.shade_reference`;
tests/drawing/test_gpu_draw.py runs the GLSL per pixel against these functions.
This package imports nothing on import: take the modules you need.
"""
