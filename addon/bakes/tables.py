"""A description's baked SH table: in memory, else the disk cache, else a fresh bake.

- :func:`get_table` / :func:`get_table_with_source` — the table of a
  :class:`~precompute.materials.material.Material`: :data:`MEMORY` (an LRU keyed by
  :func:`.description.description_key`), then the on-disk
  :class:`~precompute.tables.table_cache.TableCache` in the preferences' directory (:func:`table_cache`),
  then :func:`precompute.bakes.bake.bake`. Equal descriptions share one table. Thread-safe: the bake
  operator calls it from a worker thread.
- :func:`peek_table` — the table if it is in memory (the draw callback never bakes).
- :func:`get_film` / :func:`peek_film` — the film table (the World lamps' and light objects'
  reflectance, :func:`precompute.colour.film_colour.film_table`) of a baked table, computed once per
  description key beside it in :data:`FILMS`: on the viewport bake's worker, never in a draw.
- :func:`table_cache` — the disk cache: ``--cache-dir`` (:func:`cache_dir_override`), else
  :func:`.prefs.cache_location` (``THINFILM_SH_CACHE``, the preference, the default), with the
  size limit of :func:`.prefs.cache_max_bytes`.
- :func:`failure` / :func:`record_failure` — bakes that failed, by description key: the
  viewport does not retry them until the material's description changes (or the cache is
  cleared, or the Bake button succeeds), and the panel shows the error.
- :func:`cache_error` — why a table could not be read from or stored in the disk cache (an
  unusable directory, a full disk): the table is still baked and kept in memory, and drawn.
- :func:`format_plan` / :func:`parse_plan` / :func:`shading_path` — the lines the panel shows.

:data:`bake_count` counts the real bakes (cache misses) since the module was loaded; the tests
read it.
"""

from __future__ import annotations

import contextlib
import logging
import threading
from dataclasses import dataclass

import numpy as np

from ...precompute.bakes import bake, kernel, planner
from ...precompute.bakes.progress import reporting
from ...precompute.colour import film_colour
from ...precompute.commands import cli_support
from ...precompute.materials.material import Material
from ...precompute.shading import policy
from ...precompute.tables.table_cache import TableCache
from .. import caches
from ..materials.description import description_key
from ..ui import prefs

__all__ = [
    "CACHE_ERRORS",
    "FAILURES",
    "FILMS",
    "FAILURE_MEMORY",
    "LRU_SIZE",
    "MEMORY",
    "UnusableCache",
    "bake_count",
    "cache_dir_override",
    "cache_error",
    "clear_caches",
    "clear_memory_cache",
    "failure",
    "format_plan",
    "get_film",
    "get_table",
    "get_table_with_source",
    "keep_film",
    "open_cache",
    "parse_plan",
    "peek_film",
    "peek_table",
    "record_failure",
    "shading_path",
    "table_cache",
]

log = logging.getLogger(__name__)

#: Entries kept in the in-memory table cache.
LRU_SIZE = 32
#: Baked tables by description key (see :mod:`.caches`).
MEMORY = caches.register("tables", caches.LRU(LRU_SIZE), scope=caches.SESSION)

#: Film tables (:class:`precompute.colour.film_colour.FilmTable`) by description key, one per table kept.
FILMS = caches.register("film_tables", caches.LRU(LRU_SIZE), scope=caches.SESSION)
#: Film tables computed since the module was loaded, by the name of the thread that computed
#: each (the tests check that none was computed by the draw's thread).
film_threads: list[str] = []

#: Failures remembered (distinct failing descriptions; each entry is one error line).
FAILURE_MEMORY = 64
#: Error text of failed bakes by description key (see :func:`failure`, :mod:`.caches`).
FAILURES = caches.register("bake_failures", caches.LRU(FAILURE_MEMORY), scope=caches.SESSION)
#: Why the disk cache could not be used for a description key's table (see :func:`cache_error`).
CACHE_ERRORS = caches.register("cache_errors", caches.LRU(FAILURE_MEMORY), scope=caches.SESSION)

#: Number of real bakes (cache misses) since the module was loaded; the tests read it.
bake_count = 0
_count_lock = threading.Lock()
_override: str | None = None


@contextlib.contextmanager
def cache_dir_override(directory):
    """Use ``directory`` for the disk cache inside the ``with`` block (the headless commands'
    ``--cache-dir``); None changes nothing."""
    global _override
    saved = _override
    if directory is not None:
        _override = str(directory)
    try:
        yield
    finally:
        _override = saved


