"""Command line: ``python -m precompute bake|render|presets|plan``.

Run ``python -m precompute --help`` (or ``<command> --help``) for an artist-readable guide.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import pathlib
import sys
import time

import numpy as np

from ..materials.material import AUTO, PRESETS, Layer, Material, Quality, preset
from . import cli_support

EPILOG = """examples:
  python -m precompute presets
  python -m precompute bake --preset soap_film --out soap.exr
  python -m precompute bake --film-index 1.45 --thickness 350 --substrate gold --roughness 0.2 --out gold.exr
  python -m precompute bake --preset oil_on_water --thickness-range 100 900 --sh-order 6 --half --out oil.exr
  python -m precompute render --preset anodised_titanium --hdri studio --out titanium.png
"""


class Progress:
    """A one-line progress bar on stderr (silent when stderr is not a terminal and quiet is set)."""

    def __init__(self, label: str, enabled: bool = True):
        self.label, self.enabled, self.start = label, enabled, time.perf_counter()

    def __call__(self, fraction: float, text: str = "") -> None:
        """Draw the bar at *fraction* (0–1) with an optional status *text*."""
        if not self.enabled:
            return
        width = 28
        filled = int(round(width * min(max(fraction, 0.0), 1.0)))
        bar = "█" * filled + "·" * (width - filled)
        elapsed = time.perf_counter() - self.start
        end = "\n" if fraction >= 1.0 else ""
        sys.stderr.write(f"\r{self.label} [{bar}] {fraction * 100:5.1f}% {elapsed:6.1f}s {text:<28}{end}")
        sys.stderr.flush()


def _index_arg(text: str):
    """'1.45' → 1.45; '2.4+0.3j' or '2.4,0.3' → [2.4, 0.3]; 'gold' → {'metal': 'gold'}."""
    try:
        return float(text)
    except ValueError:
        pass
    if "," in text:
        n, k = (float(v) for v in text.split(","))
        return [n, k]
    try:
        c = complex(text.replace("i", "j"))
        return [c.real, c.imag]
    except ValueError:
        return {"metal": text}


def _quality_value(text: str):
    return text if text == AUTO else int(text)


def add_material_arguments(p: argparse.ArgumentParser) -> None:
    """Add the material options (--preset, --film-index, thickness, ...) to a parser."""
    g = p.add_argument_group("material (start from --preset, then override)")
    g.add_argument("--preset", choices=sorted(PRESETS), help="start from a named material")
    g.add_argument("--film-index", type=_index_arg, help="film index: 1.33, 2.4,0.3 (n,k) or a metal name")
    g.add_argument("--thickness", type=float, help="film thickness in nm (top layer)")
    g.add_argument(
        "--thickness-range",
        type=float,
        nargs=2,
        metavar=("MIN", "MAX"),
        help="thickness varies over the surface between MIN and MAX nm (adds a table axis)",
    )
    g.add_argument("--constant-thickness", action="store_true", help="drop a preset's thickness variation")
    g.add_argument("--layers", help="full stack as JSON: [[index, thickness_nm], ...] from the top")
    g.add_argument(
        "--substrate",
        type=_index_arg,
        help="substrate index or metal (gold, silver, copper, aluminium, titanium, iron)",
    )
    g.add_argument("--ambient", type=float, help="index of the medium the surface sits in (air 1.0)")
    g.add_argument("--roughness", type=float, help="Blender roughness 0–1 (GGX α = roughness²)")
    g.add_argument(
        "--base-color", type=float, nargs=3, metavar=("R", "G", "B"), help="diffuse base under the film"
    )
    g.add_argument(
        "--model", choices=["exact", "glassner2000"], help="optics: exact (default) or the paper's eq. 4"
    )
    g.add_argument(
        "--colour-mode",
        choices=["spectral", "per_channel"],
        help="spectral 3×3 (default) or Cycles-matching per channel",
    )
    g.add_argument("--colour-space", choices=["Linear Rec.709", "Linear Rec.2020", "ACEScg"])
    g.add_argument("--illuminant", help="light spectrum shape: E (default), D65, A, FL1–FL12")
    q = p.add_argument_group("quality (each 'auto' unless given)")
    q.add_argument("--sh-order", type=_quality_value, help="highest SH band 0–8")
    q.add_argument("--view-samples", type=_quality_value, help="θo samples")
    q.add_argument("--thickness-samples", type=_quality_value, help="samples along the thickness axis")
    q.add_argument("--wavelengths", type=_quality_value, help="wavelength samples")


def _layers_arg(text: str) -> list[Layer]:
    """``--layers`` JSON: a list of [index, thickness_nm] rows (ValueError naming the option)."""
    try:
        rows = json.loads(text)
    except (ValueError, RecursionError) as exc:
        raise ValueError(f"--layers is not valid JSON: {exc}") from None
    if not isinstance(rows, list):
        raise ValueError(f"--layers must be a JSON list of [index, thickness_nm] rows, got {text[:60]!r}")
    layers = []
    for i, row in enumerate(rows):
        if not isinstance(row, list) or len(row) != 2:
            raise ValueError(f"--layers row {i} must be [index, thickness_nm], got {json.dumps(row)[:60]}")
        layers.append(Layer(*row))
    return layers


def material_from_args(args) -> Material:
    """Build the Material from a preset and the command-line overrides (validated)."""
    base = preset(args.preset) if args.preset else Material()
    changes = {}
    layers = list(base.layers)
    if args.layers:
        layers = _layers_arg(args.layers)
    if args.film_index is not None or args.thickness is not None:
        top = layers[0] if layers else Layer(1.33, 400.0)
        layers[0:1] = [
            Layer(
                args.film_index if args.film_index is not None else top.index,
                args.thickness if args.thickness is not None else top.thickness_nm,
            )
        ]
    changes["layers"] = tuple(layers)
    if args.thickness_range:
        changes["thickness_range_nm"] = tuple(args.thickness_range)
    elif args.constant_thickness or (args.thickness is not None and not args.preset):
        changes["thickness_range_nm"] = None
    for name in ("substrate", "ambient", "roughness", "model", "colour_mode", "colour_space", "illuminant"):
        value = getattr(args, name)
        if value is not None:
            changes[name] = value
    if args.base_color:
        changes["base_color"] = tuple(args.base_color)
    q = base.quality
    changes["quality"] = Quality(
        sh_order=args.sh_order if args.sh_order is not None else q.sh_order,
        view_samples=args.view_samples if args.view_samples is not None else q.view_samples,
        thickness_samples=args.thickness_samples
        if args.thickness_samples is not None
        else q.thickness_samples,
        wavelength_count=args.wavelengths if args.wavelengths is not None else q.wavelength_count,
    )
    return base.with_(**changes)


def cmd_presets(args) -> int:
    """`presets`: list the built-in materials."""
    for name, m in PRESETS.items():
        stack = " | ".join(f"{layer.index} {layer.thickness_nm:g} nm" for layer in m.layers[:3])
        more = f" … ({len(m.layers)} layers)" if len(m.layers) > 3 else ""
        vary = f", thickness {m.thickness_range_nm[0]:g}–{m.thickness_range_nm[1]:g} nm" if m.varies else ""
        print(f"{name:20s} {stack}{more} on {m.substrate}, roughness {m.roughness}{vary}")
    return 0


def cmd_plan(args) -> int:
    """`plan`: print which effects a material needs and what they cost."""
    from ..effects import plan_text, plans  # lazy: `--help` and argument errors load no bake or render code

    with cli_support.refusing():
        material = material_from_args(args)
    print(plan_text.format_plan(plans.material_plan(material)))
    return 0


def summary_path(out: pathlib.Path, json_arg: str | None) -> pathlib.Path:
    """Where ``bake`` writes its JSON summary: ``--json``, else beside ``--out`` with ``.json``.

    Never the table's own path: ``--out x.json`` puts the summary in ``x.json.json``, and
    ``--json`` naming the same file as ``--out`` is a ``ValueError`` (the summary would replace
    the table).
    """
    if json_arg:
        path = pathlib.Path(json_arg)
        if _same_file(path, out):
            raise ValueError(
                f"--json and --out both name {str(out)!r}: the summary would replace the table; "
                "give --json another path (or leave it out for one beside the table)"
            )
        return path
    path = out.with_suffix(".json")
    return path if not _same_file(path, out) else out.with_name(out.name + ".json")


def _same_file(a: pathlib.Path, b: pathlib.Path) -> bool:
    """Whether two output paths may name one file: equal once made absolute (ignoring case, as
    macOS and Windows file systems do), or already one file (hard or symbolic links)."""
    if os.path.abspath(a).casefold() == os.path.abspath(b).casefold():
        return True
    return a.exists() and b.exists() and os.path.samefile(a, b)


def cmd_bake(args) -> int:
    """`bake`: bake a material's SH table to an EXR file."""
    from ..bakes import bake  # lazy: `--help` and argument errors load no bake or render code
    from ..tables import (  # lazy: `--help` and argument errors load no bake or render code
        atomic_write,
        table_io,
    )

    with cli_support.refusing():  # everything checked before the bake: a refusal is exit 2
        m = material_from_args(args)
        out = cli_support.output_file("--out", args.out)
        if args.json is not None:
            cli_support.output_file("--json", args.json)  # as given: "dir/" and "" are refused
        json_path = summary_path(out, args.json)
        cli_support.output_file("--json", json_path)
    progress = Progress("bake", not args.quiet)
    t0 = time.perf_counter()
    result = bake.bake(m, progress=progress)
    out.parent.mkdir(parents=True, exist_ok=True)
    json_path.parent.mkdir(parents=True, exist_ok=True)
    precision = "half" if args.half else "float"
    table_io.write_table(out, result.data, result.attributes(), precision=precision)
    summary = dict(
        result.summary(),
        output=str(out),
        precision=precision,
        file_bytes=out.stat().st_size,
        wall_s=time.perf_counter() - t0,
    )
    if args.half:
        err = table_io.half_precision_error(result.data)
        summary["half_error"] = {"max_abs": err.max_abs, "max_rel": err.max_rel}
    atomic_write.write_bytes(json_path, json.dumps(summary, indent=2, allow_nan=False).encode("utf-8"))
    if not args.quiet:
        print(f"wrote {out} ({summary['file_bytes']} bytes, table {result.data.shape}) and {json_path}")
    return 0


