"""The automatic SH order: the precomputed table picks what the band-16 criterion picks, and the
criterion computed from the lobe alone equals the one from the l = 16 u-node kernel."""

import math

import numpy as np
import pytest

from precompute.bakes import kernel, planner, sh_order
from precompute.materials.material import Material, Quality


def _kernel_criterion(roughness: float, l_max: int) -> float:
    """The criterion as it was first written: an l = 16 kernel of 10 views, summed over u nodes."""
    k = kernel.microfacet_kernel(float(roughness), 16, 10, 6)
    bands = np.array([l for l in range(17) for _ in range(l + 1)])
    worst = 0.0
    for deg in sh_order.TRUNCATION_VIEWS_DEG:
        energy = k[int(round(deg / 10.0))].sum(axis=1) ** 2
        worst = max(worst, math.sqrt(max(0.0, 1.0 - energy[bands <= l_max].sum() / energy.sum())))
    return worst


@pytest.mark.parametrize("roughness", [0.0, 0.05, 0.3, 0.6, 0.68, 0.9, 1.0])
def test_the_lobe_criterion_equals_the_kernel_criterion(roughness):
    """With R ≡ 1 the Lagrange weights sum to one: the lobe's sums are the kernel's row sums."""
    for l_max in (2, 5, 8, 12):
        assert sh_order.lobe_truncation_error(roughness, l_max) == pytest.approx(
            _kernel_criterion(roughness, l_max), abs=1e-12
        )


@pytest.mark.parametrize("points", [251, pytest.param(1001, marks=pytest.mark.slow)])
def test_the_order_table_picks_the_criterion_order_on_a_fine_grid(points):
    """Every 0.004 in roughness (fast set; finer than the table's 0.005 scan) or every 0.001 (5×
    finer, full set: 5 s), and 1e-6 either side of every breakpoint, the table's order is the
    criterion's."""
    grid = list(np.linspace(0.0, 1.0, points))
    for start, _ in sh_order.ORDER_BREAKPOINTS[1:]:
        grid += [start - 1e-6, start + 1e-6]
    wrong = [
        (r, sh_order.table_order(r), sh_order.criterion_order(r)[0])
        for r in map(float, grid)
        if sh_order.table_order(r) != sh_order.criterion_order(r)[0]
    ]
    assert not wrong, (
        f"(roughness, table order, criterion order) where the precomputed table is wrong: {wrong}"
    )


def test_planning_reads_the_table_and_computes_no_kernel():
    """An automatic order for a new roughness neither computes a kernel nor projects a lobe."""
    kernel.microfacet_kernel.cache_clear()
    sh_order._band_energies.cache_clear()
    p = planner.plan(Material(roughness=0.4137))
    assert p.sh_order == sh_order.criterion_order(0.4137)[0] == 12
    assert "precomputed" in p.reasons["sh_order"]
    sh_order._band_energies.cache_clear()
    assert planner.plan(Material(roughness=0.83)).sh_order == 6
    assert kernel.microfacet_kernel.cache_info().currsize == 0
    assert sh_order._band_energies.cache_info().currsize == 0


def test_an_explicit_target_uses_the_criterion():
    """A target other than the default is judged from the lobe (the table holds 10 % only)."""
    order, reason = sh_order.auto_sh_order(Material(roughness=0.9), target=0.05)
    assert order == sh_order.criterion_order(0.9, 0.05)[0]
    assert "truncation error" in reason
    assert planner.plan(Material(roughness=0.9, quality=Quality(sh_order=3))).sh_order == 3