def table_cache() -> TableCache:
    """The disk cache: ``--cache-dir``, else ``THINFILM_SH_CACHE``, else the preference, else the
    default (:func:`.prefs.cache_location`), bounded by :func:`.prefs.cache_max_bytes`.

    Raises :class:`~precompute.tables.table_cache.CacheDirError` (an ``OSError``) or ``ValueError`` (a
    malformed ``THINFILM_SH_CACHE_MAX_BYTES``) with a message for the user.
    """
    directory = _override if _override is not None else prefs.cache_location()[0]
    return TableCache(directory, max_bytes=prefs.cache_max_bytes())


@dataclass(frozen=True)
class UnusableCache:
    """Stands for a disk cache that could not be opened (:func:`open_cache`); ``reason`` says why."""

    reason: str


def open_cache():
    """:func:`table_cache`, or an :class:`UnusableCache` with the reason: never raises. Call it in
    the main thread (it reads the preferences) and hand the result to worker threads."""
    try:
        return table_cache()
    except (OSError, ValueError) as exc:
        return UnusableCache(f"table cache unusable: {exc}")


def failure(desc: Material) -> str | None:
    """The error of the last failed bake of ``desc`` (by description key), or None."""
    return FAILURES.get(description_key(desc))


def record_failure(desc: Material, exc: BaseException) -> str:
    """Remember that baking ``desc`` failed with ``exc``; returns the error line kept."""
    text = str(exc) if isinstance(exc, (ValueError, OSError)) and str(exc) else repr(exc)
    FAILURES[description_key(desc)] = text
    return text


def cache_error(desc: Material) -> str | None:
    """Why the table of ``desc`` is not in the disk cache (it is in memory), or None."""
    return CACHE_ERRORS.get(description_key(desc))


def peek_table(desc: Material):
    """The table of ``desc`` if it is in memory (never touches the disk, never bakes), else None."""
    return MEMORY.get(description_key(desc))


def peek_film(desc_key: str):
    """The film table of the description key ``desc_key`` if it was computed, else None."""
    return FILMS.get(desc_key)


def get_film(desc: Material, result: bake.BakeResult | None, progress=None):
    """The film table of ``desc`` (its baked table ``result``): from :data:`FILMS`, else
    computed (:func:`precompute.colour.film_colour.film_table`: ≈ 10 ms from a fresh bake's reflectance
    at its u nodes, 20–50 ms by a sweep for a table read from disk) and kept. Without ``result``
    it is computed from ``desc`` alone (:func:`~precompute.colour.film_colour.film_table_of`).

    ``progress(fraction, text)`` is called at the computation's checkpoints (fraction 1: the
    table is done) and may raise to cancel it; nothing is kept then. Thread-safe: the viewport
    calls it on the bake's worker.
    """
    key = description_key(desc)
    found = FILMS.get(key)
    if found is not None:
        release_nodes(result)
        return found

    def hook():
        if progress is not None:
            progress(1.0, "film table")

    with reporting(hook):
        found = film_colour.film_table(result) if result is not None else film_colour.film_table_of(desc)
    with _count_lock:
        film_threads.append(threading.current_thread().name)
    FILMS[key] = found
    release_nodes(result)
    return found


def keep_film(desc: Material, film) -> None:
    """Keep ``film``, the film table of ``desc`` computed elsewhere (the bake helper process,
    :mod:`.bake_helper`, with its table), for :func:`get_film` and :func:`peek_film`."""
    FILMS[description_key(desc)] = film


def release_nodes(result) -> None:
    """Drop a fresh bake's reflectance at its u nodes (kept by ``keep_nodes`` for its film
    table): the table in memory does not need it."""
    if result is not None:
        result.node_reflectance = None


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
        view_angles_rad=kernel.view_angles(int(a["view_samples"])),
        thicknesses_nm=np.linspace(float(lo), float(hi), int(a["thickness_samples"])),
        wavelengths_nm=np.asarray(a["wavelengths_nm"], dtype=float),
        u_nodes=int(a["u_nodes"]),
        reasons=dict(a.get("reasons", {})),
        timings_s=dict(a.get("timings_s", {})),
    )


