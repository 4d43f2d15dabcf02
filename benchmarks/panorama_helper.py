"""The panorama helper process (issue 16): start-up, memory, the main thread's hand-over, renders.

A procedural World's Cycles panorama is rendered by a helper process (``addon/world/panorama_helper.py``)
so that Blender's main thread only writes the World to a .blend and sends its path. Measured here
with the add-on's own code (real bpy, a Sky Texture World):

- **start-up**: the process start on the main thread (``warm``: ``subprocess.Popen``) and the
  time until the helper is ready (it imports bpy and the add-on's ``panorama`` module);
- **memory**: the helper's resident memory when ready (idle) and after the renders;
- **hand-over**: ``bpy.data.libraries.write`` of the World (the one main-thread cost left) and the
  whole ``submit`` (write and send);
- **render**: the helper's render as it reports it, the round trip (submit → panorama in this
  process), and the same panorama rendered in this process on the main thread, as before;
  whether the two panoramas are equal.

Run: ``.venv/bin/python -m benchmarks.panorama_helper`` → the section *The panorama helper
process* of ``docs/world-latency.md`` (the rest of the file is ``benchmarks/world_latency.py``'s,
which writes this section too).
"""

from __future__ import annotations

import argparse
import importlib
import math
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks import common

EXTENSION_ID = "thinfilm_sh"
HEADING = "## The panorama helper process"
#: Repeats of the write and of the renders (medians reported).
WRITES, RENDERS = 20, 5


def _extension():
    """The repository imported as ``thinfilm_sh`` and registered (helper stopped)."""
    import bpy

    root = Path(tempfile.mkdtemp(prefix="tf_helper_bench_"))
    os.symlink(common.ROOT, root / EXTENSION_ID, target_is_directory=True)
    sys.path.insert(0, str(root))
    package = importlib.import_module(EXTENSION_ID)
    package.register()
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    package.register()
    return package, importlib.import_module(f"{EXTENSION_ID}.addon.world.panorama_helper")


def sky_world(bpy, name: str = "Sky"):
    """A Sky Texture World (the latency benchmark's procedural sky)."""
    world = bpy.data.worlds.new(name)
    tree = world.node_tree
    node = tree.nodes.new("ShaderNodeTexSky")
    node.sun_elevation = math.radians(30.0)
    tree.links.new(node.outputs["Color"], tree.nodes["Background"].inputs["Color"])
    return world


def _ms(seconds: float) -> float:
    return 1000.0 * seconds


def measure(helper=None) -> dict:
    """The helper's figures (see the module's docstring); ``helper``: the add-on's
    ``panorama_helper`` module, else the extension is imported and registered here."""
    import bpy

    if helper is None:
        _package, helper = _extension()
    panorama = importlib.import_module(helper.__name__.rpartition(".")[0] + ".panorama")
    helper.unregister()  # a fresh helper, none given up
    world = sky_world(bpy)
    found = {"load_start": common.load_average()}
    start = time.perf_counter()
    helper.warm()
    found["popen_ms"] = _ms(time.perf_counter() - start)
    process = helper.SLOT.current()  # the session's helper (helper_process.HelperSlot)
    if process is None or not process.ready.wait(helper.START_TIMEOUT_S) or process.ready_s is None:
        raise RuntimeError(f"the helper did not start: {helper.info()}")
    found["ready_s"] = process.ready_s
    time.sleep(0.5)  # its start-up settled
    found["idle_rss"] = process.rss_bytes()
    writes = []
    with tempfile.TemporaryDirectory() as folder:
        for i in range(WRITES):
            path = os.path.join(folder, f"w{i}.blend")
            start = time.perf_counter()
            bpy.data.libraries.write(path, {world}, path_remap="ABSOLUTE", fake_user=True, compress=False)
            writes.append(_ms(time.perf_counter() - start))
    found["write_ms"] = statistics.median(writes)
    found["write_max_ms"] = max(writes)
    submits, trips, renders, here = [], [], [], []
    rgb = reference = None
    for _ in range(RENDERS):
        start = time.perf_counter()
        pending = helper.submit(world)
        submits.append(_ms(time.perf_counter() - start))
        rgb = pending.result()
        trips.append(_ms(time.perf_counter() - start))
        renders.append(helper.LAST["render_ms"])
        start = time.perf_counter()
        reference = panorama.render_world_panorama(world)
        here.append(_ms(time.perf_counter() - start))
    found.update(
        submit_ms=statistics.median(submits),
        submit_max_ms=max(submits),
        helper_render_ms=statistics.median(renders),
        round_trip_ms=statistics.median(trips),
        in_process_ms=statistics.median(here),
        equal=bool(np.array_equal(rgb, reference)),
        rss_after=process.rss_bytes(),
        load_end=common.load_average(),
    )
    helper.stop()
    bpy.data.worlds.remove(world)
    return found


