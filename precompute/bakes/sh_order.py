"""The automatic SH order of a table: from the roughness, by a precomputed table of the criterion.

The criterion (:func:`lobe_truncation_error`): the R ≡ 1 transfer function of the GGX lobe,
projected to band :data:`JUDGE_ORDER` (16) at the judged views (:data:`TRUNCATION_VIEWS_DEG`),
loses at most ``target`` (10 %) of its L2 norm when truncated at l_max; the order is the
smallest l_max in 2…:data:`~precompute.materials.material.MAX_SH_ORDER` that meets it. It depends on the
roughness alone, so the orders it picks are a step function of the roughness, tabulated in
:data:`ORDER_BREAKPOINTS` (by :func:`order_breakpoints`, ``scripts/sh_order_table.py``):
planning reads the table and computes nothing; ``tests/sh/test_sh_order.py`` checks that the
table and the criterion pick the same order on a fine roughness grid and on both sides of every
breakpoint.

The criterion itself is cheap too: with R ≡ 1 the Lagrange weights of the u nodes sum to one,
so the band-16 coefficients are plain weighted sums of the SH over the half-vector nodes at two
views (no u-node kernel).
"""

from __future__ import annotations

import bisect
import functools
import math

import numpy as np

from .. import brdf
from ..materials.material import MAX_SH_ORDER, Material
from ..sh import harmonics
from .kernel import half_vector_nodes, view_cosines, view_weights

__all__ = [
    "DEFAULT_TARGET",
    "JUDGE_ORDER",
    "ORDER_BREAKPOINTS",
    "TRUNCATION_VIEWS_DEG",
    "auto_sh_order",
    "criterion_order",
    "lobe_truncation_error",
    "order_breakpoints",
    "table_order",
]

#: View angles at which the SH truncation is judged: normal incidence, where the lobe is
#: narrowest around its peak, and 80°, where the horizon cuts the lobe — measured against Cycles,
#: the rim of a rough sphere is where a low order fails (ΔE 7.6 at l = 5 vs 4.3 at l = 8,
#: roughness 0.6, studio HDRI), although the normal-view lobe alone would accept l = 5.
TRUNCATION_VIEWS_DEG = (0.0, 80.0)
#: Band to which the lobe is projected to judge a truncation (the energy above it is ignored).
JUDGE_ORDER = 16
#: The judged views are taken on a grid of 10 view angles (every 10°, the cosine clamped as the
#: bake's), as the criterion has always been computed.
JUDGE_VIEW_SAMPLES = 10
#: The lobe truncation error the automatic order must meet.
DEFAULT_TARGET = 0.10

#: (first roughness, order) steps of :func:`criterion_order` at :data:`DEFAULT_TARGET`, from
#: :func:`order_breakpoints` (``scripts/sh_order_table.py``; each breakpoint bisected to 1e-9).
ORDER_BREAKPOINTS: tuple[tuple[float, int], ...] = (
    (0.0, 12),
    (0.6705995588, 11),
    (0.6936687469, 10),
    (0.7181447191, 9),
    (0.7425866699, 8),
    (0.7727860432, 7),
    (0.8053880501, 6),
    (0.8689762211, 5),
    (0.9502279692, 6),
)


@functools.lru_cache(maxsize=256)
def _band_energies(roughness: float) -> np.ndarray:
    """(views, JUDGE_ORDER + 1): energy Σ_m c_lm² per band of the R ≡ 1 lobe at each judged view."""
    alpha = float(brdf.alpha_from_roughness(roughness))
    h, w = half_vector_nodes(alpha)
    cosines = view_cosines(JUDGE_VIEW_SAMPLES)
    bands = np.repeat(np.arange(JUDGE_ORDER + 1), np.arange(JUDGE_ORDER + 1) + 1)  # m ≥ 0 rows
    out = np.empty((len(TRUNCATION_VIEWS_DEG), JUDGE_ORDER + 1))
    for v, deg in enumerate(TRUNCATION_VIEWS_DEG):
        cos_o = float(cosines[int(round(deg * (JUDGE_VIEW_SAMPLES - 1) / 90.0))])
        _, wi, scalar = view_weights(cos_o, alpha, h, w)
        live = np.flatnonzero(scalar)
        coeffs = harmonics.basis_nonnegative_m(JUDGE_ORDER, wi[live], scalar[live]).sum(axis=1)
        out[v] = np.bincount(bands, coeffs**2, minlength=JUDGE_ORDER + 1)
    out.setflags(write=False)
    return out


