"""Fixtures of the viewport tests: the extension registered once per file, an empty scene per test.

test_live.py defines its own ``tf``/``scene`` (a start-up file with a 3D viewport, other
modules); the plain helpers (``film``, ``grid``, ``collect``, ``redraw``) are those of
test_viewport_state.py, which the other files here import from it.
"""

import pytest
from _extension import registered_extension


@pytest.fixture(scope="module")
def tf(bpy, tmp_path_factory):
    """The extension, registered once for the module, with a private table cache."""
    root = tmp_path_factory.mktemp("extension")
    modules = (
        "addon.drawing.scene_draw",
        "addon.drawing.viewport",
        "addon.drawing.lights",
        "addon.materials.props",
        "addon.ui.prefs",
        "addon.ui.ui",
        "addon.bakes.tables",
        "addon.bakes.bake_jobs",
        "addon.thickness.thickness",
        "addon.thickness.linked",
        "addon.thickness.corners",
        "addon.world.panorama",
        "addon.world.world",
        "addon.world.world_state",
        "addon.workers",
        "precompute.bakes.bake",
        "precompute.bakes.planner",
        "precompute.bakes.kernel",
        "precompute.tables.table_io",
        "precompute.tables.atomic_write",
        "precompute.tables.table_cache",
    )
    with registered_extension(bpy, root, modules, cache_preference=False, gpu=True) as ns:
        yield ns


@pytest.fixture
def scene(bpy, tf):
    """An empty file (no World: nothing to render for the lighting), the caches emptied."""
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    tf.package.register()
    tf.prefs.preferences().cache_dir = tf.cache_dir
    tf.tables.clear_caches()  # memory, remembered failures and the disk cache
    tf.scene_draw.CACHES.clear()
    return bpy.context.scene
