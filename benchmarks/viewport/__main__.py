"""The command line of ``python -m benchmarks.viewport`` (the package docstring has the usage)."""

from __future__ import annotations

import argparse
import importlib
import json
import os
import sys
import time

from .. import common
from .config import RESULTS_JSON, roughness_cases
from .measure import automatic_orders, grid, order_sweep, split_sum
from .python_time import python_time, rebuild_time
from .report import _code_state, report
from .scene import Extension, Scene

# ----------------------------------------------------------------------------------------------
# The run
# ----------------------------------------------------------------------------------------------
PARTS = ("grid", "sweep", "split_sum", "python", "rebuild", "automatic")


def run(
    quick: bool, baseline_rev: str | None = None, parts=PARTS, orders=None, log=print, per_pixel: bool = True
) -> dict:
    started = time.perf_counter()
    ext = Extension()  # imports bpy first: gpu and mathutils come with it
    import gpu

    scene = Scene(ext)
    baseline = tree = None
    res: dict = {"quick": quick}
    try:
        if baseline_rev:
            baseline, tree, res["baseline"] = ext.baseline(baseline_rev)
        res["renderer"] = f"{gpu.platform.renderer_get()} ({gpu.platform.backend_type_get()})"
        res["vendor"] = gpu.platform.vendor_get()
        res["workbench_settings"] = scene.workbench_settings
        log(f"renderer: {res['renderer']}; Workbench: {scene.workbench_settings}")
        if "grid" in parts:
            log("grid at the headline order …")
            res["grid"] = grid(scene, quick, baseline, log)
        if "sweep" in parts:
            log("l_max sweep …")
            res["sweep"] = order_sweep(scene, quick, baseline, orders, log)
        if "split_sum" in parts:
            log("split sum vs SH …")
            res["split_sum"] = split_sum(scene, quick, log)
        if "python" in parts:
            log("Python time per frame …")
            res["python"] = python_time(scene, quick, baseline, log)
        if "rebuild" in parts:
            log("batch rebuild after an edit …")
            res["rebuild"] = rebuild_time(scene, quick, log)
        if "automatic" in parts:
            log("glossy, medium and rough films at their automatic order …")
            res["automatic"] = automatic_orders(scene, quick, log, per_pixel=per_pixel)
    finally:
        if tree is not None:
            ext.remove_baseline(tree)
    res["roughness"] = roughness_cases()
    res["minutes"] = (time.perf_counter() - started) / 60
    return res


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.viewport",
        description=importlib.import_module(__package__).__doc__.splitlines()[0],
    )
    parser.add_argument("--quick", action="store_true", help="smoke run (< 1 min) that writes nothing")
    parser.add_argument("--baseline", metavar="REV", help="also draw with git revision REV's draw module")
    parser.add_argument(
        "--only", nargs="+", choices=PARTS, help="measure only these parts (prints, writes nothing)"
    )
    parser.add_argument(
        "--orders", nargs="+", type=int, metavar="L", help="l_max of the order sweep (prints, writes nothing)"
    )
    parser.add_argument(
        "--no-per-pixel",
        action="store_true",
        help="part 'automatic' without the per-pixel SH frames (prints, writes nothing)",
    )
    parser.add_argument(
        "--report-only",
        action="store_true",
        help=f"rewrite docs/performance.md from the last full run's {RESULTS_JSON} (no measuring)",
    )
    args = parser.parse_args(argv)
    path = os.path.join(common.ROOT, RESULTS_JSON)
    if args.report_only:
        with open(path, encoding="utf-8") as handle:
            res = json.load(handle)
    else:
        code_state = _code_state()  # before measuring: what was measured
        res = run(
            args.quick,
            args.baseline,
            parts=args.only or PARTS,
            orders=args.orders,
            per_pixel=not args.no_per_pixel,
        )
        res["machine"] = common.machine_lines()
        res["code_state"] = code_state
        res["command"] = " ".join(
            ["python -m benchmarks.viewport", *(argv if argv is not None else sys.argv[1:])]
        )
        if args.quick or args.only or args.orders or args.no_per_pixel:
            print(f"run done in {res['minutes']:.1f} min; nothing written")
            return 0
        os.makedirs(os.path.dirname(path), exist_ok=True)
        with open(path, "w", encoding="utf-8") as handle:
            json.dump(res, handle)
    print(common.write_doc("performance.md", report(res)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