def studiolight(name: str) -> pathlib.Path:
    """Path of one of the HDRIs shipped inside the bpy package (found without importing bpy)."""
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        raise FileNotFoundError(
            f"HDRI {name!r}: not a file, and the bpy package (which ships studio lights) "
            "is not installed; pass a path to an .exr"
        )
    base = pathlib.Path(list(spec.submodule_search_locations)[0])
    hits = sorted(base.glob(f"*/datafiles/studiolights/world/{name}.exr"))
    if not hits:
        names = sorted(p.stem for p in base.glob("*/datafiles/studiolights/world/*.exr"))
        raise FileNotFoundError(f"HDRI {name!r} not found; bpy ships: {', '.join(names)}")
    return hits[0]


def _read_hdri(text: str) -> tuple[pathlib.Path, np.ndarray, int]:
    """(path, image, NaN/Inf pixels set to 0) of ``--hdri``: a file, or a studio light of bpy."""
    from ..world import hdri  # lazy: `--help` and argument errors load no bake or render code

    path = pathlib.Path(text)
    if not path.exists():
        path = studiolight(text)
    image = hdri.read_equirect(path)
    bad = ~np.isfinite(image).all(axis=-1)
    if bad.any():  # left out (black), as the World's SH projection does, and reported
        image = np.where(bad[..., None], 0.0, image).astype(np.float32)
    return path, image, int(bad.sum())


