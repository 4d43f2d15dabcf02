"""Why viewport bakes run in a helper process: a bake on a thread of Blender's process against
the same bake in the bake helper, while Blender's main thread is idle, busy with Python, or
redrawing the viewport (issue 16).

One bpy process, the soap bubble sample scene opened as in ``benchmarks/latency.py`` (its event
loop, the add-on's own draw through ``render_offscreen`` at 96×72), the soap preset as the
viewport bakes it (``policy.drawn_material``: order 0), with its film table. Per condition,
warm bakes of films whose thickness range grows by 0.5 nm each (every value changes, the
kernel is reused), median wall time from the request to the table (and film table) in hand:

- *thread*: ``precompute.bakes.bake.bake`` and ``film_colour.film_table`` on a worker thread of this
  process, as the viewport baked before the helper;
- *helper*: ``addon.bakes.bake_helper.bake`` (the worker waits on the pipe; the helper bakes);

while the main thread (a) sleeps, (b) runs a pure-Python loop (an add-on's or a panel's Python:
it holds the interpreter's lock), (c) redraws the soap bubble again and again (the loop's
``redraw``: depsgraph update, our draw callback, llvmpipe's draw and read-back).

Run: ``.venv/bin/python -m benchmarks.bake_helper`` → ``docs/bake-helper.md``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

from benchmarks import common
from benchmarks import latency as replay
from precompute.effects import plan_text

#: Bakes per condition.
BAKES = 12


def _materials(ext, count: int, start: int):
    """``count`` soap films as the viewport bakes them, each a new table."""
    package = ext.package.__name__
    material = sys.modules[f"{package}.precompute.materials.material"]
    policy = sys.modules[f"{package}.precompute.shading.policy"]
    base = policy.drawn_material(material.preset("soap_film"))
    out = []
    for i in range(start, start + count):
        data = base.to_dict()
        data["thickness_range_nm"] = [0.0, 1000.0 + 0.5 * i]
        out.append(material.Material.from_dict(data))
    return out


def _in_thread(ext):
    package = ext.package.__name__
    bake = sys.modules[f"{package}.precompute.bakes.bake"]
    film_colour = sys.modules[f"{package}.precompute.colour.film_colour"]

    def run(desc):
        film_colour.film_table(bake.bake(desc))

    return run


def _in_helper(ext):
    def run(desc):
        ext.bake_helper.bake(desc, True)

    return run


def _python_loop(stop: threading.Event) -> None:
    while not stop.is_set():
        total = 0
        for k in range(20_000):
            total += k


def measure(ext, loop, how: str, main: str, start: int) -> list[float]:
    """Seconds per bake (``how``: "thread" or "helper") while the main thread does ``main``."""
    run = _in_thread(ext) if how == "thread" else _in_helper(ext)
    times: list[float] = []
    done = threading.Event()

    def worker():
        for desc in _materials(ext, BAKES, start):
            t0 = time.perf_counter()
            run(desc)
            times.append(time.perf_counter() - t0)
        done.set()

    thread = threading.Thread(target=worker)
    thread.start()
    draws = 0
    while not done.is_set():
        if main == "idle":
            done.wait(0.05)
        elif main == "python":
            stop = threading.Event()
            threading.Timer(0.05, stop.set).start()
            _python_loop(stop)
        else:
            loop.redraw(record=False)
            draws += 1
    thread.join()
    return times


def report(rows, draw_ms: float, helper_info: dict, started: str, wall_s: float) -> str:
    lines = [
        "# Viewport bakes: on a thread of Blender's process, or in the bake helper",
        "",
        "Written by `.venv/bin/python -m benchmarks.bake_helper` (see its docstring). The soap",
        "bubble sample scene, the soap preset as the viewport bakes it (order 0) with its film",
        f"table; {BAKES} warm bakes per cell, each a new table (the thickness range grows by 0.5 nm);",
        "median and maximum wall time from the request to the table and film table in hand.",
        "",
        "## Machine",
        "",
        *common.machine_lines(),
        f"- Run started {started} UTC, took {wall_s / 60:.1f} min.",
        "",
        "## Results",
        "",
        "| main thread meanwhile | on a thread (median / max) | in the helper (median / max) | ratio |",
        "|---|---:|---:|---:|",
    ]
    for main, thread_times, helper_times in rows:
        t, h = statistics.median(thread_times), statistics.median(helper_times)
        lines.append(
            f"| {main} | {common.fmt_seconds(t)} / {common.fmt_seconds(max(thread_times))} | "
            f"{common.fmt_seconds(h)} / {common.fmt_seconds(max(helper_times))} | {t / h:.1f}× |"
        )
    rss = helper_info.get("rss_bytes")
    lines += [
        "",
        f"One redraw of the scene (median, main thread alone): {draw_ms:.1f} ms. The helper:",
        f"ready {helper_info.get('start_s', float('nan')):.2f} s after it was started, "
        f"{plan_text.fmt_bytes(rss) if rss else 'n/a'} resident after the run.",
        "",
        "*Idle* is the baseline. *Python* is a main thread busy with Python code (another add-on, a",
        "panel's `draw`): it holds the interpreter's lock, which the thread's bake needs between its",
        "numpy calls. *Redrawing* is Blender's case while an edit is shown: the main thread holds",
        "the lock through each frame (here the off-screen draw and its read-back, which wait for",
        "llvmpipe), so the thread's bake runs only between frames. The helper needs the lock only",
        "to hand the request over and unpickle the answer; what remains is the two cores shared",
        "with llvmpipe's threads.",
    ]
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.parse_args(argv)
    started = time.strftime("%Y-%m-%d %H:%M", time.gmtime())
    t_start = time.perf_counter()
    ext = replay.Extension()
    out = Path(tempfile.mkdtemp(prefix="tf_bake_helper_bench_"))
    path = replay.build_scene(ext, "soap_bubble", out)
    loop, _ = replay.first_open(ext, path)
    loop.settle()
    draw_ms = 1000.0 * statistics.median(common.time_runs(lambda: loop.redraw(record=False), runs=9))
    rows = []
    start = 1
    for how in ("thread", "helper"):  # warm both: kernels, quadrature, the helper's process
        measure(ext, loop, how, "idle", start)
        start += BAKES
    for main in ("idle", "python", "redrawing"):
        per = {}
        for how in ("thread", "helper"):
            per[how] = measure(ext, loop, how, main, start)
            start += BAKES
            print(f"{main:10s} {how:6s} median {1000 * statistics.median(per[how]):7.1f} ms", flush=True)
        rows.append((main, per["thread"], per["helper"]))
    text = report(rows, draw_ms, ext.bake_helper.info(), started, time.perf_counter() - t_start)
    print(common.write_doc("bake-helper.md", text))
    return 0


if __name__ == "__main__":
    sys.exit(main())
