"""The headless commands' options: one argparse parser, built without Blender.

``blender -b FILE.blend -c thinfilm_sh bake|render|plan …`` and scripts/thinfilm_headless.py
parse with :func:`parser`; it imports neither ``bpy`` nor numpy, so ``--help`` answers before
a .blend is opened (scripts/thinfilm_headless.py loads this module alone for it). Every option
is documented in docs/cli.md.
"""

from __future__ import annotations

import argparse
import re

from ...precompute.commands import cli_support

#: Samples per pixel along each axis of the headless frame (the default of ``--supersample``;
#: addon/headless/headless.py's SUPERSAMPLE).
SUPERSAMPLE = 4
#: ``--engine`` choices: the engine that renders the rest of the scene (addon/headless/background.py),
#: or SOLID for Blender's Solid drawing with the World's panorama behind the films.
ENGINE_CHOICES = ("EEVEE", "WORKBENCH", "CYCLES", "SOLID")

_FRAMES = re.compile(r"^\s*(-?\d+)\s*-\s*(-?\d+)\s*(?::\s*(\d+))?\s*$")


def frame_range(text: str) -> list[int]:
    """``A-B`` or ``A-B:step`` → the frames A, A + step, …, ≤ B (step ≥ 1, A ≤ B, at most 100 000)."""
    match = _FRAMES.match(str(text))
    if match is None:
        raise argparse.ArgumentTypeError(f"expected A-B or A-B:STEP (e.g. 1-250:2), got {text!r}")
    start, end, step = int(match[1]), int(match[2]), int(match[3] or 1)
    if step < 1:
        raise argparse.ArgumentTypeError(f"the step must be at least 1, got {step}")
    if end < start:
        raise argparse.ArgumentTypeError(f"the last frame {end} is before the first {start}")
    frames = list(range(start, end + 1, step))
    if len(frames) > 100_000:
        raise argparse.ArgumentTypeError(f"{len(frames)} frames: at most 100000 per run")
    return frames


def resolution(text: str) -> tuple[int, int]:
    """``WxH`` (e.g. 1920x1080) → (W, H), each 1–16384."""
    match = re.fullmatch(r"\s*(\d+)\s*[xX×]\s*(\d+)\s*", str(text))
    if match is None:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT (e.g. 1920x1080), got {text!r}")
    try:
        return (
            cli_support.image_size("--resolution width", int(match[1])),
            cli_support.image_size("--resolution height", int(match[2])),
        )
    except cli_support.UsageError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def percentage(text: str) -> int:
    """``--percentage``: 1–1000 (% of the resolution)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number of percent, got {text!r}") from None
    if not 1 <= value <= 1000:
        raise argparse.ArgumentTypeError(f"must be 1–1000, got {value}")
    return value


def _scene_options(command) -> None:
    """What every command reads: which scene, view layer and frame."""
    command.add_argument("--scene", help="the scene to use (default: the file's active scene)")
    command.add_argument(
        "--view-layer", help="the view layer to use (default: the window's, else the scene's first)"
    )
    command.add_argument(
        "--frame", type=int, help="the frame to evaluate (default: the scene's current frame)"
    )
    command.add_argument(
        "--cache-dir",
        help="the table cache's folder (default: $THINFILM_SH_CACHE, else the add-on's preference, "
        "else a private per-user folder); tables go in its thinfilm_sh_tables subfolder",
    )
    command.add_argument("--quiet", action="store_true", help="print only errors and the final summary line")


def _render_options(r) -> None:
    r.add_argument(
        "--out",
        required=True,
        help="output .png (an .exr is written beside it); with --frames, '#'s become the frame "
        "number (zero-padded to their count), else _NNNN is added before the suffix",
    )
    r.add_argument("--frames", type=frame_range, help="render frames A to B (every STEP): A-B[:STEP]")
    r.add_argument("--camera", help="the camera object to render through (default: the scene's camera)")
    r.add_argument("--resolution", type=resolution, help="WIDTHxHEIGHT (default: the scene's resolution)")
    r.add_argument(
        "--percentage", type=percentage, help="%% of the resolution (default: the scene's resolution %%)"
    )
    r.add_argument("--width", type=cli_support.image_size_arg("--width"), help="output width (overrides)")
    r.add_argument("--height", type=cli_support.image_size_arg("--height"), help="output height (overrides)")
    r.add_argument(
        "--engine",
        choices=ENGINE_CHOICES,
        default="EEVEE",
        help="what renders the rest of the scene behind the films (default EEVEE; SOLID: Blender's "
        "Solid drawing with the World's panorama, the preview's look)",
    )
    r.add_argument(
        "--no-background",
        action="store_true",
        help="leave the World out of the picture (transparent film; it still lights)",
    )
    r.add_argument(
        "--no-scene-probe",
        action="store_true",
        help="skip the six views of the scene from solid glass's centre (what its paths see off the "
        "picture: then the World); saves their seconds",
    )
    r.add_argument(
        "--supersample",
        type=cli_support.supersample_arg("--supersample"),
        default=SUPERSAMPLE,
        help=f"samples per pixel along each axis, filtered with the scene's Cycles pixel filter "
        f"(default {SUPERSAMPLE}; 1: one sample per pixel, no filter)",
    )
    r.add_argument("--json", help="write a JSON summary here (objects, fallbacks, errors, messages)")


def parser() -> argparse.ArgumentParser:
    """The ``thinfilm_sh`` parser: ``bake``, ``render``, ``plan`` and their options."""
    top = cli_support.ArgumentParser(
        prog="thinfilm_sh", description="Thin Film SH: headless bake and render of the open .blend file."
    )
    sub = top.add_subparsers(dest="command", required=True)
    b = sub.add_parser("bake", help="bake every thin-film material the scene renders (uses the cache)")
    b.add_argument("--out-dir", help="also write each table as an EXR here (one file per material)")
    b.add_argument("--json", help="write a JSON summary here (errors and a manifest of the files)")
    r = sub.add_parser(
        "render", help="render the camera's view: the scene by EEVEE, the films drawn over it; PNG + EXR"
    )
    _render_options(r)
    p = sub.add_parser(
        "plan",
        help="print what each rendered material needs simulated (effects, table size, orders, estimated "
        "bake time and shader cost) and why; bakes nothing",
    )
    for command in (b, r, p):
        _scene_options(command)
    return top
