"""Shared pytest configuration: hypothesis profiles sized for 2-core CI machines, the bpy fixture,
the order in which the two workers get the test files, the repository root as a plain folder.

The tests live in feature folders (optics/, sh/, parity/, world/, bake/, viewport/, drawing/,
headless/, extension/, eevee/); each folder's conftest.py holds the fixtures its files share. The helpers
shared across folders are modules in tests/ (on pythonpath): _extension.py, _waits.py,
_cycles_scenes.py, _sh_irradiance.py.
"""

import os
from pathlib import Path

import pytest
from _why import reason
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
# down or make it fail, which a helper process would not see. tests/viewport/test_bake_helper.py turns
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


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """A failed test's report gets a section saying why the check matters (tests/_why.py)."""
    outcome = yield
    report = outcome.get_result()
    if report.failed and call.when == "call":
        report.sections.append(("why this test matters", reason(item)))


def pytest_configure(config):
    config.pluginmanager.register(_RepositoryRootIsNotATestPackage(config.rootpath), "thinfilm-root-dir")


#: The test files that take longest in the fast set, longest first (2 cores, cold shader cache;
#: docs/benchmarks.md#test-suite). ``--dist loadfile`` hands whole files to the two workers in
#: collection order: these go first, so no long file starts when the other worker is nearly done
#: (the longest-processing-time rule). Files not listed keep their order after them.
LONGEST_FIRST = (
    "headless/test_headless.py",
    "headless/test_sample_scenes.py",
    "drawing/test_gpu_draw.py",
    "headless/test_frame.py",
    "bake/test_bake.py",
    "world/test_panorama_helper.py",
    "world/test_world.py",
    "parity/test_cycles_parity.py",
    "parity/test_glossy.py",
    "drawing/test_viewport_perf_invariants.py",
    "drawing/test_radiance_grid.py",
    "optics/test_film_channels.py",
    "headless/test_display.py",
    "world/test_live_world.py",
    "viewport/test_radiance_grid_viewport.py",
    "viewport/test_bake_helper.py",
    "eevee/test_eevee_native.py",  # 53 s alone at load 2 (14 EEVEE final renders)
)


def pytest_collection_modifyitems(config, items):
    """Put the files of :data:`LONGEST_FIRST` first, in its order; a stable sort keeps the order
    of the tests within each file and of every other file (the same on every worker)."""
    here = Path(__file__).parent
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}

    def key(item):
        path = Path(item.path)
        name = path.relative_to(here).as_posix() if path.is_relative_to(here) else ""
        return rank.get(name, len(rank))

    items.sort(key=key)
