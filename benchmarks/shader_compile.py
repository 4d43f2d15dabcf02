"""First-compile time of every shader variant the sample scenes draw (issue 16).

Usage (from the repository root)::

    .venv/bin/python -m benchmarks.shader_compile                 # → docs/shader-compile.md
    .venv/bin/python -m benchmarks.shader_compile --only soap_bubble --no-per-pixel   # smoke run

Each sample scene (``sample_scenes/make_scenes.py``, built into a temporary folder) is opened with
the extension registered, collected as a headless frame does (tables baked, World analysed, the
films' outgoing-radiance grids built) and every variant that ``gpu.draw.prepare_draw`` picks for
its items is compiled cold in a fresh ``gpu.shaders.ShaderCache``, with Mesa's on-disk shader cache
off (``MESA_SHADER_CACHE_DISABLE``): each compile is timed from ``GPUShaderCreateInfo`` to the
linked program.
Besides what the product draws: the stand-in of each variant (``variant.stand_in``, what the
viewport draws while the variant compiles at idle) and, unless ``--no-per-pixel``, the per-pixel
SH variant a grid variant replaces (what the viewport compiled before).
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys
import tempfile
import time
from pathlib import Path

from . import common
from .viewport.scene import Extension

# Cold compiles: Mesa's on-disk shader cache would hand back a variant compiled by an earlier run
# (set before bpy creates its GL context).
os.environ.setdefault("MESA_SHADER_CACHE_DISABLE", "true")


def _make_scenes_module():
    spec = importlib.util.spec_from_file_location(
        "thinfilm_sh_make_scenes", Path(common.ROOT) / "sample_scenes" / "make_scenes.py"
    )
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def _variants(ext, items) -> list:
    """(variant, item name) of each item as prepare_draw picks it (display output)."""
    from precompute.shading.variant import choose_variant

    gd = ext.gpu
    out = []
    for item in items:
        table = item.table
        film = item.film
        out.append(
            (
                choose_variant(
                    l_max=table.l_max,
                    spectral=table.spectral,
                    thickness_rows=table.thickness_count,
                    has_thickness=item.batch.has_thickness,
                    display=True,
                    prefiltered=item.prefiltered is not None,
                    sh_weight=item.sh_weight,
                    lamp_count=item.lighting.lamp_count,
                    film=film is not None,
                    film_ubo=film is not None and film.ubo is not None,
                    table_ubo=table.ubo is not None,
                    light_count=gd.resources.light_count(item.lights),
                    grid=item.grid is not None,
                ).normalised(),
                item.name,
            )
        )
    return out


def _compile(ext, variant) -> float:
    cache = ext.gpu.shaders.ShaderCache()
    start = time.perf_counter()
    cache.mesh(variant)
    return time.perf_counter() - start


def run(names=None, per_pixel: bool = True, log=print) -> dict:
    import bpy

    from precompute.shading.variant import stand_in

    ext = Extension()
    made = _make_scenes_module().make_scenes(tempfile.mkdtemp(prefix="tf_compile_"), names=names)
    rows = []
    done: dict = {}
    for name, path in made.items():
        bpy.ops.wm.open_mainfile(filepath=str(path))
        ext.package.register()
        items, messages = ext.scene_draw.collect(bpy.context.evaluated_depsgraph_get())
        for variant, item_name in dict(_variants(ext, items)).items():
            kinds = [("drawn", variant), ("stand-in", stand_in(variant))]
            if per_pixel and variant.grid:
                kinds.append(("per-pixel SH (before)", variant._replace(grid=False)))
            for kind, v in kinds:
                if v not in done:
                    done[v] = _compile(ext, v)
                    log(f"  {name}: {item_name} {kind} l_max {v.l_max} grid {v.grid}: {done[v]:.1f} s")
                rows.append(
                    {
                        "scene": name,
                        "item": item_name,
                        "kind": kind,
                        "variant": v._asdict(),
                        "seconds": done[v],
                    }
                )
    return {"rows": rows, "machine": common.machine_lines()}


def report(res: dict) -> str:
    lines = [
        "# Shader compile time",
        "",
        "First compile of every shader variant the sample scenes draw, cold, each in a fresh",
        "`ShaderCache` (`python -m benchmarks.shader_compile`). *drawn*: what the product draws;",
        "*stand-in*: what the viewport draws while that variant compiles at idle",
        "(`variant.stand_in`, addon/drawing/shader_warmup.py); *per-pixel SH (before)*: the variant a",
        "radiance-grid variant replaces, which the viewport compiled in its draw callback before.",
        "A variant several scenes draw is compiled once: its rows repeat that figure.",
        "",
        "| Scene | Item | Kind | l_max | grid | split | lamps | vary | s |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for row in res["rows"]:
        v = row["variant"]
        lines.append(
            f"| {row['scene']} | {row['item']} | {row['kind']} | {v['l_max']} | {v['grid']} |"
            f" {v['split_sum']} | {v['lamps']} | {v['vary_thickness']} | {row['seconds']:.1f} |"
        )
    lines += ["", "Machine:", "", *res["machine"], ""]
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="+", help="these sample scenes (prints, writes nothing)")
    parser.add_argument("--no-per-pixel", action="store_true", help="skip the per-pixel SH variants")
    args = parser.parse_args(argv)
    res = run(args.only, per_pixel=not args.no_per_pixel)
    if args.only:
        return 0
    print(common.write_doc("shader-compile.md", report(res)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