def cmd_render(args) -> int:
    """`render`: bake and render a preview sphere to an image."""
    # lazy: `--help` and argument errors load no bake or render code
    from ..bakes import bake
    from ..output import image_io, render
    from ..tables import atomic_write, table_io
    from ..world import prefilter

    with cli_support.refusing():  # everything checked before the bake: a refusal is exit 2
        m = material_from_args(args)
        out = cli_support.output_file("--out", args.out)
        exr_out = out.with_suffix(".exr")
        if _same_file(exr_out, out):
            raise ValueError(
                f"--out {str(out)!r} names the PNG, and the scene-linear EXR is written beside it with .exr: "
                "give --out a .png path"
            )
        cli_support.output_file("--out (the .exr beside it)", exr_out)
        path, environment, rejected = _read_hdri(args.hdri)
    notes = [f"HDRI {path.name}: {rejected} NaN/Inf pixels left out (black)"] if rejected else []
    progress = Progress("render", not args.quiet)
    progress(0.02, "reading HDRI")
    result = bake.bake(m, progress=lambda f, t: progress(0.05 + 0.4 * f, t))
    image, coeffs = render.prepare_environment(environment, result.sh_order, roughness=m.roughness)
    progress(0.5, "shading")
    view = render.sphere_view(args.size, args.size)
    thickness = (
        args.thickness
        if args.thickness is not None
        else (0.5 * sum(m.thickness_range_nm) if m.varies else None)
    )
    progress(0.55, "prefiltering the HDRI")
    pre = None if args.reference or args.sh_only else prefilter.prefilter(image)
    progress(0.7, "shading")
    rgb = render.render_sphere(
        result,
        image,
        coeffs,
        view,
        thickness,
        reference_material=m if args.reference else None,
        prefiltered=pre,
    )
    bad = ~np.isfinite(rgb).all(axis=-1)
    if bad.any():  # never a NaN written without a word: 0, reported, exit "partial"
        notes.append(f"{int(bad.sum())} non-finite pixels written as 0")
        rgb = np.where(bad[..., None], 0.0, rgb)
    out.parent.mkdir(parents=True, exist_ok=True)
    display = image_io.srgb_encode(rgb, args.exposure)
    atomic_write.write_file(out, lambda tmp: image_io.write_png(tmp, display), verify=verify_png)
    atomic_write.write_file(exr_out, lambda tmp: image_io.write_exr(tmp, rgb), verify=table_io.verify_exr)
    progress(1.0, "done")
    for note in notes:
        print(f"warning: {note}", file=sys.stderr)
    if not args.quiet:
        print(f"wrote {out} and {exr_out} ({args.size}×{args.size}, HDRI {path.name})")
    return cli_support.EXIT_PARTIAL if notes else cli_support.EXIT_OK