def section(found: dict) -> list[str]:
    """The figures as the markdown section :data:`HEADING`."""
    mib = 1024.0**2
    return [
        HEADING,
        "",
        "A procedural World's panorama is rendered by one long-lived helper process "
        "(`addon/world/panorama_helper.py`, `addon/world/panorama_process.py`), started at the "
        "viewport's first "
        "World read; the main thread writes the World to a private .blend and sends its path, a "
        "worker thread waits for the float32 panorama and analyses it. Measured by "
        f"`benchmarks/panorama_helper.py` (a Sky Texture World, medians of {WRITES} writes and "
        f"{RENDERS} renders; load average {found['load_start']} at the start, {found['load_end']} "
        "at the end):",
        "",
        "| What | Where | Time or size |",
        "|---|---|---|",
        f"| process start (`warm`: `Popen`) | main thread | {found['popen_ms']:.1f} ms |",
        f"| helper ready (imports bpy and `panorama`) | helper | {found['ready_s']:.2f} s |",
        f"| helper's memory when ready (idle RSS) | helper | {found['idle_rss'] / mib:.0f} MiB |",
        f"| helper's memory after {RENDERS} renders | helper | {found['rss_after'] / mib:.0f} MiB |",
        f"| `bpy.data.libraries.write` of the World | main thread | {found['write_ms']:.1f} ms "
        f"(longest {found['write_max_ms']:.1f} ms) |",
        f"| `submit` (the write, one line to the pipe) | main thread | {found['submit_ms']:.1f} ms "
        f"(longest {found['submit_max_ms']:.1f} ms) |",
        f"| the panorama's render (256 × 128, 32 samples) | helper | {found['helper_render_ms']:.0f} ms |",
        f"| round trip: submit → panorama here | worker thread | {found['round_trip_ms']:.0f} ms |",
        f"| the same render in this process, as before | main thread | {found['in_process_ms']:.0f} ms |",
        "",
        f"The helper's panorama {'equals' if found['equal'] else 'differs from'} the in-process "
        "render bit for bit (the same `panorama.render_world_panorama`, samples and seed; "
        "`tests/world/test_panorama_helper.py` checks it). A helper that cannot start, exits or takes "
        "longer than 60 s is given up for the session (one logged error) and procedural Worlds are "
        "rendered on the main thread as before; so are files whose working colour space is not "
        "Linear Rec.709 (the helper's factory start-up), and everything when the preference "
        "*Render Procedural Worlds in a Helper Process* is off.",
    ]


def splice(text: str, lines: list[str]) -> str:
    """``text`` with its :data:`HEADING` section replaced by ``lines`` (inserted before
    ``## Machine`` when it has none)."""
    block = "\n".join(lines) + "\n\n"
    if HEADING in text:
        head, rest = text.split(HEADING, 1)
        following = rest.find("\n## ")
        tail = rest[following + 1 :] if following >= 0 else ""
        return head + block + tail
    if "## Machine" in text:
        head, tail = text.split("## Machine", 1)
        return head + block + "## Machine" + tail
    return text.rstrip("\n") + "\n\n" + block


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--no-doc", action="store_true", help="print, do not write docs/world-latency.md")
    args = parser.parse_args(argv)
    lines = section(measure())
    print("\n".join(lines))
    if not args.no_doc:
        path = os.path.join(common.ROOT, "docs", "world-latency.md")
        with open(path, encoding="utf-8") as handle:
            text = handle.read()
        print("wrote", common.write_doc("world-latency.md", splice(text, lines)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
