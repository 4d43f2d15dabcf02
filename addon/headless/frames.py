"""The ``render`` command over frames: options → sizes, camera, output paths, one render per frame.

:func:`run_render` renders ``--frame`` / ``--frames`` through ``--camera`` at ``--resolution`` ×
``--percentage`` (the scene's by default; ``--width``/``--height`` override), printing a
progress line with timings per frame unless ``--quiet``. The World's lighting and the tables are
cached by content (scene_draw's World key, the table cache), so a World that does not change
across frames is analysed once for the whole range.
"""

from __future__ import annotations

import contextlib
import json
import pathlib
import re
import sys
import time

import bpy

from ...precompute.commands import cli_support
from ...precompute.tables import atomic_write
from .render import render_scene


def frame_path(out, frame: int | None, many: bool) -> pathlib.Path:
    """The output .png of ``frame``: ``#``s in the name become the zero-padded frame number;
    else, when rendering ``many`` frames, ``_NNNN`` goes before the suffix."""
    out = pathlib.Path(out)
    if frame is None:
        return out
    if "#" in out.name:
        name = re.sub(r"#+", lambda m: f"{frame:0{len(m.group(0))}d}", out.name)
        return out.with_name(name)
    return out.with_name(f"{out.stem}_{frame:04d}{out.suffix}") if many else out


def render_size(scene, args) -> tuple[int, int]:
    """(width, height): ``--resolution`` (else the scene's) × ``--percentage`` (else the
    scene's), each side overridden by ``--width``/``--height``; ``UsageError`` naming the source
    of a size outside 1–16384 pixels."""
    base = args.resolution or (scene.render.resolution_x, scene.render.resolution_y)
    percent = args.percentage or scene.render.resolution_percentage
    source = "--resolution" if args.resolution else "the scene's resolution"
    source += " × --percentage" if args.percentage else " × percentage"
    sizes = []
    for given, option, value in ((args.width, "--width", base[0]), (args.height, "--height", base[1])):
        if given:
            sizes.append(cli_support.image_size(option, given))
        else:
            sizes.append(cli_support.image_size(source, round(value * percent / 100.0)))
    return sizes[0], sizes[1]


def _camera(scene, name):
    """The ``--camera`` object (``UsageError`` naming the cameras there are), else the scene's."""
    if name is None:
        if scene.camera is None:
            raise cli_support.UsageError(f"scene '{scene.name}' has no camera: set one or pass --camera")
        return scene.camera
    obj = bpy.data.objects.get(name)
    if obj is None or obj.type != "CAMERA":
        cameras = ", ".join(repr(o.name) for o in scene.objects if o.type == "CAMERA") or "none"
        raise cli_support.UsageError(f"--camera: no camera object {name!r} (cameras in the scene: {cameras})")
    return obj


@contextlib.contextmanager
def _using_camera(scene, camera):
    saved = scene.camera
    scene.camera = camera
    try:
        yield
    finally:
        scene.camera = saved


def _aa(result) -> str:
    if not result["pixel_filter"]:
        return "1 sample per pixel"
    kind, width = result["pixel_filter"]
    name = kind.replace("_", "-").title()
    return f"{result['supersample']}×{result['supersample']} samples per pixel, {name} {width:g} px"


def run_render(args, scene) -> int:
    """`render`: each frame through the camera to its PNG and EXR (:func:`.render.render_scene`);
    the exit code (see docs/cli.md)."""
    frames = args.frames or [args.frame if args.frame is not None else None]
    many = args.frames is not None and len(frames) > 1
    with cli_support.refusing():  # before any work: a refusal is exit 2
        cli_support.output_file("--out", args.out)  # as given: "dir/" and "" are refused
        paths = [frame_path(args.out, f, many) for f in frames]
        if len(set(paths)) != len(paths):
            raise cli_support.UsageError("--out: every frame would write the same file; put '#' in the name")
        for path in paths:
            cli_support.output_file("--out", path)
            cli_support.output_file("--out (the .png)", path.with_suffix(".png"))
            cli_support.output_file("--out (the .exr beside it)", path.with_suffix(".exr"))
        json_path = cli_support.output_file("--json", args.json) if args.json else None
        width, height = render_size(scene, args)
        cli_support.exposure("the scene's exposure (Color Management)", scene.view_settings.exposure)
        camera = _camera(scene, args.camera)
    engine = None if args.engine == "SOLID" else args.engine
    results, failed, partial = [], [], False
    t_all = time.perf_counter()
    with _using_camera(scene, camera):
        for i, (frame, path) in enumerate(zip(frames, paths, strict=True)):
            if frame is not None:
                scene.frame_set(frame)
            if not args.quiet and many:
                print(f"frame {frame} ({i + 1}/{len(frames)}): rendering", flush=True)
            result = render_scene(
                scene,
                str(path),
                width,
                height,
                background=not args.no_background,
                supersample=args.supersample,
                engine=engine,
                scene_probe=not args.no_scene_probe,
            )
            result["frame"] = scene.frame_current
            results.append(result)
            if not args.quiet:
                for msg in result["messages"]:
                    print(f"note: {msg}")
            print(
                f"wrote {result['png']} and {result['exr']} ({result['size'][0]}×{result['size'][1]}, "
                f"{_aa(result)}, {len(result['objects'])} thin-film objects, {result['engine']}, "
                f"{result['seconds']:.1f} s)",
                flush=True,
            )
            errors = [*result["errors"].values(), *result["world_errors"]]
            failed.extend(errors)
            partial = partial or bool(errors or result["nonfinite_pixels"])
    if many and not args.quiet:
        print(f"rendered {len(frames)} frames in {time.perf_counter() - t_all:.1f} s")
    if json_path is not None:
        json_path.parent.mkdir(parents=True, exist_ok=True)
        summary = {"frames": results} if args.frames is not None else results[0]
        atomic_write.write_bytes(json_path, json.dumps(summary, indent=2, allow_nan=False).encode("utf-8"))
    for err in dict.fromkeys(failed):
        print(f"error: {err}", file=sys.stderr)
    return cli_support.EXIT_PARTIAL if partial else cli_support.EXIT_OK
