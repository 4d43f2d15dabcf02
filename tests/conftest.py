"""Shared pytest configuration: hypothesis profiles sized for 2-core CI machines, the bpy fixture."""

import os

import pytest
from hypothesis import HealthCheck, settings

settings.register_profile(
    "ci", max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow], derandomize=True
)
settings.register_profile("dev", max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile("ci" if os.environ.get("CI") else os.environ.get("HYPOTHESIS_PROFILE", "dev"))

# The table cache's environment variables win over the add-on's preference (docs/cache.md): a
# developer's own must not send the tests' tables to their cache. Tests that need them set them.
for _name in ("THINFILM_SH_CACHE", "THINFILM_SH_CACHE_MAX_BYTES"):
    os.environ.pop(_name, None)
# Viewport bakes run in process in the tests: many replace precompute.bakes.bake.bake to slow a bake
# down or make it fail, which a helper process would not see. tests/test_bake_helper.py turns
# the helper on and tests it through the viewport's own path.
os.environ["THINFILM_SH_BAKE_HELPER"] = "0"


@pytest.fixture(scope="session")
def bpy():
    """Blender as a Python module (the real one, never mocked), shared by the Blender tests."""
    import bpy as bpy_module

    return bpy_module
