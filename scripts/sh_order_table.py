"""Print ``precompute.bakes.sh_order.ORDER_BREAKPOINTS``: the automatic SH order's steps in roughness.

Usage (from the repository root)::

    .venv/bin/python scripts/sh_order_table.py

Scans :func:`precompute.bakes.sh_order.criterion_order` (the band-16 lobe truncation criterion) over
roughness [0, 1] every 0.002 and bisects each change of order to 1e-9 (≈ 20 s on two cores).
Paste the output into ``precompute/bakes/sh_order.py``; tests/sh/test_sh_order.py checks the table
against the criterion on a grid five times finer and on both sides of every breakpoint.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from precompute.bakes import sh_order  # noqa: E402


def main() -> None:
    """Compute the breakpoints and print them as Python source."""
    print("ORDER_BREAKPOINTS: tuple[tuple[float, int], ...] = (")
    for start, order in sh_order.order_breakpoints():
        print(f"    ({start!r}, {order}),")
    print(")")


if __name__ == "__main__":
    main()