def get_table_with_source(
    desc: Material,
    cache=None,
    progress=None,
    store: bool = True,
    keep_nodes: bool = False,
    baker=None,
) -> tuple[bake.BakeResult, str]:
    """Like :func:`get_table`, also saying where the table came from: memory, disk or bake.

    ``store`` False: a baked table is kept in memory only; the caller writes it to the disk
    cache later with :func:`store_table` (the viewport's worker first lets the frame show it:
    writing the soap preset's 61-row table takes 0.4–2 s). ``keep_nodes``: a fresh bake keeps
    its reflectance at its u nodes (``BakeResult.node_reflectance``) until :func:`get_film` or
    :func:`release_nodes` drops it, so its film table needs no second sweep. ``baker(desc,
    progress)`` bakes in place of :func:`precompute.bakes.bake.bake` (the viewport's: the bake helper
    process, :func:`.bake_helper.baker`)."""
    global bake_count
    key = description_key(desc)
    hit = MEMORY.get(key)
    if hit is not None:
        return hit, "memory"
    problem = None  # why the disk cache was not used: reported, never fatal
    if cache is None:
        cache = open_cache()
    if isinstance(cache, UnusableCache):
        problem, cache = cache.reason, None
    expect = {"material": planner.table_material(desc).to_dict()}
    table = None
    if cache is not None:
        try:
            table = cache.load(key, expect=expect, kind=bake.FORMAT_KIND)
        except OSError as exc:
            problem = f"table cache unreadable: {exc}"
    if table is not None:
        try:
            result = _from_table(table)
        except (KeyError, TypeError, ValueError) as exc:  # a valid EXR but not one of ours
            log.warning("thinfilm_sh: cached table %s unusable (%s); baking", table.path, exc)
        else:
            MEMORY[key] = result
            CACHE_ERRORS.pop(key)
            return result, "disk"
    result = (baker or bake.bake)(desc, progress)
    with _count_lock:
        bake_count += 1
    if not keep_nodes:  # up to 4.5 MiB, only a film table computed next reads it (get_film)
        result.node_reflectance = None
    MEMORY[key] = result  # kept (and drawn) whatever happens to the disk copy
    FAILURES.pop(key)
    if store:
        _store(key, result, cache, problem)
    elif problem is not None:
        _store(key, result, None, problem)  # the disk cache is unusable: say so now
    return result, "bake"


def store_table(desc: Material, result: bake.BakeResult, cache=None) -> None:
    """Write a table baked with ``store=False`` (:func:`get_table_with_source`) to the disk
    cache; a failure is reported by :func:`cache_error`, never raised. Thread-safe."""
    if cache is None:
        cache = open_cache()
    if isinstance(cache, UnusableCache):
        return  # reported when it was baked
    _store(description_key(desc), result, cache, None)


def _store(key: str, result: bake.BakeResult, cache, problem: str | None) -> None:
    if cache is not None:
        try:
            cache.store(key, result.data, _attributes(result), kind=bake.FORMAT_KIND)
        except (OSError, ValueError) as exc:  # TableWriteError (disk full, …), CacheDirError
            problem = f"table not saved to the disk cache (kept in memory): {exc}"
    if problem is None:
        CACHE_ERRORS.pop(key)
    else:
        CACHE_ERRORS[key] = problem
        log.warning("thinfilm_sh: %s", problem)


def get_table(desc: Material, cache=None, progress=None) -> bake.BakeResult:
    """The baked table of ``desc``: from memory, else the disk cache, else a fresh bake.

    ``cache`` is a :class:`~precompute.tables.table_cache.TableCache`, an :class:`UnusableCache` (none:
    bake, keep in memory, report the reason) or None (:func:`open_cache`, which reads the
    preferences: pass the cache in from the main thread when calling from a worker).
    A corrupt disk entry is moved aside by the cache and re-baked. A disk cache that cannot be
    used (an unsafe or uncreatable directory, a full disk) never fails the call: the table is
    baked, kept in memory and returned, and :func:`cache_error` says what went wrong.
    ``progress(fraction, text)`` is passed to :func:`precompute.bakes.bake.bake`; an exception it
    raises aborts the bake and nothing is stored. Thread-safe.
    """
    return get_table_with_source(desc, cache, progress)[0]


def clear_memory_cache() -> None:
    """Empty the in-memory tables (:data:`MEMORY`) and their film tables (:data:`FILMS`)."""
    MEMORY.clear()
    FILMS.clear()


def clear_caches(cache=None) -> int:
    """Empty the in-memory tables, the remembered failures and the disk cache (only the files
    the cache wrote, :meth:`~precompute.tables.table_cache.TableCache.clear`); returns how many files were
    removed. Raises ``OSError`` (:class:`~precompute.tables.table_cache.CacheDirError`) for an unusable
    directory, after emptying memory."""
    clear_memory_cache()
    FAILURES.clear()
    CACHE_ERRORS.clear()
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


def bake_failure(name: str, exc: Exception) -> str:
    """One line on why material ``name`` could not be baked; a bug's traceback goes to a log file."""
    text = f"material {name!r} could not be baked ({type(exc).__name__}: {' '.join(str(exc).split())}"
    if isinstance(exc, (ValueError, OSError)):
        return text + ")"
    where = cli_support.write_log("thinfilm_sh", exc)
    log.error("Thin Film SH: material %r could not be baked: %s (details in %s)", name, exc, where)
    return text + f"; details in {where})"
