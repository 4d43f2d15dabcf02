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
# Viewport bakes run in process in the tests: many replace precompute.bake.bake to slow a bake
# down or make it fail, which a helper process would not see. tests/test_bake_helper.py turns
# the helper on and tests it through the viewport's own path.
os.environ["THINFILM_SH_BAKE_HELPER"] = "0"


@pytest.fixture(scope="session")
def bpy():
    """Blender as a Python module (the real one, never mocked), shared by the Blender tests."""
    import bpy as bpy_module

    return bpy_module


class _RepositoryRootIsNotATestPackage:
    """The repository root has an ``__init__.py`` (it is the extension package), so pytest would
    collect it as a test package and import that ``__init__.py`` before the first test, under the
    checkout folder's name. A folder name that is not a Python identifier (``thin-film-sh``, a
    git worktree ``wt-x``) makes that a bare ``import __init__`` whose relative imports fail: every
    test errors. The root is collected as a plain folder instead; the tests import the extension
    as ``thinfilm_sh`` themselves (tests/_extension.py)."""

    def __init__(self, root):
        self.root = root

    @pytest.hookimpl(tryfirst=True)
    def pytest_collect_directory(self, path, parent):
        if path == self.root and (path / "__init__.py").is_file():
            return pytest.Dir.from_parent(parent, path=path)
        return None


def pytest_configure(config):
    config.pluginmanager.register(_RepositoryRootIsNotATestPackage(config.rootpath), "thinfilm-root-dir")
