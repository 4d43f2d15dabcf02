"""A description's baked SH table: in memory, else the disk cache, else a fresh bake.

- :func:`get_table` / :func:`get_table_with_source` — the table of a
  :class:`~precompute.material.Material`: :data:`MEMORY` (an LRU keyed by
  :func:`.description.description_key`), then the on-disk
  :class:`~precompute.table_io.TableCache` in the preferences' directory (:func:`table_cache`),
  then :func:`precompute.bake.bake`. Equal descriptions share one table. Thread-safe: the bake
  operator calls it from a worker thread.
- :func:`peek_table` — the table if it is in memory (the draw callback never bakes).
- :func:`format_plan` / :func:`parse_plan` / :func:`shading_path` — the lines the panel shows.

:data:`bake_count` counts the real bakes (cache misses) since the module was loaded; the tests
read it.
"""

from __future__ import annotations

import logging
import threading

import numpy as np

from ..precompute import bake, table_io
from ..precompute.material import Material
from ..precompute.shading import policy
from . import caches
from .description import description_key
from .prefs import cache_dir

__all__ = [
    "LRU_SIZE",
    "MEMORY",
    "bake_count",
    "clear_caches",
    "clear_memory_cache",
    "format_plan",
    "get_table",
    "get_table_with_source",
    "parse_plan",
    "peek_table",
    "shading_path",
    "table_cache",
]

log = logging.getLogger(__name__)

#: Entries kept in the in-memory table cache.
LRU_SIZE = 32
#: Baked tables by description key (see :mod:`.caches`).
MEMORY = caches.register("tables", caches.LRU(LRU_SIZE), scope=caches.SESSION)

#: Number of real bakes (cache misses) since the module was loaded; the tests read it.
bake_count = 0
_count_lock = threading.Lock()


def table_cache() -> table_io.TableCache:
    """The on-disk cache in the directory chosen in the add-on preferences (or the default)."""
    return table_io.TableCache(cache_dir())


def peek_table(desc: Material):
    """The table of ``desc`` if it is in memory (never touches the disk, never bakes), else None."""
    return MEMORY.get(description_key(desc))


def _attributes(result) -> dict:
    attrs = result.attributes()
    attrs["reasons"] = {k: str(v) for k, v in result.reasons.items()}
    attrs["timings_s"] = {k: float(v) for k, v in result.timings_s.items()}
    attrs["wavelengths_nm"] = [float(w) for w in result.wavelengths_nm]
    return attrs


def _from_table(table) -> bake.BakeResult:
    a = table.attributes
    lo, hi = a["thickness_axis_nm"]
    return bake.BakeResult(
        data=np.array(table.data),
        material=Material.from_dict(a["material"]),
        sh_order=int(a["sh_order"]),
        view_angles_rad=bake.view_angles(int(a["view_samples"])),
        thicknesses_nm=np.linspace(float(lo), float(hi), int(a["thickness_samples"])),
        wavelengths_nm=np.asarray(a["wavelengths_nm"], dtype=float),
        u_nodes=int(a["u_nodes"]),
        reasons=dict(a.get("reasons", {})),
        timings_s=dict(a.get("timings_s", {})),
    )


def get_table_with_source(desc: Material, cache=None, progress=None) -> tuple[bake.BakeResult, str]:
    """Like :func:`get_table`, also saying where the table came from: memory, disk or bake."""
    global bake_count
    key = description_key(desc)
    hit = MEMORY.get(key)
    if hit is not None:
        return hit, "memory"
    if cache is None:
        cache = table_cache()
    expect = {"material": bake.table_material(desc).to_dict()}  # what bake() stores
    table = None
    try:
        table = cache.load(key, expect=expect, kind=bake.FORMAT_KIND)
    except OSError as exc:
        log.warning("thinfilm_sh: cache %s unreadable (%s); baking", cache.directory, exc)
    if table is not None:
        try:
            result = _from_table(table)
        except (KeyError, TypeError, ValueError) as exc:  # a valid EXR but not one of ours
            log.warning("thinfilm_sh: cached table %s unusable (%s); baking", table.path, exc)
        else:
            MEMORY[key] = result
            return result, "disk"
    result = bake.bake(desc, progress)
    with _count_lock:
        bake_count += 1
    try:
        cache.store(key, result.data, _attributes(result), kind=bake.FORMAT_KIND)
    except (OSError, ValueError) as exc:
        log.warning("thinfilm_sh: could not store the table in %s: %s", cache.directory, exc)
    MEMORY[key] = result
    return result, "bake"


def get_table(desc: Material, cache=None, progress=None) -> bake.BakeResult:
    """The baked table of ``desc``: from memory, else the disk cache, else a fresh bake.

    ``cache`` is a :class:`~precompute.table_io.TableCache` (default: :func:`table_cache`).
    A corrupt disk entry is moved aside by the cache and re-baked. ``progress(fraction, text)``
    is passed to :func:`precompute.bake.bake`; an exception it raises aborts the bake and
    nothing is stored. Thread-safe.
    """
    return get_table_with_source(desc, cache, progress)[0]


def clear_memory_cache() -> None:
    """Empty the in-memory tables (:data:`MEMORY`)."""
    MEMORY.clear()


def clear_caches(cache=None) -> int:
    """Empty the in-memory tables and the disk cache; returns how many files were removed."""
    clear_memory_cache()
    return (cache or table_cache()).clear()


# ----------------------------------------------------------------------------------------------
# What the panel shows
# ----------------------------------------------------------------------------------------------
_PLAN_ORDER = ("sh_order", "view_samples", "thickness_samples", "wavelength_count", "u_nodes")


def shading_path(roughness: float) -> str:
    """How the viewport and the headless render shade a film of this roughness, for the panel.

    policy.sh_weight: 0 → the split sum alone (prefiltered World × the film's albedo at the
    lobe light's angle), 1 → the SH path alone, between them a blend.
    """
    w = policy.sh_weight(roughness)
    if w <= 0.0:
        return "Shading: split sum (glossy)"
    if w >= 1.0:
        return "Shading: spherical harmonics (rough)"
    return f"Shading: split sum {100 * (1 - w):.0f} % + SH {100 * w:.0f} %"


def format_plan(result, source: str = "bake") -> str:
    """One line per quality choice, "name value: reason", then where the table came from."""
    values = {
        "sh_order": result.sh_order,
        "view_samples": int(result.view_angles_rad.size),
        "thickness_samples": int(result.thicknesses_nm.size),
        "wavelength_count": int(result.wavelengths_nm.size),
        "u_nodes": result.u_nodes,
    }
    lines = [f"{name} {values[name]}: {result.reasons.get(name, '')}".rstrip(": ") for name in _PLAN_ORDER]
    lines.append(f"source {source}")
    return "\n".join(lines)


def parse_plan(text: str) -> dict[str, str]:
    """name → chosen value from :func:`format_plan`'s text (for the panel)."""
    out = {}
    for line in text.splitlines():
        name, _, rest = line.partition(" ")
        out[name] = rest.partition(":")[0].strip()
    return out
