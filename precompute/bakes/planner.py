"""What a bake will make: the automatic quality choices, the u-node search and the table's key.

:func:`plan` resolves every ``"auto"`` setting of a :class:`~precompute.materials.material.Material`
(SH order from the roughness, view angles, thickness rows from the fringe density, wavelengths
from the optical path), each with its reason; :func:`choose_u_degree` finds the fewest Chebyshev
nodes per interval that interpolate the film's R(u) within :data:`U_TOLERANCE`;
:func:`table_material` and :func:`table_key` name the table a material needs (with
:data:`PLANNER_VERSION`). The bake itself is :mod:`.bake`.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace

import numpy as np

from .. import constants
from ..materials.material import AUTO, Material
from ..tables import table_io
from .chunks import chunked_sweep
from .kernel import U_EDGES, u_interpolation_matrix, u_nodes
from .sh_order import auto_sh_order

#: Nodes per interval tried in turn until the interpolation error meets U_TOLERANCE.
U_DEGREE_LADDER = (6, 8, 12, 16, 24, 32, 48, 64)
#: The ladder's rungs probed together (one reflectance evaluation per group, ~5 ms of fixed cost
#: each): most films stop in the first group, thick ones in the second.
U_PROBE_GROUPS = ((6, 8, 12, 16), (24,), (32,), (48, 64))
#: Max |R_interp − R| at test points relative to max R; keeps the factorisation error ≪ 1e-5.
U_TOLERANCE = 1e-6
#: Test points skip u < 0.0125 (half-vectors within 0.7° of grazing): the first interval's
#: resonances are narrower still, and only views within 0.7° of the horizon see them.
U_TEST_MIN = U_EDGES[1]


# ----------------------------------------------------------------------------------------------
# Automatic choices
# ----------------------------------------------------------------------------------------------
def optical_path_nm(material: Material) -> float:
    """Upper bound of the round-trip optical path 2 Σ |N_j| d_j over the film (nm), at max thickness.

    A varying top layer counts at the top of its range (the thickest row of the table), never at
    its own ``thickness_nm``, which the table does not use (:func:`table_material`).
    """
    wl = np.array([constants.WAVELENGTH_MIN_NM])
    total = 0.0
    for model, d in zip(material.indices()[1:-1], table_material(material).thicknesses(), strict=False):
        total += float(np.abs(model.index(wl))[0]) * d
    return 2.0 * total


def auto_wavelength_count(material: Material) -> tuple[int, str]:
    """Enough samples that one spans ≤ MAX_PHASE_STEP of fringe phase (Nyquist in wavenumber)."""
    opd = optical_path_nm(material)
    span = 2.0 * np.pi * opd * (1.0 / constants.WAVELENGTH_MIN_NM - 1.0 / constants.WAVELENGTH_MAX_NM)
    count = int(min(4096, max(48, math.ceil(span / constants.MAX_PHASE_STEP))))
    return (
        count,
        f"optical path {opd:.0f} nm → {span / (2 * np.pi):.1f} fringes over 360–830 nm → {count} samples",
    )


def auto_thickness_samples(material: Material) -> tuple[int, str]:
    """Eight samples per fringe at 360 nm across the thickness range (lerp error ≤ 8 % of a fringe)."""
    if not material.varies:
        return 1, "constant thickness: no thickness axis"
    lo, hi = material.thickness_range_nm
    n_top = float(np.abs(material.indices()[1].index(np.array([constants.WAVELENGTH_MIN_NM])))[0])
    fringes = 2.0 * n_top * (hi - lo) / constants.WAVELENGTH_MIN_NM
    count = int(min(128, max(8, math.ceil(8 * fringes) + 1)))
    return count, f"{fringes:.1f} fringes across {lo:g}–{hi:g} nm → {count} samples"


def auto_view_samples(material: Material) -> tuple[int, str]:
    """Narrow lobes change faster with θo: 48 below roughness 0.15, 32 below 0.5, else 16."""
    r = material.roughness
    count = 48 if r < 0.15 else 32 if r < 0.5 else 16
    return count, f"roughness {r:g} → {count} view angles"


def _test_points(degree: int) -> np.ndarray:
    """Where a rung's interpolation is checked: the Chebyshev points of one degree more, from
    ``U_TEST_MIN`` on."""
    test = u_nodes(degree + 1)
    return test[test >= U_TEST_MIN]


@functools.lru_cache(maxsize=16)
def _rung(degree: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A ladder rung's (nodes, test points, interpolation matrix nodes → test points), the same
    for every material: cached (≈ 0.5 ms a rung to build), read-only."""
    test = _test_points(degree)
    matrix = u_interpolation_matrix(degree, test)
    test.flags.writeable = False
    matrix.flags.writeable = False
    return u_nodes(degree), test, matrix


