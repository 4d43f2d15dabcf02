"""Fixtures of the GPU draw tests (addon/gpu/ + glsl/ against their numpy twins).

The shared scene helpers (bakes, the World, the camera, the tilted quad) are plain functions of
test_gpu_draw.py, which the other files here import from it.
"""

import pytest
from _extension import gpu_layer, linked_extension


@pytest.fixture(scope="module")
def gd(bpy, tmp_path_factory):
    """``addon.gpu`` (its modules imported) inside the package ``thinfilm_sh`` (relative imports
    work), with a GPU context: one per test file."""
    with linked_extension(tmp_path_factory.mktemp("ext"), unregister=False):
        layer = gpu_layer()
        layer.context.ensure_gpu_context()
        yield layer
        # the GPU objects this copy of the layer keeps, freed while Blender runs (the extension
        # is not registered here, so its unregister does not empty them; one collected at
        # interpreter exit, after Blender's own, crashes the process)
        layer.draw.FULLSCREEN_TRIANGLE.clear()
        layer.draw.UNIFORMS.clear()
        layer.shaders.SHADERS.clear()
