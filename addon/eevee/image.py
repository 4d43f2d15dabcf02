"""The film's EEVEE image: a float image packed into the .blend, written in place on an edit.

One image per film group (:mod:`.nodes`), named ``TF EEVEE · <material>``: float RGBA,
*Non-Color*, packed as OpenEXR (float pixels survive a save and reload), with the key of what
it holds (:data:`KEY`) as a custom property, so an unchanged film is never rewritten and a
reopened file needs no bake. The pixels come from :func:`precompute.bakes.eevee_table.film_image`,
computed off the main thread; :func:`write` only copies them in (``foreach_set``), updates and
packs: milliseconds for the largest table (docs/eevee-native.md).
"""

from __future__ import annotations

import bpy
import numpy as np

from . import nodes

__all__ = ["IMAGE_PREFIX", "KEY", "LIGHT_PREFIX", "OWNER", "ensure", "ensure_light", "stored_key", "write"]

IMAGE_PREFIX = "TF EEVEE · "
#: The dominant-direction image's name prefix.
LIGHT_PREFIX = "TF EEVEE Light · "
#: Custom properties on the image: the key of its content, and a mark that the extension made it.
KEY = "thinfilm_eevee_key"
OWNER = "thinfilm_eevee_group"


def stored_key(image) -> str | None:
    """The key of what ``image`` holds (None for no image or an unwritten one)."""
    return None if image is None else image.get(KEY)


def _owned(image, group) -> bool:
    """Whether ``group`` alone uses ``image`` (each of its textures counts one user): an image
    shared with a copied material's group is not."""
    if image is None or image.library is not None:
        return False
    mine = sum(1 for n in group.nodes if getattr(n, "image", None) == image)
    return image.users <= mine


def _new(name: str, width: int, height: int):
    image = bpy.data.images.new(name, width, height, alpha=True, float_buffer=True)
    image.colorspace_settings.name = "Non-Color"
    image.alpha_mode = "NONE"
    return image


def _ensure(current, group, name: str, width: int, height: int):
    """``current`` when ``group`` alone uses it (resized to ``width`` × ``height`` when needed),
    else a new image ``name`` of that size."""
    if not _owned(current, group):
        image = _new(name, width, height)
        image[OWNER] = 1
        return image
    if tuple(current.size) != (width, height):
        current.scale(width, height)
    return current


def ensure(group, material_name: str, width: int, height: int):
    """The film image ``group`` reads, made for it when it has none or shares one with another
    group (a copied material), resized to ``width`` × ``height`` when its table's size changed."""
    return _ensure(nodes.film_image_of(group), group, IMAGE_PREFIX + material_name, width, height)


def ensure_light(group, material_name: str, width: int, height: int):
    """The dominant-direction image of ``group`` (its lookup "light"), made when it has none or
    shares one, resized when needed."""
    current = getattr(group.nodes.get("light"), "image", None)
    return _ensure(current, group, LIGHT_PREFIX + material_name, width, height)


def write(image, pixels: np.ndarray, key: str) -> None:
    """Copy ``pixels`` (H, W, 4) into ``image`` (already that size), pack it as float OpenEXR and
    record ``key``. Main thread; no computation here."""
    flat = np.ascontiguousarray(pixels, dtype=np.float32).reshape(-1)
    if flat.size != len(image.pixels):
        image.scale(int(pixels.shape[1]), int(pixels.shape[0]))
    image.pixels.foreach_set(flat)
    image.file_format = "OPEN_EXR"
    image.update()
    image.pack()
    image[KEY] = key