_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_PNG_END = b"\x00\x00\x00\x00IEND\xaeB`\x82"  # the IEND chunk: length 0, type, CRC


def verify_png(path) -> None:
    """``ValueError`` unless ``path`` starts with the PNG signature and ends with the IEND chunk
    (what :func:`render.write_png` writes): a truncated PNG, e.g. on a full disk, is caught."""
    with open(path, "rb") as handle:
        head = handle.read(len(_PNG_SIGNATURE))
        handle.seek(0, os.SEEK_END)
        size = handle.tell()
        handle.seek(max(0, size - len(_PNG_END)))
        tail = handle.read()
    if head != _PNG_SIGNATURE or tail != _PNG_END:
        raise ValueError(f"{str(path)!r} is not a complete PNG ({size} bytes)")


def _material_command(sub, name: str, help_text: str) -> argparse.ArgumentParser:
    """A command that takes a material (``bake``, ``render``), with the examples as its epilog."""
    parser = sub.add_parser(
        name, help=help_text, epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    add_material_arguments(parser)
    return parser


def build_parser() -> argparse.ArgumentParser:
    """The `python -m precompute` argument parser with its sub-commands."""
    parser = cli_support.ArgumentParser(
        prog="python -m precompute",
        description="Thin Film SH: bake thin-film interference into SH tables, or preview a material.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("presets", help="list the material presets").set_defaults(func=cmd_presets)
    p = sub.add_parser("plan", help="show the automatic quality choices for a material and why")
    add_material_arguments(p)
    p.set_defaults(func=cmd_plan)
    b = _material_command(sub, "bake", "bake a material's SH table to an OpenEXR file (+ a JSON summary)")
    b.add_argument(
        "--out",
        required=True,
        help="output .exr path (a FIFO, device, symbolic link or directory there is refused)",
    )
    b.add_argument(
        "--json", help="summary path (default: beside --out with .json; never the same file as --out)"
    )
    b.add_argument("--half", action="store_true", help="store half floats (half the size; error reported)")
    b.add_argument("--quiet", action="store_true", help="no progress bar or messages")
    b.set_defaults(func=cmd_bake)
    r = _material_command(sub, "render", "render a sphere with the material under an HDRI to PNG + EXR")
    r.add_argument(
        "--hdri",
        default="studio",
        help="an .exr path, or a studio light shipped with bpy "
        "(city, courtyard, forest, interior, night, studio, sunrise, sunset)",
    )
    r.add_argument(
        "--out", required=True, help="output .png (an .exr with scene-linear values is written beside it)"
    )
    r.add_argument(
        "--size",
        type=cli_support.image_size_arg("--size"),
        default=256,
        help=f"image size in pixels (square, 1–{cli_support.MAX_IMAGE_SIZE})",
    )
    r.add_argument(
        "--exposure",
        type=cli_support.exposure_arg("--exposure"),
        default=0.0,
        help=f"exposure in stops for the PNG (finite, within ±{cli_support.MAX_EXPOSURE:g})",
    )
    r.add_argument("--reference", action="store_true", help="brute-force spectral ground truth (slow)")
    r.add_argument(
        "--sh-only", action="store_true", help="the paper's SH path alone (no split sum for gloss)"
    )
    r.add_argument("--quiet", action="store_true")
    r.set_defaults(func=cmd_render)
    return parser


def main(argv=None) -> int:
    """Run one command; the exit code is one of docs/cli-exit-codes.md (cli_support.EXIT_*).

    Never a traceback: input refused before work is exit 2, an output that cannot be written
    exit 4, a bug exit 3 with the traceback in a log file the one-line message names.
    """
    parser = build_parser()

    def body() -> int:
        args = parser.parse_args(argv)  # argparse's own refusals exit 2 through SystemExit
        return args.func(args)

    return cli_support.run(body, prog="precompute")
