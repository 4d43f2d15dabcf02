"""Fixtures of the tests of the add-on in a real Blender (materials, registration, UI, glTF).

Each test file builds its per-test fixture (a fresh factory file with the extension registered
and the modules it needs) on :func:`package`.
"""

import pytest
from _extension import linked_extension


@pytest.fixture(scope="module")
def package(bpy, tmp_path_factory):
    """The repository imported as ``thinfilm_sh`` (once per test file), forgotten afterwards."""
    with linked_extension(tmp_path_factory.mktemp("extension")) as module:
        yield module
