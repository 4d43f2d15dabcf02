"""``measure``: compile, draw and time every case of a prepared OUTDIR, and write the result JSON.

numpy + moderngl only (no bpy, no add-on, no precompute): this runs on the GPU machine, where
only those are installed.
"""

from __future__ import annotations

import ctypes
import fnmatch
import json
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

import moderngl
import numpy as np

from .config import CHECK_SIZE, FORMAT_VERSION, PNG_CASES, RESOLUTION, ROUNDS, WARMUP
from .gl import InfoLog
from .harness import Harness, create_context
from .pictures import diff, save_picture
from .store import Prepared


def _context_info(ctx) -> dict:
    info = dict(ctx.info)
    keep = (
        "GL_VENDOR",
        "GL_RENDERER",
        "GL_VERSION",
        "GL_SHADING_LANGUAGE_VERSION",
        "GL_MAX_UNIFORM_BLOCK_SIZE",
        "GL_MAX_ARRAY_TEXTURE_LAYERS",
        "GL_MAX_3D_TEXTURE_SIZE",
    )
    out = {k: info.get(k) for k in keep if k in info}
    gl = InfoLog().gl
    if gl is not None:
        gl.glGetString.restype = ctypes.c_char_p
        glsl = gl.glGetString(0x8B8C)  # GL_SHADING_LANGUAGE_VERSION
        out["GL_SHADING_LANGUAGE_VERSION"] = glsl.decode() if glsl else None
    out["moderngl"] = moderngl.__version__
    out["python"] = platform.python_version()
    out["numpy"] = np.__version__
    out["machine"] = f"{platform.system()} {platform.release()} {platform.machine()}"
    return out


