"""Thin Film SH's headless commands (bake, render, plan) through Python and the bpy module.

The same commands as ``blender -b FILE.blend -c thinfilm_sh bake|render|plan …`` (the CLI
command the extension registers with ``bpy.utils.register_cli_command``), for a Python that has
Blender as a module (``pip install bpy``; the repository's .venv):

    .venv/bin/python scripts/thinfilm_headless.py FILE.blend render --out out/a.png [--width W --height H]
    .venv/bin/python scripts/thinfilm_headless.py FILE.blend bake --json out/bake.json [--out-dir out/tables]
    .venv/bin/python scripts/thinfilm_headless.py FILE.blend plan

and, for a folder of files, a batch render of every .blend in it (sorted by name):

    .venv/bin/python scripts/thinfilm_headless.py --all-scenes sample_scenes/out --out-dir out/renders \\
        [--width W --height H] [--cache-dir DIR] [--engine EEVEE|WORKBENCH|CYCLES|SOLID]

It opens the file, registers the extension from this repository (imported as ``thinfilm_sh``
through a symlink in a temporary folder, as Blender imports an installed extension), runs
``addon.headless.headless.main`` with the remaining arguments and exits with its code (batch: 0 when
every file rendered, else 1). Baked tables go to the add-on's table cache: ``--cache-dir DIR``
(every command takes it), else ``$THINFILM_SH_CACHE``, else the private per-user
``~/.cache/thinfilm_sh`` (``$XDG_CACHE_HOME/thinfilm_sh``); see docs/cache.md.
"""

from __future__ import annotations

import argparse
import gc
import importlib
import os
import pathlib
import sys
import tempfile

REPO = pathlib.Path(__file__).resolve().parent.parent
EXTENSION_ID = "thinfilm_sh"

USAGE = """usage: thinfilm_headless.py FILE.blend {bake,render,plan} [args]
       thinfilm_headless.py --all-scenes DIR --out-dir OUT [--width W] [--height H]

Run 'thinfilm_headless.py FILE.blend COMMAND --help' for a command's options."""


def options_parser():
    """The commands' argparse parser (addon/headless/cli_args.py) without importing Blender or opening a
    file: the package and its ``addon`` subpackage are stood in for by bare modules, so their
    ``__init__`` (which imports bpy) does not run. Only for ``--help``: the process ends after."""
    import types

    for name, path in ((EXTENSION_ID, REPO), (f"{EXTENSION_ID}.addon", REPO / "addon")):
        if name not in sys.modules:
            module = types.ModuleType(name)
            module.__path__ = [str(path)]
            sys.modules[name] = module
    return importlib.import_module(f"{EXTENSION_ID}.addon.headless.cli_args").parser()


def register_extension():
    """Import this repository as the package ``thinfilm_sh`` and register it; returns the package."""
    module = sys.modules.get(EXTENSION_ID)
    if module is None:
        root = tempfile.mkdtemp(prefix="thinfilm_sh_ext_")
        os.symlink(REPO, os.path.join(root, EXTENSION_ID), target_is_directory=True)
        sys.path.insert(0, root)
        module = importlib.import_module(EXTENSION_ID)
    module.register()
    return module


def open_blend(path) -> None:
    import bpy

    path = pathlib.Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such .blend file")
    bpy.ops.wm.open_mainfile(filepath=str(path.resolve()))


def headless():
    return importlib.import_module(f"{EXTENSION_ID}.addon.headless.headless")


def run_file(blend, argv) -> int:
    """Open ``blend`` and run one headless command (``argv`` as after ``-c thinfilm_sh``)."""
    register_extension()
    open_blend(blend)
    return int(headless().main(list(argv)))


def release() -> None:
    """Before the process exits: unregister the extension (if this script registered it) and
    collect its garbage while Blender is still alive.

    GPU textures and batches, and the Blender data the caches refer to, must be freed before
    interpreter shutdown: collected after Blender's own exit they crash the process (exit code
    -11 after a complete render, seen once the linked-thickness caches existed).
    """
    module = sys.modules.get(EXTENSION_ID)
    if module is not None and hasattr(module, "unregister"):  # not the bare stand-in of --help
        module.unregister()
    gc.collect()


def render_all(folder, out_dir, width=None, height=None, background=True, cache_dir=None, engine=None) -> int:
    """Render every .blend in ``folder`` to ``out_dir/<stem>.png`` (+ .exr); 0 if all succeeded."""
    files = sorted(pathlib.Path(folder).glob("*.blend"))
    if not files:
        print(f"error: no .blend files in {folder}", file=sys.stderr)
        return 1
    register_extension()
    out = pathlib.Path(out_dir)
    failed = []
    for blend in files:
        argv = ["render", "--out", str(out / f"{blend.stem}.png")]
        if width:
            argv += ["--width", str(width)]
        if height:
            argv += ["--height", str(height)]
        if not background:
            argv.append("--no-background")
        if cache_dir:
            argv += ["--cache-dir", str(cache_dir)]
        if engine:
            argv += ["--engine", engine]
        print(f"== {blend.name}")
        try:
            open_blend(blend)
            code = int(headless().main(argv))
        except Exception as exc:  # one broken file must not stop the batch
            print(f"error: {blend.name}: {type(exc).__name__}: {exc}", file=sys.stderr)
            code = 1
        if code:
            failed.append(blend.name)
    print(
        f"rendered {len(files) - len(failed)}/{len(files)} files into {out}"
        + (f"; failed: {', '.join(failed)}" if failed else "")
    )
    return 1 if failed else 0


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in {"-h", "--help"}:
        print(__doc__ if argv else USAGE)
        return 0 if argv else 2
    if argv[0] == "--all-scenes":
        parser = argparse.ArgumentParser(
            prog="thinfilm_headless.py --all-scenes", description="Render every .blend in a folder."
        )
        parser.add_argument("--all-scenes", required=True, metavar="DIR", help="folder of .blend files")
        parser.add_argument("--out-dir", required=True, help="where <stem>.png and <stem>.exr go")
        parser.add_argument("--width", type=int)
        parser.add_argument("--height", type=int)
        parser.add_argument("--no-background", action="store_true")
        parser.add_argument("--cache-dir", help="the table cache's folder (see docs/cache.md)")
        parser.add_argument(
            "--engine", choices=("EEVEE", "WORKBENCH", "CYCLES", "SOLID"), help="as render --engine"
        )
        args = parser.parse_args(argv)
        return render_all(
            args.all_scenes,
            args.out_dir,
            args.width,
            args.height,
            not args.no_background,
            args.cache_dir,
            args.engine,
        )
    blend, rest = argv[0], argv[1:]
    if "-h" in rest or "--help" in rest:  # answered before Blender is imported or the file opened
        try:
            options_parser().parse_args(rest)
        except SystemExit as done:
            return int(done.code or 0)
    if not blend.endswith(".blend") or not rest:
        print(USAGE, file=sys.stderr)
        return 2
    if not pathlib.Path(blend).is_file():  # before importing bpy (seconds)
        print(f"error: {blend}: no such .blend file", file=sys.stderr)
        return 2
    try:
        return run_file(blend, rest)
    except FileNotFoundError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except RuntimeError as exc:  # bpy.ops.wm.open_mainfile: not a .blend file, or a damaged one
        print(f"error: {blend}: cannot be opened: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    exit_code = main()
    release()
    sys.exit(exit_code)