def choose_u_degree(
    indices, thickness_sets, wavelengths_nm, method: str, evaluate=None, tolerance=U_TOLERANCE
):
    """Smallest nodes-per-interval whose interpolation of R(u) meets ``tolerance``.

    Checked on four thickness rows including the thickest (R oscillates fastest in u there) at
    test points interleaved with the nodes (the Chebyshev points of one degree more), for
    u ≥ ``U_TEST_MIN``; then R is evaluated at the chosen nodes for every row, once.
    The search always starts at the bottom of the ladder (a probe step costs 4 rows only), so a
    material's table never depends on what was baked before it; the rungs of a group of
    ``U_PROBE_GROUPS`` are evaluated in one sweep and checked in ladder order.
    ``evaluate(thickness_sets, u)`` → (T, U, C) replaces the spectral reflectance (e.g. the film
    per colour channel, :func:`channel_film`).
    Returns (degree, measured relative error, R at the nodes (T, U, W or C)).
    """
    if evaluate is None:

        def evaluate(sets, u):
            return chunked_sweep(indices, sets, wavelengths_nm, u, method)

    rows = np.unique(np.linspace(0, thickness_sets.shape[0] - 1, 4).round().astype(int))
    probe = thickness_sets[rows]
    err = math.inf
    for group in U_PROBE_GROUPS:  # one evaluation per group of rungs: its fixed cost paid once
        rungs = [_rung(c) for c in group]
        values = evaluate(probe, np.concatenate([np.concatenate(rung[:2]) for rung in rungs]))
        start = 0
        for candidate, (nodes, test, matrix) in zip(group, rungs, strict=True):
            both = values[:, start : start + nodes.size + test.size]
            start += nodes.size + test.size
            at_nodes, exact = both[:, : nodes.size], both[:, nodes.size :]
            interp = np.matmul(matrix, at_nodes)
            err = float(np.max(np.abs(interp - exact))) / max(float(np.abs(exact).max()), 1e-6)
            if err <= tolerance:
                return candidate, err, evaluate(thickness_sets, u_nodes(candidate))
    return U_DEGREE_LADDER[-1], err, evaluate(thickness_sets, u_nodes(U_DEGREE_LADDER[-1]))


@dataclass(frozen=True)
class Plan:
    """Resolved quality choices for a material, with the reason for each."""

    sh_order: int
    view_samples: int
    thickness_samples: int
    wavelength_count: int
    reasons: dict


def plan(material: Material) -> Plan:
    """Resolve every ``"auto"`` quality setting of ``material``."""
    q = material.quality
    reasons = {}

    def pick(name, auto_fn):
        value = getattr(q, name)
        if value == AUTO:
            value, reasons[name] = auto_fn(material)
        else:
            reasons[name] = "set explicitly"
        return int(value)

    sh_order = pick("sh_order", auto_sh_order)
    views = pick("view_samples", auto_view_samples)
    t = pick("thickness_samples", auto_thickness_samples) if material.varies else 1
    if not material.varies:
        reasons["thickness_samples"] = "constant thickness: no thickness axis"
    w = pick("wavelength_count", auto_wavelength_count)
    return Plan(sh_order, views, t, w, reasons)


def thickness_sets(material: Material, count: int) -> tuple[np.ndarray, np.ndarray]:
    """(T, L) thickness sets and the top-layer thickness axis (T,)."""
    base = np.array(material.thicknesses(), dtype=float)
    if not material.varies:
        return base[None, :], base[:1] if base.size else np.zeros(1)
    axis = np.linspace(*material.thickness_range_nm, count)
    sets = np.repeat(base[None, :], count, axis=0)
    sets[:, 0] = axis
    return sets, axis


def active_stack(material: Material, count: int):
    """(indices, thickness sets (T, L'), thickness axis) with constant 0 nm layers removed.

    A layer of thickness exactly 0 that does not vary is optically absent, so it costs nothing:
    a film whose every layer is 0 nm takes the bare-interface path.
    """
    indices = material.indices()
    sets, axis = thickness_sets(material, count)
    keep = [j for j in range(sets.shape[1]) if np.any(sets[:, j] != 0.0)]
    if len(keep) < sets.shape[1]:
        indices = [indices[0]] + [indices[j + 1] for j in keep] + [indices[-1]]
        sets = sets[:, keep]
    return indices, sets, axis


#: Version of the automatic choices and the bake's maths, part of every table's cache key
#: (:func:`table_key`). Bump it when a material's table would come out different: cached tables
#: of the old version are then not reused (they would be stale, not corrupt, so the checks on
#: load cannot see it). 2: SH order up to 12 (was 8). 3: Cycles' colour pipeline in the
#: per-channel mode (film_channels) and Cycles' layering of the diffuse base there.
PLANNER_VERSION = 3


def table_material(material: Material) -> Material:
    """``material`` as its table sees it: what the table does not depend on set to one value.

    With a thickness range the top layer's thickness at each table row is the row's value, so
    the layer's own ``thickness_nm`` is unused; it is set to the top of the range (the thickest
    row, where the wavelength count and the u nodes are planned). Two materials that differ only
    in that unused value then share one plan, one key and one table. Other materials are
    returned unchanged (the same object).
    """
    if not material.varies:
        return material
    top = material.layers[0]
    hi = float(material.thickness_range_nm[1])
    if float(top.thickness_nm) == hi:
        return material
    return material.with_(layers=(replace(top, thickness_nm=hi), *material.layers[1:]))


def table_key(material: Material) -> str:
    """Cache key of a material's table: the parameters it uses (:func:`table_material`) and
    :data:`PLANNER_VERSION`."""
    return table_io.content_key({"material": table_material(material).to_dict(), "planner": PLANNER_VERSION})
