"""The blend file's working colour space: one reading, one fallback, for every room.

Blender 5.x stores the working (scene linear) space per file in
``bpy.data.colorspace.working_space``: "Linear Rec.709", "Linear Rec.2020" or "ACEScg"; older
versions have none. :func:`working_space` is what the whole add-on works in — the bakes' RGB
matrices (``Material.colour_space``), the World's SH and the conversion of its images, the
display transform's source, the headless EXR's chromaticities and PNG, the panorama's pixels —
so that everything one frame multiplies is in one space.

The fallback is :data:`DEFAULT_WORKING_SPACE` (Linear Rec.709) both for a file that names none
and for a name ``precompute`` has no primaries for (:data:`precompute.colour.rgb_spaces.WORKING_SPACES`):
a bake can only be made in a space ``precompute`` knows, so the World and the frame follow the
bake there rather than label Rec.709 data with another space's name. The material panel says so
(:func:`unsupported_working_space`). Blender 5.2 offers only the three known spaces, so the
fallback serves older files and configurations that add their own.
"""

from __future__ import annotations

import bpy

from ..precompute.colour import rgb_spaces

__all__ = ["DEFAULT_WORKING_SPACE", "file_working_space", "unsupported_working_space", "working_space"]

#: The working space of files that name none, or one ``precompute`` does not know.
DEFAULT_WORKING_SPACE = rgb_spaces.DEFAULT_SPACE


def file_working_space() -> str:
    """The working space's name as the blend file stores it ("" before Blender 5.x)."""
    colorspace = getattr(bpy.data, "colorspace", None)
    return getattr(colorspace, "working_space", "") if colorspace is not None else ""


def working_space() -> str:
    """The working space the add-on works in: the file's when ``precompute`` knows it, else
    :data:`DEFAULT_WORKING_SPACE` (see the module docstring)."""
    name = file_working_space()
    return name if name in rgb_spaces.WORKING_SPACES else DEFAULT_WORKING_SPACE


def unsupported_working_space() -> str:
    """The file's working space when it names one the add-on cannot work in (it then works in
    :data:`DEFAULT_WORKING_SPACE`), else ""."""
    name = file_working_space()
    return name if name and name not in rgb_spaces.WORKING_SPACES else ""
