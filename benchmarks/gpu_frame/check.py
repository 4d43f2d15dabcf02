"""``check`` (bpy + moderngl in a subprocess): the harness's pictures against the product's."""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import bpy  # noqa: F401 (gpu is importable once bpy is)
import gpu
import numpy as np

from .config import CHECK_SIZE, ROOT
from .pictures import diff
from .prepare import source_digest
from .record import record_cases
from .store import Prepared


def check(outdir, log=print) -> dict:
    """Draw every case with ``gpu.draw.draw_items`` at :data:`CHECK_SIZE` and with ``measure`` on
    the same OpenGL; compare the 8-bit pictures. Writes OUTDIR/check.json and the harness's
    pictures to OUTDIR/pictures-check.npz."""
    outdir = Path(outdir)
    data = Prepared(outdir)
    stored = {c["id"]: c for c in data.cases()}
    w, h = CHECK_SIZE
    ours, notes = {}, []
    if data.manifest.get("source_digest") != source_digest():
        notes.append(
            "addon/, glsl/ or precompute/ differ from what prepare recorded: the add-on now draws other"
            " shaders or data than the prepared ones (run prepare again)"
        )
    for meta, items, view, proj, _capture, ext in record_cases(CHECK_SIZE, log):
        gd = ext.gpu
        view_ubo = gd.draw.view_uniforms(view, proj)
        recorded = data.array(stored[meta["id"]]["view"])
        if not np.array_equal(view_ubo.astype(np.float32), recorded):
            notes.append(f"{meta['id']}: the view at {w}×{h} differs from the prepared one")
        offscreen = gpu.types.GPUOffScreen(w, h, format="RGBA8")
        try:
            with offscreen.bind():
                fb = gpu.state.active_framebuffer_get()
                fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
                gd.draw.draw_items(items, view, proj, display_srgb=True)
                buf = fb.read_color(0, 0, w, h, 4, 0, "UBYTE")
                buf.dimensions = w * h * 4
                ours[meta["id"]] = np.asarray(buf, dtype=np.uint8).reshape(h, w, 4)[::-1].copy()
        finally:
            offscreen.free()
        log(f"  Blender drew {meta['id']}")
    renderer = f"{gpu.platform.renderer_get()} ({gpu.platform.backend_type_get()})"
    with tempfile.TemporaryDirectory(prefix="tf_gpu_frame_check_") as tmp:
        cmd = [
            sys.executable,
            "-m",
            "benchmarks.gpu_frame",
            "measure",
            str(outdir),
            "--out",
            os.path.join(tmp, "result.json"),
            "--size",
            f"{w}x{h}",
            "--rounds",
            "0",
            "--pictures",
            tmp,
            "--picture-size",
            f"{w}x{h}",
            "--png",
        ]
        log("harness: " + " ".join(cmd[1:]))
        subprocess.run(cmd, cwd=ROOT, check=True)
        harness_result = json.loads(Path(tmp, "result.json").read_text(encoding="utf-8"))
        with np.load(Path(tmp) / f"pictures-{w}x{h}.npz") as npz:
            theirs = {k: npz[k] for k in npz.files}
    np.savez_compressed(outdir / "pictures-check.npz", **theirs)
    cases = {name: diff(theirs[name], ours[name]) for name in ours if name in theirs}
    for name in ours:
        if name not in theirs:
            notes.append(f"{name}: not drawn by the harness")
    result = {
        "size": [w, h],
        "blender_renderer": renderer,
        "harness_renderer": harness_result["context"].get("GL_RENDERER"),
        "cases": cases,
        "max": max(c["max"] for c in cases.values()),
        "mean": statistics.mean(c["mean"] for c in cases.values()),
        "coverage": {name: float(np.mean(ours[name][..., 3] > 0)) for name in ours},
        "notes": notes,
    }
    if "blender_source" in harness_result:
        result["blender_source_vs_header"] = harness_result["blender_source"]["vs_header"]
    (outdir / "check.json").write_text(json.dumps(result, indent=1), encoding="utf-8")
    log(
        f"harness vs gpu.draw.draw_items on {renderer}, {w}×{h} RGBA8: max {result['max']} levels,"
        f" mean {result['mean']:.4f} over {len(cases)} cases" + ("; " + "; ".join(notes) if notes else "")
    )
    return result
