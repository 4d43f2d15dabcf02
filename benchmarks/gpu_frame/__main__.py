"""GPU frame time of our draw alone: the extension's shaders and data, drawn through moderngl + EGL.

The command line of ``python -m benchmarks.gpu_frame`` (the package docstring has the commands).
"""

from __future__ import annotations

import argparse
import importlib
import sys

from .config import CHECK_SIZE, PNG_CASES, RESOLUTION, ROUNDS, WARMUP
from .pictures import compare
from .report import write_report


def _command(name: str):
    """The module of a command that needs more than numpy: ``prepare`` and ``check`` import bpy
    (the machine with Blender), ``measure`` imports moderngl (not in the requirements). Each is
    imported only when its command runs, so that ``measure`` runs on the GPU machine without bpy,
    the add-on or precompute, and ``report`` and ``compare`` run without moderngl."""
    return importlib.import_module(f"{__package__}.{name}")


def _parse_size(text: str) -> tuple[int, int]:
    w, h = text.lower().split("x")
    return int(w), int(h)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.gpu_frame", description=__doc__.splitlines()[0]
    )
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("prepare", help="record shaders and data with bpy")
    p.add_argument("outdir")
    p = sub.add_parser("check", help="harness pictures vs gpu.draw.draw_items (bpy + moderngl)")
    p.add_argument("outdir")
    p = sub.add_parser("measure", help="compile, draw and time (numpy + moderngl)")
    p.add_argument("outdir")
    p.add_argument("--out", required=True, help="result JSON")
    p.add_argument("--backend", default="egl", help="moderngl standalone backend (default egl; '' = default)")
    p.add_argument("--size", default=f"{RESOLUTION[0]}x{RESOLUTION[1]}", help="frame size WxH")
    p.add_argument("--warmup", type=int, default=WARMUP)
    p.add_argument("--rounds", type=int, default=ROUNDS, help="timed rounds per scene (0: no timing)")
    p.add_argument("--scenes", nargs="+", help="time only these scenes")
    p.add_argument("--pictures", help="folder for pictures-WxH.npz and a few PNGs")
    p.add_argument("--picture-size", default=f"{CHECK_SIZE[0]}x{CHECK_SIZE[1]}")
    p.add_argument("--png", nargs="*", default=list(PNG_CASES), help="cases saved as full-size PNG")
    p.add_argument("--no-blender-sources", action="store_true", help="skip Blender's own GLSL")
    p.add_argument(
        "--skip", nargs="+", default=[], metavar="PATTERN", help="leave out cases (fnmatch on ids)"
    )
    p.add_argument("--budget-s", type=float, help="stop a scene's rounds after this many seconds")
    p = sub.add_parser("compare", help="recompute a result's picture comparison (numpy only)")
    p.add_argument("result")
    p.add_argument("pictures", help="the pictures-WxH.npz that measure --pictures wrote with the result")
    p.add_argument("reference", help="OUTDIR/pictures-check.npz")
    p = sub.add_parser("report", help="write docs/gpu-frame.md from a result JSON")
    p.add_argument("result")
    p.add_argument(
        "--extra", nargs="+", help="results of further measure runs: merged into docs/gpu-frame.json first"
    )
    args = parser.parse_args(argv)
    if args.command == "prepare":
        _command("prepare").prepare(args.outdir)
    elif args.command == "check":
        result = _command("check").check(args.outdir)
        return 0 if result["max"] <= 1 and not result["notes"] else 1
    elif args.command == "measure":
        _command("measure").measure(
            args.outdir,
            args.out,
            backend=args.backend or None,
            size=_parse_size(args.size),
            warmup=args.warmup,
            rounds=args.rounds,
            pictures=args.pictures,
            picture_size=_parse_size(args.picture_size),
            png_cases=tuple(args.png),
            scenes=args.scenes,
            blender_sources=not args.no_blender_sources,
            skip=tuple(args.skip),
            budget_s=args.budget_s,
        )
    elif args.command == "compare":
        for name, d in compare(args.result, args.pictures, args.reference).items():
            print(f"{name}: max {d['max']}, covered mean {d['inside_mean']:.4f}, >1: {d['over_1_px']} px")
    else:
        print(write_report(args.result, args.extra))
    return 0


if __name__ == "__main__":
    sys.exit(main())
