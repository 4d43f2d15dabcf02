"""The extension registered with its EEVEE path, for the EEVEE-native film's tests."""

import pathlib
import tempfile

import pytest
from _extension import registered_extension


@pytest.fixture(scope="module")
def ext(bpy):
    """The extension registered from a temporary copy, its EEVEE modules in the namespace."""
    root = pathlib.Path(tempfile.mkdtemp(prefix="tf_eevee_"))
    with registered_extension(
        bpy,
        root,
        [
            "addon.eevee.sync",
            "addon.eevee.source",
            "addon.eevee.nodes",
            "addon.bakes.tables",
            "precompute.bakes.eevee_table",
            "addon.drawing.viewport",
            "addon.ui.prefs",
        ],
    ) as ns:
        ns.root = root
        yield ns
