"""Start-up cost of enabling the extension: median of repeated fresh processes.

Usage (from the repository root)::

    .venv/bin/python -m benchmarks.startup             # → docs/startup.md
    .venv/bin/python -m benchmarks.startup --runs 5    # fewer processes (a smoke run)

Issue 20: "Blender start-up with the extension enabled ≤ 0.3 s extra". Each run is a fresh
Python process that imports ``bpy`` (Blender as a module), then imports the extension the way
Blender does (the package ``thinfilm_sh``, through a symbolic link as in the tests) and calls its
``register()``. The figure is the time from before the import to after ``register()``, measured
inside the process; its median over the runs is the start-up cost. The process also reports
which heavy packages the registration imported (colour-science, OpenEXR, scipy, matplotlib):
none should be. For reference, the wall time of a whole process that only imports ``bpy`` is
reported next to one that also enables the extension (alternating, so load hits both alike).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

from . import common

#: Packages that must not be imported by enabling the extension.
HEAVY = ("colour", "OpenEXR", "scipy", "matplotlib")

_CHILD = r"""
import json, os, sys, time
import bpy
root = sys.argv[1]
mode = sys.argv[2]
t0 = time.perf_counter()
if mode == "1":
    sys.path.insert(0, root)
    import thinfilm_sh
    thinfilm_sh.register()
elif mode == "colour":
    import colour  # what registering the extension imported before the tables shipped as data
t1 = time.perf_counter()
heavy = [m for m in HEAVY if m in sys.modules]
print(json.dumps({"enable_s": t1 - t0, "heavy": heavy}))
""".replace("HEAVY", repr(HEAVY))


def child_env(pycache: str) -> dict:
    """The environment of a child: bytecode cached in ``pycache`` (as an installed extension's
    ``__pycache__`` is after its first start), whatever the caller's PYTHONDONTWRITEBYTECODE."""
    env = dict(os.environ)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    env["PYTHONPYCACHEPREFIX"] = pycache
    return env


def one_process(root: str, enable) -> tuple[float, dict]:
    """(wall seconds of the whole process, what it printed) for one fresh process: ``enable``
    True registers the extension, "colour" only imports colour-science, False nothing."""
    start = time.perf_counter()
    out = subprocess.run(
        [sys.executable, "-c", _CHILD, root, enable if isinstance(enable, str) else "1" if enable else "0"],
        capture_output=True,
        text=True,
        check=True,
        cwd=common.ROOT,
        env=child_env(os.path.join(root, "pycache")),
    )
    wall = time.perf_counter() - start
    line = next(line for line in out.stdout.splitlines() if line.startswith("{"))
    return wall, json.loads(line)


def _row(label: str, values) -> str:
    return f"| {label} | {statistics.median(values):.2f} s | {min(values):.2f} s | {max(values):.2f} s |"


def main(argv=None) -> int:
    """Run the processes, print the figures and write docs/startup.md (unless --no-doc)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=15)
    parser.add_argument("--no-doc", action="store_true")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as root:
        os.symlink(common.ROOT, os.path.join(root, "thinfilm_sh"), target_is_directory=True)
        _, first = one_process(root, True)  # the first start after installing: compiles the .pyc files
        enable, walls_on, walls_off, colour_import, heavy = [], [], [], [], set()
        for _ in range(args.runs):
            wall, data = one_process(root, True)
            walls_on.append(wall)
            enable.append(data["enable_s"])
            heavy.update(data["heavy"])
            wall, _ = one_process(root, False)
            walls_off.append(wall)
            _, data = one_process(root, "colour")
            colour_import.append(data["enable_s"])
    med = statistics.median(enable)
    lines = [
        "# Start-up cost of enabling the extension",
        "",
        f"Written by `benchmarks/startup.py` ({args.runs} fresh processes of each kind, alternating).",
        "",
        "| Figure | Median | Min | Max |",
        "|---|---:|---:|---:|",
        f"| Import + `register()` of the extension, in-process | **{med:.3f} s** | {min(enable):.3f} s | "
        f"{max(enable):.3f} s |",
        f"| The first start after installing (compiles the bytecode), in-process | {first['enable_s']:.3f} s "
        "| | |",
        _row("Whole process: `import bpy` + enable", walls_on),
        _row("Whole process: `import bpy` only", walls_off),
        "",
        f"Heavy packages imported by enabling the extension: {', '.join(sorted(heavy)) or 'none'} "
        f"(checked: {', '.join(HEAVY)}).",
        "",
        f"Issue 20's bound: ≤ 0.3 s extra. Measured: {med:.3f} s "
        f"({'within' if med <= 0.3 else 'over'} the bound on this machine).",
        "",
        "Before issue 20, registering imported colour-science, and with it two ColourUsageWarnings",
        "printed at every start. The colour tables now ship as data (`precompute/colour/colour_tables.py`).",
        f"`import colour` alone, in the same fresh processes: median "
        f"{statistics.median(colour_import):.3f} s "
        f"(min {min(colour_import):.3f} s, max {max(colour_import):.3f} s).",
        "",
        "## Machine",
        "",
        *common.machine_lines(),
    ]
    print("\n".join(lines))
    if not args.no_doc:
        print(common.write_doc("startup.md", "\n".join(lines)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
