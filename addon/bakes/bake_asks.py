"""What a viewport bake is asked for, and asking early: before the edit's first redraw.

A material whose table is not in memory is handed to the viewport's bake queue
(:func:`.bake_jobs.want`) by the draw (:func:`ask`). Two things make the edit's correct frame
come sooner than "the next draw queues it, the timer starts it, the redraw after that asks for
the grid":

- **Asked at the depsgraph update** (:func:`ask_changed`): Blender evaluates the depsgraph
  (``depsgraph_update_post``) before it redraws the views, so an edited material's bake starts
  there and runs while the edit's first frame is drawn with the previous table.
- **Its grid chained to the bake** (:func:`.radiance_grids.chain`): a constant-thickness film
  drawn from an outgoing-radiance grid needs a new grid for its new table; the bake's worker
  builds it right after the table, under the lighting the material was last drawn with, so the
  one redraw the bake's end asks for shows both (a wrong guess costs one grid build: the draw
  then asks for the right one as before).

The material's last drawn entry (``scene_draw.Caches.previous``) says what it needs besides the
table: its film table, its grid and whether it shades the World's lamps.
"""

from __future__ import annotations

import bpy

from ..materials import description
from ..thickness import linked
from . import bake_jobs, radiance_grids, tables


def material_identity(bpy_material):
    """What the draw keys a material's previous entry and its viewport bake by: its
    ``session_uid`` (stable across renames and edits, unlike the description key)."""
    return getattr(bpy_material, "session_uid", None) or bpy_material.as_pointer()


def ask(desc, owner, previous, lighting, film: bool) -> None:
    """Ask the viewport's bake queue for ``desc``'s table (for the material ``owner``), with its
    film table if ``film``; with the grid chained (``then``) when the material's last drawn
    entry ``previous`` read one under ``lighting`` (a ``WorldLighting``)."""
    then = radiance_grids.chain(previous, lighting)
    if then is None:
        bake_jobs.want(desc, owner=owner, film=film)
    else:
        bake_jobs.want(desc, owner=owner, film=film, then=then)


def ask_changed(depsgraph, previous, lighting) -> int:
    """Ask for the bakes of the materials this depsgraph update changed (the
    ``depsgraph_update_post`` handler, before the redraw); how many were asked.

    Only materials the viewport has drawn (an entry in ``previous``, keyed by
    :func:`material_identity`) under a known ``lighting`` are asked: the draw asks for the
    others. A material whose description cannot be evaluated, or whose table is in memory or
    failed, is left to the draw too.
    """
    if lighting is None or not len(previous):
        return 0
    count = 0
    for update in depsgraph.updates:
        material = update.id
        if not isinstance(material, bpy.types.Material):
            continue
        material = getattr(material, "original", material)
        owner = material_identity(material)
        last = previous.get(owner)
        if last is None:
            continue
        with linked.deferring():  # a linked thickness that needs a Cycles bake waits for the timer
            try:
                desc = description.description(material)
            except ValueError:  # the draw reports it and draws the fallback
                continue
        if desc is None:
            continue
        key = description.description_key(desc)
        if tables.MEMORY.get(key) is not None or tables.FAILURES.get(key) is not None:
            continue
        ask(desc, owner, last, lighting, film=last.film is not None)
        count += 1
    return count