def _nvidia_smi() -> str | None:
    try:
        return subprocess.run(
            [
                "nvidia-smi",
                "--query-gpu=name,driver_version,memory.total,clocks.max.sm,clocks.sm,pstate",
                "--format=csv,noheader",
            ],
            capture_output=True,
            text=True,
            timeout=20,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None


def _summary(values: list[float]) -> dict:
    s = sorted(values)
    n = len(s)
    return {
        "median": statistics.median(s),
        "p10": s[int(0.1 * (n - 1))],
        "p90": s[int(0.9 * (n - 1))],
        "min": s[0],
        "n": n,
    }


def measure(
    outdir,
    out,
    *,
    backend: str | None = "egl",
    size=RESOLUTION,
    warmup: int = WARMUP,
    rounds: int = ROUNDS,
    pictures: str | None = None,
    picture_size=CHECK_SIZE,
    png_cases=PNG_CASES,
    scenes=None,
    blender_sources: bool = True,
    skip=(),
    budget_s: float | None = None,
    log=print,
) -> dict:
    """Compile, draw and time every case of ``outdir``; write the result JSON to ``out``."""
    started = time.perf_counter()
    data = Prepared(outdir)
    if skip:
        data.manifest["cases"] = [
            c for c in data.manifest["cases"] if not any(fnmatch.fnmatch(c["id"], pat) for pat in skip)
        ]
        used = {g["variant"] for c in data.manifest["cases"] for g in c["groups"]}
        data.manifest["variants"] = {k: v for k, v in data.manifest["variants"].items() if k in used}
    ctx = create_context(backend)
    res: dict = {
        "format": FORMAT_VERSION,
        "context": _context_info(ctx),
        "nvidia_smi": _nvidia_smi(),
        "prepared": {k: data.manifest[k] for k in ("created", "code", "prepared_on", "resolution")},
        "size": list(size),
        "warmup": warmup,
        "rounds": rounds,
        "skipped": list(skip),
        "budget_s": budget_s,
        "cases": {},
        "command": " ".join(["python -m benchmarks.gpu_frame", *sys.argv[1:]]),
    }
    log(" | ".join(str(res["context"].get(k)) for k in ("GL_RENDERER", "GL_VERSION", "GL_VENDOR")))
    harness = Harness(data, ctx, "header", log)
    harness.compile_all()
    res["compile"] = {
        name: {"seconds": harness.compile_seconds.get(name), "error": harness.errors.get(name)}
        for name in data.manifest["variants"]
    }
    fbo = harness.framebuffer(tuple(size))
    for case in data.cases():
        res["cases"][case["id"]] = {
            k: case[k]
            for k in (
                "scene",
                "l_max",
                "case",
                "lamps",
                "roughness",
                "sh_weight",
                "lamp_count",
                "triangles",
                "objects",
            )
        }
        res["cases"][case["id"]]["variant"] = case["groups"][0]["variant"]
        res["cases"][case["id"]]["drawn"] = harness.ready(case)
    # timing, one scene at a time
    for scene in scenes or data.manifest["scenes"]:
        cases = {c["id"]: c for c in data.cases(scene) if harness.ready(c)}
        if not cases or rounds <= 0:
            continue
        for case in cases.values():
            harness.warm(case)
        cases[f"{scene}-clear"] = None
        log(f"timing {scene}: {len(cases)} cases × {rounds} rounds after {warmup} warm-up frames …")
        t0 = time.perf_counter()
        timed = harness.time_cases(cases, fbo, warmup, rounds, budget_s, log)
        res.setdefault("rounds_done", {})[scene] = len(timed["gpu_ms"][f"{scene}-clear"])
        for name in cases:
            entry = res["cases"].setdefault(name, {"scene": scene, "case": "clear"})
            entry["gpu_ms"] = _summary(timed["gpu_ms"][name])
            entry["wall_ms"] = _summary(timed["wall_ms"][name])
            entry["gpu_samples"] = [round(x, 4) for x in timed["gpu_ms"][name]]
            entry["wall_samples"] = [round(x, 4) for x in timed["wall_ms"][name]]
            log(f"  {name}: GPU {entry['gpu_ms']['median']:.3f} ms, wall {entry['wall_ms']['median']:.3f} ms")
        log(f"  ({time.perf_counter() - t0:.1f} s)")
        _write(out, res, started)
    # pictures: coverage at full size, PNGs of a few, all at picture_size (and compared)
    pics, blender_pics = {}, {}
    small = harness.framebuffer(tuple(picture_size))
    for case in data.cases():
        if not harness.ready(case):
            continue
        full = harness.picture(case, fbo)
        res["cases"][case["id"]]["coverage"] = float(np.mean(full[..., 3] > 0))
        if pictures and case["id"] in png_cases:
            save_picture(Path(pictures) / f"{case['id']}.png", full)
        pics[case["id"]] = harness.picture(case, small)
    if pictures:
        Path(pictures).mkdir(parents=True, exist_ok=True)
        np.savez_compressed(Path(pictures) / f"pictures-{picture_size[0]}x{picture_size[1]}.npz", **pics)
    res["picture_size"] = list(picture_size)
    _write(out, res, started)  # the measurements, before anything else can fail
    if blender_sources and any("blender_vertex" in v for v in data.manifest["variants"].values()):
        log("Blender's own GLSL (as compiled by bpy on the machine that prepared OUTDIR):")
        theirs = Harness(data, ctx, "blender", log)
        theirs.compile_all()
        res["blender_source"] = {
            "compile": {
                name: {"seconds": theirs.compile_seconds.get(name), "error": theirs.errors.get(name)}
                for name in data.manifest["variants"]
            },
            "vs_header": {},
        }
        for case in data.cases():
            if theirs.ready(case) and case["id"] in pics:
                blender_pics[case["id"]] = theirs.picture(case, small)
                res["blender_source"]["vs_header"][case["id"]] = diff(
                    blender_pics[case["id"]], pics[case["id"]]
                )
    reference = Path(outdir) / "pictures-check.npz"
    if reference.exists() and tuple(picture_size) == CHECK_SIZE:
        with np.load(reference) as ref:
            res["vs_check_pictures"] = {
                name: diff(pics[name], ref[name]) for name in pics if name in ref.files
            }
        check = Path(outdir) / "check.json"
        if check.exists():
            res["check"] = json.loads(check.read_text(encoding="utf-8"))
    res["picture_size"] = list(picture_size)
    _write(out, res, started)
    # Last, so that whatever happens in it the measurements are written: the compile logs of a
    # second compile through the GL entry points (moderngl keeps a successful compile's warnings).
    log("compile and link logs:")
    for name, logs in harness.info_logs().items():
        res["compile"][name].update(logs)
    if "blender_source" in res:
        for name, logs in theirs.info_logs().items():
            res["blender_source"]["compile"][name].update(logs)
    res["info_logs"] = any("fragment" in v for v in res["compile"].values())
    _write(out, res, started)
    return res


def _write(out, res: dict, started: float) -> None:
    res["seconds"] = time.perf_counter() - started
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    Path(out).write_text(json.dumps(res, indent=1), encoding="utf-8")
    print(f"wrote {out} ({res['seconds']:.0f} s)")