def lobe_truncation_error(roughness: float, l_max: int) -> float:
    """Relative L2 error of the R ≡ 1 transfer function truncated at band l_max (worst judged view).

    Parameters
    ----------
    roughness : float
        Blender roughness in [0, 1] (α = roughness²).
    l_max : int
        Highest band kept, 0 ≤ l_max ≤ :data:`JUDGE_ORDER`.

    Returns
    -------
    float
        max over the judged views of √(1 − Σ_{l ≤ l_max} E_l / Σ_l E_l), E_l the band energies
        of the lobe projected to band :data:`JUDGE_ORDER`.
    """
    energy = _band_energies(float(roughness))
    kept = energy[:, : int(l_max) + 1].sum(axis=1) / energy.sum(axis=1)
    return float(max(math.sqrt(max(0.0, 1.0 - k)) for k in kept))


def criterion_order(roughness: float, target: float = DEFAULT_TARGET) -> tuple[int, float]:
    """(order, its truncation error): the smallest l_max in 2…MAX_SH_ORDER meeting ``target``,
    else MAX_SH_ORDER, computed from the lobe (what :data:`ORDER_BREAKPOINTS` tabulates)."""
    for l_max in range(2, MAX_SH_ORDER + 1):
        err = lobe_truncation_error(roughness, l_max)
        if err <= target:
            return l_max, err
    return MAX_SH_ORDER, lobe_truncation_error(roughness, MAX_SH_ORDER)


def table_order(roughness: float) -> int:
    """The automatic order of ``roughness`` read from :data:`ORDER_BREAKPOINTS` (no computation)."""
    r = float(roughness)
    starts = [start for start, _ in ORDER_BREAKPOINTS]
    return ORDER_BREAKPOINTS[max(0, bisect.bisect_right(starts, r) - 1)][1]


def order_breakpoints(step: float = 0.002, tol: float = 1e-9, target: float = DEFAULT_TARGET):
    """Tabulate :func:`criterion_order` over roughness [0, 1]: ((first roughness, order), …).

    Scanned every ``step``, each change of order bisected to ``tol``. (An order that holds on an
    interval shorter than ``step`` could be missed: the tests check the table on a grid five
    times finer.)
    """
    grid = np.linspace(0.0, 1.0, int(round(1.0 / step)) + 1)
    orders = [criterion_order(float(r), target)[0] for r in grid]
    steps = [(0.0, orders[0])]
    for lo, hi, before, after in zip(grid[:-1], grid[1:], orders[:-1], orders[1:], strict=True):
        if before == after:
            continue
        a, b = float(lo), float(hi)
        while b - a > tol:
            mid = 0.5 * (a + b)
            if criterion_order(mid, target)[0] == before:
                a = mid
            else:
                b = mid
        steps.append((round(b, 10), after))
    return tuple(steps)


def auto_sh_order(material: Material, target: float = DEFAULT_TARGET) -> tuple[int, str]:
    """Smallest l_max in 2…:data:`MAX_SH_ORDER` whose lobe truncation error is ≤ ``target``; the
    highest if none is. At the default target it is read from :data:`ORDER_BREAKPOINTS`.

    The cap is 12: against Cycles (benchmarks/cycles_compare.py cases, combined path, mean
    ΔE2000) l = 8 / 10 / 12 gave courtyard r 0.5: 2.74 / 2.06 / 1.5, studio r 0.6: 3.72 / 2.93 /
    2.5, forest r 0.5: 1.26 / 0.97 / 0.9; the error sits at grazing views, where the clipped lobe
    needs many bands.
    """
    r = float(material.roughness)
    if target == DEFAULT_TARGET:
        l_max = table_order(r)
        return l_max, (
            f"roughness {r:g}: band-{l_max} lobe truncation error ≤ {target} "
            "(precomputed order table, sh_order.ORDER_BREAKPOINTS)"
        )
    l_max, err = criterion_order(r, target)
    if err <= target:
        return l_max, f"roughness {r:g}: band-{l_max} truncation error {err:.3f} ≤ {target}"
    return l_max, f"roughness {r:g}: lobe needs more than band {l_max} (error {err:.3f} at {l_max})"
