"""docs/cli.md is the command lines' reference (issue 19): every command and option of both
parsers is documented there, and the JSON outputs match the schema it carries.

The schema is the ```json cli-schema``` block of docs/cli.md: per output, the ``required`` and
``optional`` fields (``materials.*``: the fields of each entry of ``materials``).
"""

from __future__ import annotations

import json
import re

import pytest
from _extension import REPO, registered_extension, set_cache_preference

DOC = REPO / "docs" / "cli.md"


def schema() -> dict:
    text = DOC.read_text(encoding="utf-8")
    match = re.search(r"```json cli-schema\n(.*?)```", text, flags=re.S)
    assert match, "docs/cli.md has no ```json cli-schema``` block"
    return json.loads(match.group(1))


def check(output: str, summary: dict) -> None:
    """``summary`` has every required field of ``output`` and none outside the documented ones."""
    spec = schema()[output]
    keys = set(summary)
    missing = set(spec["required"]) - keys
    extra = keys - set(spec["required"]) - set(spec["optional"])
    assert not missing and not extra, f"{output}: missing {sorted(missing)}, undocumented {sorted(extra)}"
    for field, sub in spec.items():
        if field.endswith(".*"):
            for entry in summary[field[:-2]].values():
                check_fields(f"{output} {field}", entry, sub)


def check_fields(name, entry, spec) -> None:
    keys = set(entry)
    missing = set(spec["required"]) - keys
    extra = keys - set(spec["required"]) - set(spec["optional"])
    assert not missing and not extra, f"{name}: missing {sorted(missing)}, undocumented {sorted(extra)}"


def _options(parser) -> set[str]:
    """Every option string and sub-command name of an argparse parser, recursively."""
    import argparse

    found = set()
    for action in parser._actions:
        found.update(o for o in action.option_strings if o.startswith("--"))
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                found.add(name)
                found |= _options(sub)
    return found - {"--help"}


def test_precompute_options_are_documented():
    """Every option of the precompute command line appears in docs/cli.md, so the reference never lags the
    tool."""
    from precompute.commands.cli import build_parser

    text = DOC.read_text(encoding="utf-8")
    missing = sorted(o for o in _options(build_parser()) if f"`{o}" not in text)
    assert not missing, f"docs/cli.md does not document {missing}"


def test_precompute_help_imports_no_heavy_package():
    import subprocess
    import sys

    probe = "import sys, contextlib, io\nfrom precompute.commands.cli import main\n"
    probe += "with contextlib.redirect_stdout(io.StringIO()), contextlib.suppress(SystemExit):\n"
    probe += "    main(['--help'])\nprint(sorted(sys.modules))"
    out = subprocess.run(
        [sys.executable, "-c", probe],
        cwd=REPO,
        capture_output=True,
        text=True,
        check=False,
    )
    modules = {m.split(".")[0] for m in out.stdout.split("'")}
    assert "precompute" in modules, out.stderr
    heavy = {"colour", "matplotlib", "scipy"} & modules
    assert not heavy, heavy
    loaded = set(out.stdout.split("'"))  # the bake and the renderer load with a command, not for help
    assert not {"precompute.bakes.bake", "precompute.output.render", "precompute.world.prefilter"} & loaded


@pytest.fixture(scope="module")
def tf(bpy, tmp_path_factory):
    """The extension, registered once for the module, with a private table cache."""
    with registered_extension(
        bpy,
        tmp_path_factory.mktemp("extension"),
        (
            "addon.headless.headless",
            "addon.ui.prefs",
            "addon.headless.cli_args",
        ),
    ) as ns:
        yield ns


@pytest.mark.blender
def test_headless_options_are_documented(tf):
    """Every option of Blender's `-c thinfilm_sh` commands appears in docs/cli.md, so the reference never
    lags the tool."""
    text = DOC.read_text(encoding="utf-8")
    missing = sorted(o for o in _options(tf.cli_args.parser()) if f"`{o}" not in text)
    assert not missing, f"docs/cli.md does not document {missing}"


@pytest.mark.blender
def test_headless_json_outputs_match_the_documented_schema(bpy, tf, tmp_path, capsys):
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    tf.package.register()
    set_cache_preference(bpy, tf.prefs, tf.cache_dir)
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 24, 16, 100
    bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, segments=16, ring_count=8)
    mat = bpy.data.materials.new("Doc Film")
    mat.thinfilm_sh.preset = "SOAP_FILM"
    mat.thinfilm_sh.enabled = True
    bpy.context.object.data.materials.append(mat)
    bpy.ops.object.camera_add(location=(0.0, -5.0, 0.0), rotation=(1.5708, 0.0, 0.0))
    scene.camera = bpy.context.object
    scene.world = bpy.data.worlds.new("Doc World")
    assert (
        tf.headless._cli(["bake", "--json", str(tmp_path / "bake.json"), "--out-dir", str(tmp_path / "t")])
        == 0
    )
    check("headless bake", json.loads((tmp_path / "bake.json").read_text()))
    render = ["render", "--out", str(tmp_path / "r.png"), "--engine", "SOLID", "--supersample", "1"]
    assert tf.headless._cli([*render, "--json", str(tmp_path / "render.json")]) == 0
    check("headless render", json.loads((tmp_path / "render.json").read_text()))
    frames = ["render", "--out", str(tmp_path / "f#.png"), "--engine", "SOLID", "--supersample", "1"]
    assert tf.headless._cli([*frames, "--frames", "1-2", "--json", str(tmp_path / "frames.json")]) == 0
    summary = json.loads((tmp_path / "frames.json").read_text())
    check("headless render frames", summary)
    for frame in summary["frames"]:
        check("headless render", frame)
    capsys.readouterr()
    assert tf.headless._cli(["plan"]) == 0
    lines = [line for line in capsys.readouterr().out.splitlines() if line.startswith("plan-json ")]
    assert lines
    for line in lines:
        check("headless plan", json.loads(line[len("plan-json ") :]))
