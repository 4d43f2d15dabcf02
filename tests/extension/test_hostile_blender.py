"""Issue 23, Blender side: hostile material, World and mesh data, and hostile headless commands.

Every case ends cleanly: a ValueError or message naming the problem and a finite picture drawn
with the documented fallback, or a refusal (exit 2) before any work. "Before any work" is
asserted by counting, not timing: the bake function and ``render_scene`` are replaced by ones
that fail the test if they are called. Everything runs in this one Blender process (the
extension is registered once for the module); most cases read descriptions, World SH or
thickness values and cost milliseconds, and six render 64×48 pictures on llvmpipe.

The pure side (materials, both command lines' options, EXR and cache files, output names) is
tests/headless/test_hostile_inputs.py. docs/hostile-input.md lists the fallbacks these tests check.
"""

from __future__ import annotations

import functools
import importlib
import importlib.util
import json
import math
import os
import types
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.blender

import _blender_scene  # noqa: E402
from _blender_scene import read_exr, white_world  # noqa: E402
from _extension import EXTENSION_ID, REPO, empty_file, linked_extension, set_cache_preference  # noqa: E402

#: This file's spheres are coarser (32 × 16) and its camera farther (7) than test_headless.py's.
sphere = functools.partial(_blender_scene.sphere, segments=(32, 16))
camera = functools.partial(_blender_scene.camera, distance=7.0)

NAN, INF = float("nan"), float("inf")
FLT_MAX = 3.4028234663852886e38  # what Blender stores for inf
SIZE = (64, 48)
SCRIPT = REPO / "scripts" / "thinfilm_headless.py"


# ----------------------------------------------------------------------------------------------
# Fixtures and small scenes
# ----------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def tf(bpy, tmp_path_factory):
    """The extension, registered once for the module, with a private cache; modules as attributes."""
    root = tmp_path_factory.mktemp("extension")
    with linked_extension(root) as package:
        try:
            package.register()
            ns = types.SimpleNamespace(package=package, cache_dir=root / "cache")
            for dotted in (
                "addon.headless.headless",
                "addon.headless.frames",
                "addon.materials.description",
                "addon.bakes.tables",
                "addon.ui.prefs",
                "addon.drawing.scene_draw",
                "addon.world.world",
            ):
                setattr(ns, dotted.rpartition(".")[2], importlib.import_module(f"{EXTENSION_ID}.{dotted}"))
            ns.thickness = importlib.import_module(f"{EXTENSION_ID}.addon.thickness.thickness")
            ns.cli_support = importlib.import_module(f"{EXTENSION_ID}.precompute.commands.cli_support")
            ns.material = importlib.import_module(f"{EXTENSION_ID}.precompute.materials.material")
            set_cache_preference(bpy, ns.prefs, ns.cache_dir)
            importlib.import_module(f"{EXTENSION_ID}.addon.gpu.context").ensure_gpu_context()
            yield ns
        finally:
            entry = bpy.context.preferences.addons.get(EXTENSION_ID)
            if entry is not None:
                bpy.context.preferences.addons.remove(entry)


@pytest.fixture
def fresh(bpy, tf):
    """An empty factory file with the extension registered and its private cache chosen."""
    scene = empty_file(bpy, tf, SIZE)
    scene.view_settings.view_transform = "Standard"
    tf.scene_draw.CACHES.clear()
    return scene


class Guard:
    """Counts calls of a function that must not run; each call fails the test too."""

    def __init__(self, what):
        self.what, self.calls = what, 0

    def __call__(self, *args, **kwargs):
        self.calls += 1
        raise AssertionError(f"{self.what} was called: the input should have been refused first")


@pytest.fixture
def no_bake(tf, monkeypatch):
    guard = Guard("precompute.bakes.bake.bake")
    monkeypatch.setattr(tf.tables.bake, "bake", guard)
    return guard


@pytest.fixture
def no_work(tf, monkeypatch, no_bake):
    """Neither a bake nor a render may start."""
    guard = Guard("render.render_scene")
    monkeypatch.setattr(tf.frames, "render_scene", guard)  # what the render command calls
    return types.SimpleNamespace(bake=no_bake, render=guard)


def film(bpy, name="Film", thickness_nm=420.0, roughness=0.3, preset="SOAP_FILM"):
    """A film at small explicit quality: its table bakes in a fraction of a second."""
    mat = bpy.data.materials.new(name)
    s = mat.thinfilm_sh
    s.preset = preset
    s.enabled = True
    s.vary_thickness = False
    s.layers[0].thickness_nm = thickness_nm
    s.roughness = roughness
    s.sh_order, s.view_samples, s.thickness_samples, s.wavelength_count = "4", 8, 8, 32
    return mat


# ----------------------------------------------------------------------------------------------
# Material settings: every value a script can store is refused with its name, before any bake
# ----------------------------------------------------------------------------------------------
def _set(mat, target: str, attribute: str, value) -> None:
    s = mat.thinfilm_sh
    if target in ("layer", "cauchy"):
        layer = s.layers[0]
        if target == "cauchy":
            layer.index_mode = "CAUCHY"
        setattr(layer, attribute, value)
    elif target == "custom":
        s.substrate_mode = "CUSTOM"
        setattr(s, attribute, value)
    elif target == "vary":
        s.vary_thickness = True
        setattr(s, attribute, value)
    elif target == "diffuse":
        s.diffuse_base = True
        setattr(s, attribute, value)
    else:
        setattr(s, attribute, value)


SETTINGS = [
    # (target, attribute, value, words the message must contain)
    ("layer", "n", NAN, "layers[0].index"),
    ("layer", "n", INF, "layers[0].index"),  # Blender stores 3.4e38: the 293 s bake
    ("layer", "n", 1e30, "layers[0].index"),
    ("layer", "n", 1500.0, "n ≤ 1000"),
    ("layer", "k", NAN, "layers[0].index"),
    ("layer", "k", INF, "layers[0].index"),
    ("layer", "k", 1e30, "k ≤ 1000"),
    ("cauchy", "cauchy_a", NAN, "Cauchy"),
    ("cauchy", "cauchy_a", INF, "Cauchy A"),
    ("cauchy", "cauchy_b", NAN, "Cauchy"),
    ("cauchy", "cauchy_b", -10.0, "n > 0"),  # the Cauchy B that makes n negative
    ("cauchy", "cauchy_b", INF, "Cauchy"),
    ("cauchy", "cauchy_b", 1e30, "n ≤ 1000"),
    ("cauchy", "cauchy_c", NAN, "Cauchy"),
    ("cauchy", "cauchy_c", -5.0, "n > 0"),
    ("cauchy", "cauchy_c", INF, "Cauchy"),
    ("layer", "thickness_nm", NAN, "layers[0].thickness_nm"),
    ("layer", "thickness_nm", INF, "layers[0].thickness_nm"),
    ("layer", "thickness_nm", 1e30, "layers[0].thickness_nm"),
    ("layer", "thickness_nm", 200_000.0, "100 µm"),
    ("settings", "roughness", NAN, "roughness"),
    ("settings", "ambient_ior", NAN, "ambient"),
    ("settings", "ambient_ior", INF, "ambient"),
    ("settings", "substrate_ior", NAN, "substrate"),
    ("settings", "substrate_ior", INF, "substrate"),
    ("custom", "substrate_n", NAN, "substrate"),
    ("custom", "substrate_n", INF, "substrate"),
    ("custom", "substrate_k", NAN, "substrate"),
    ("custom", "substrate_k", INF, "substrate"),
    ("vary", "thickness_min_nm", NAN, "thickness_range_nm min"),
    ("vary", "thickness_max_nm", NAN, "thickness_range_nm max"),
    ("vary", "thickness_max_nm", INF, "thickness_range_nm max"),
    ("vary", "thickness_min_nm", 5000.0, "min < max"),  # min above the preset's max
    ("diffuse", "diffuse_color", (NAN, 0.0, 0.0), "base_color R"),
    ("diffuse", "diffuse_color", (0.0, NAN, 0.0), "base_color G"),  # Inf is clamped to 1
]


@pytest.mark.parametrize(
    ("target", "attribute", "value", "named"), SETTINGS, ids=[f"{a}={v}" for _, a, v, _ in SETTINGS]
)
def test_invalid_setting_is_named_and_never_baked(bpy, tf, fresh, no_bake, target, attribute, value, named):
    mat = film(bpy, "Hostile")
    _set(mat, target, attribute, value)
    with pytest.raises(ValueError) as info:
        tf.description.description(mat)
    message = str(info.value)
    assert "'Hostile'" in message and named in message, message
    notes = tf.description.warnings(mat)  # the panel's message path
    assert any(named in note and "magenta" in note for note in notes), notes
    assert no_bake.calls == 0


def test_too_many_layers_are_refused(bpy, tf, fresh, no_bake):
    mat = film(bpy, "Stack")
    for _ in range(tf.material.validate.MAX_LAYERS):  # one more than the limit with the preset's
        mat.thinfilm_sh.layers.add().thickness_nm = 100.0
    with pytest.raises(ValueError, match=r"'Stack'.*at most 128 layers"):
        tf.description.description(mat)
    assert no_bake.calls == 0


PRINCIPLED = [
    ("Thin Film Thickness", NAN),
    ("Thin Film IOR", NAN),
    ("Thin Film IOR", INF),
    ("IOR", NAN),
    ("Roughness", NAN),
    ("Metallic", NAN),
    ("Base Color", (NAN, 0.5, 0.5, 1.0)),
    ("Transmission Weight", NAN),
    ("Specular Tint", (NAN, 1.0, 1.0, 1.0)),
]


@pytest.mark.parametrize(("socket", "value"), PRINCIPLED, ids=[f"{s}={v}" for s, v in PRINCIPLED])
def test_invalid_principled_input_is_named(bpy, tf, fresh, no_bake, socket, value):
    mat = bpy.data.materials.new("Principled")
    node = next(n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    node.inputs["Thin Film Thickness"].default_value = 300.0
    if socket == "Specular Tint":
        node.inputs["Metallic"].default_value = 1.0
    node.inputs[socket].default_value = value
    with pytest.raises(ValueError) as info:
        tf.description.description(mat)
    assert "'Principled'" in str(info.value) and f"'{socket}'" in str(info.value), str(info.value)
    assert no_bake.calls == 0


# ----------------------------------------------------------------------------------------------
# The World: NaN/Inf values give the documented fallback lighting and an error naming them
# ----------------------------------------------------------------------------------------------
WORLDS = [
    # (input, value, viewport colour, what the error names, expected fallback radiance)
    ("Strength", NAN, (0.2, 0.1, 0.05), "Strength = nan", (0.2, 0.1, 0.05)),
    ("Strength", INF, (0.2, 0.1, 0.05), "Strength = 3.40282e+38", (0.2, 0.1, 0.05)),
    ("Strength", 1e30, (0.2, 0.1, 0.05), "Strength = 1e+30", (0.2, 0.1, 0.05)),
    ("Color", (NAN, 0.5, 0.5, 1.0), (0.2, 0.1, 0.05), "Color = nan", (0.2, 0.1, 0.05)),
    ("Color", (INF, 0.5, 0.5, 1.0), (0.2, 0.1, 0.05), "Color = 3.40282e+38", (0.2, 0.1, 0.05)),
    ("Strength", NAN, (NAN, 0.0, 0.0), "Viewport Display Color", (0.0509,) * 3),
    ("Strength", NAN, (0.0, 0.0, 0.0), "Strength = nan", (0.0509,) * 3),  # never black
]


@pytest.mark.parametrize(
    ("socket", "value", "viewport", "named", "fallback"), WORLDS, ids=[f"{w[1]}/{w[2]}" for w in WORLDS]
)
def test_invalid_world_falls_back_with_a_message(bpy, tf, fresh, socket, value, viewport, named, fallback):
    world = white_world(bpy, fresh)
    world.color = viewport
    world.node_tree.nodes["Background"].inputs[socket].default_value = value
    result = tf.world.world_sh(fresh, cache={})
    assert np.isfinite(result.coeffs).all()
    assert result.errors and named in result.errors[0] and "'White'" in result.errors[0], result.errors
    np.testing.assert_allclose(result.coeffs[0] / math.sqrt(4.0 * math.pi), fallback, rtol=1e-6)
    assert not np.any(result.coeffs[1:])


def _environment_world(bpy, scene, pixels):
    world = bpy.data.worlds.new("Sky")
    tree = world.node_tree
    env = tree.nodes.new("ShaderNodeTexEnvironment")
    h, w = pixels.shape[:2]
    image = bpy.data.images.new("sky", w, h, float_buffer=True)
    image.pixels.foreach_set(np.concatenate([pixels, np.ones((h, w, 1))], axis=-1).astype(np.float32).ravel())
    env.image = image
    tree.links.new(env.outputs["Color"], tree.nodes["Background"].inputs["Color"])
    scene.world = world
    return world


@pytest.mark.parametrize(
    "case", ["some NaN pixels", "all pixels NaN", "Inf pixels", "NaN strength", "1e30 pixels"]
)
def test_environment_image_with_bad_values(bpy, tf, fresh, case):
    pixels = np.full((16, 32, 3), 0.5)
    if case == "some NaN pixels":
        pixels[3:5, 4:9] = NAN
    elif case == "all pixels NaN":
        pixels[:] = NAN
    elif case == "Inf pixels":
        pixels[0, :, 1] = INF
    elif case == "1e30 pixels":  # finite, but the lighting would overflow float32 in the shader
        pixels[:] = 1e30
    world = _environment_world(bpy, fresh, pixels)
    if case == "NaN strength":
        world.node_tree.nodes["Background"].inputs["Strength"].default_value = NAN
    result = tf.world.world_sh(fresh, cache={})
    assert np.isfinite(result.coeffs).all()
    text = " ".join(result.warnings + result.errors)
    if case == "NaN strength":
        assert "Strength = nan" in text, text
    elif case == "1e30 pixels":
        assert "environment texture 'sky'" in text and "beyond 1e+20" in text, text
    else:  # kept from before: NaN/Inf pixels are left out and counted, with a message
        assert "NaN/Inf pixels left out" in text and not result.errors, text


# ----------------------------------------------------------------------------------------------
# Mesh data: thickness values that are not numbers
# ----------------------------------------------------------------------------------------------
def _grid(bpy, scene, name="Grid"):
    mesh = bpy.data.meshes.new(name)
    verts = [(x, y, 0.0) for y in range(3) for x in range(3)]
    faces = [(0, 1, 4, 3), (1, 2, 5, 4), (3, 4, 7, 6), (4, 5, 8, 7)]
    mesh.from_pydata(verts, [], faces)
    mesh.uv_layers.new(name="UVMap")
    obj = bpy.data.objects.new(name, mesh)
    scene.collection.objects.link(obj)
    return obj, mesh


THICKNESS = [
    # (source, domain, values (None: noise), error expected?, words)
    ("ATTRIBUTE", "POINT", [NAN] * 9, True, "no finite value"),
    ("ATTRIBUTE", "POINT", [INF] * 9, True, "no finite value"),
    ("ATTRIBUTE", "CORNER", [-INF] * 16, True, "no finite value"),
    ("ATTRIBUTE", "FACE", [NAN] * 4, True, "no finite value"),
    ("ATTRIBUTE", "POINT", [NAN, 0.2, 0.3, NAN, 0.5, 0.6, 0.7, 0.8, 0.9], False, "3 of 16"),
    ("ATTRIBUTE", "FACE", [0.1, INF, 0.3, 0.4], False, "4 of 16"),
    ("NOISE", None, NAN, True, "noise scale"),
    ("NOISE", None, INF, True, "noise scale"),  # Blender stores 3.4e38
    ("IMAGE", None, "all", True, "no finite value"),
    ("IMAGE", None, "some", False, "of 16"),
]


@pytest.mark.parametrize(
    ("source", "domain", "values", "raises", "words"),
    THICKNESS,
    ids=[f"{t[0]}-{t[1]}-{i}" for i, t in enumerate(THICKNESS)],
)
def test_thickness_that_is_not_a_number(bpy, tf, fresh, source, domain, values, raises, words):
    obj, mesh = _grid(bpy, fresh)
    mat = film(bpy, "Varying")
    s = mat.thinfilm_sh
    s.vary_thickness, s.thickness_source = True, source
    if source == "ATTRIBUTE":
        attribute = mesh.attributes.new("thickness", "FLOAT", domain)
        attribute.data.foreach_set("value", np.asarray(values, dtype=np.float32))
        s.thickness_attribute = "thickness"
    elif source == "NOISE":
        s.noise_scale = values
    else:
        pixels = np.full((8, 8, 4), 0.5, dtype=np.float32)
        pixels[..., 0] = NAN if values == "all" else pixels[..., 0]
        if values == "some":
            pixels[0:2, 0:2, 0] = NAN  # the corners at UV (0, 0) sample these
            mesh.uv_layers["UVMap"].data.foreach_set("uv", np.zeros(32, dtype=np.float32))
            mesh.uv_layers["UVMap"].data[0].uv = (0.5, 0.5)
            for i in range(1, 16):
                mesh.uv_layers["UVMap"].data[i].uv = (0.5, 0.5) if i % 8 else (0.0, 0.0)
        image = bpy.data.images.new("thickness", 8, 8, float_buffer=True)
        image.pixels.foreach_set(pixels.ravel())
        s.thickness_image = image
    notes = []
    if raises:
        with pytest.raises(ValueError, match=words):
            tf.thickness.thickness_per_vertex(obj, mesh, s, notes=notes)
        return
    values = tf.thickness.thickness_per_vertex(obj, mesh, s, notes=notes)
    assert np.isfinite(values).all() and values.min() >= 0.0 and values.max() <= 1.0
    assert notes and words in notes[0] and "middle of the thickness range" in notes[0], notes


# ----------------------------------------------------------------------------------------------
# The headless commands: bad paths and sizes are refused before any work (exit 2)
# ----------------------------------------------------------------------------------------------
def _scene_with_a_film(bpy, scene):
    white_world(bpy, scene)
    sphere(bpy, scene, material=film(bpy, "Film"))
    camera(bpy, scene)


def _plant(kind: str, tmp_path: Path) -> Path | str:
    """A path that must be refused; ``tmp_path`` holds whatever it needs."""
    if kind == "dir":
        path = tmp_path / "out.png"
        path.mkdir()
    elif kind == "exr-dir":  # --out x.png with a directory where x.exr goes
        (tmp_path / "out.exr").mkdir()
        path = tmp_path / "out.png"
    elif kind == "fifo":
        path = tmp_path / "out.png"
        os.mkfifo(path)
    elif kind == "symlink":
        (tmp_path / "real.png").write_bytes(b"the user's file")
        path = tmp_path / "out.png"
        path.symlink_to(tmp_path / "real.png")
    elif kind == "device":
        path = Path("/dev/full")
    elif kind == "unwritable":
        path = Path("/proc/self/no-such-folder/out.png")
    elif kind == "parent-is-file":
        (tmp_path / "notes.txt").write_text("the user's notes")
        path = tmp_path / "notes.txt" / "out.png"
    elif kind == "trailing-slash":
        path = str(tmp_path / "folder") + "/"  # a str: Path would drop the slash
    else:
        raise AssertionError(kind)
    return path


def _snapshot(tmp_path: Path) -> dict:
    return {
        p.relative_to(tmp_path).as_posix(): (p.lstat().st_mode, p.read_bytes() if p.is_file() else None)
        for p in sorted(tmp_path.rglob("*"))
        if not p.is_fifo()
    }


PATH_KINDS = ["dir", "exr-dir", "fifo", "symlink", "device", "unwritable", "parent-is-file", "trailing-slash"]
PATH_WORDS = {
    "dir": "directory",
    "exr-dir": ".exr",
    "fifo": "FIFO",
    "symlink": "symbolic link",
    "device": "character device",
    "unwritable": "cannot",
    "parent-is-file": "not a folder",
    "trailing-slash": "folder",
}


@pytest.mark.parametrize("kind", PATH_KINDS)
def test_render_out_is_refused_before_work(bpy, tf, fresh, no_work, tmp_path, capsys, kind):
    _scene_with_a_film(bpy, fresh)
    path = _plant(kind, tmp_path)
    before = _snapshot(tmp_path)
    code = tf.headless.main(["render", "--out", str(path)])
    err = capsys.readouterr().err
    assert code == 2, err
    assert "--out" in err and PATH_WORDS[kind] in err and "Traceback" not in err, err
    assert len(err.strip().splitlines()) == 1
    assert no_work.render.calls == 0 and no_work.bake.calls == 0
    assert _snapshot(tmp_path) == before


@pytest.mark.parametrize("kind", ["dir", "fifo", "symlink", "device", "unwritable"])
@pytest.mark.parametrize("command", ["bake", "render"])
def test_json_summary_path_is_refused_before_work(bpy, tf, fresh, no_work, tmp_path, capsys, command, kind):
    _scene_with_a_film(bpy, fresh)
    path = _plant(kind, tmp_path)
    before = _snapshot(tmp_path)
    extra = ["--out", str(tmp_path / "ok.png")] if command == "render" else []
    code = tf.headless.main([command, *extra, "--json", str(path)])
    err = capsys.readouterr().err
    assert code == 2 and "--json" in err and PATH_WORDS[kind] in err, err
    assert no_work.render.calls == 0 and no_work.bake.calls == 0
    assert _snapshot(tmp_path) == before


SIZES = [
    (["--width", "0"], "--width"),
    (["--width", "-5"], "--width"),
    (["--width", "16385"], "--width"),
    (["--height", "100000"], "--height"),
    (["--width", "abc"], "--width"),
    (["--height", "nan"], "--height"),
    (["--width", "1e3"], "--width"),
    (["--supersample", "0"], "--supersample"),
    (["--supersample", "17"], "--supersample"),
    (["--supersample", "nan"], "--supersample"),
]


@pytest.mark.parametrize(("args", "option"), SIZES, ids=[" ".join(a) for a, _ in SIZES])
def test_render_size_out_of_range_is_refused(bpy, tf, fresh, no_work, tmp_path, capsys, args, option):
    _scene_with_a_film(bpy, fresh)
    code = tf.headless.main(["render", "--out", str(tmp_path / "x.png"), *args])
    err = capsys.readouterr().err
    assert code == 2 and option in err and "Traceback" not in err, err
    assert no_work.render.calls == 0 and not any(tmp_path.iterdir())


@pytest.mark.parametrize("case", ["huge resolution", "zero percentage", "NaN exposure", "no camera"])
def test_render_scene_values_are_refused(bpy, tf, fresh, no_work, tmp_path, capsys, case):
    _scene_with_a_film(bpy, fresh)
    words = {"huge resolution": "resolution", "zero percentage": "resolution"}.get(case, case.split()[-1])
    if case == "huge resolution":
        fresh.render.resolution_x, fresh.render.resolution_percentage = 65536, 32767  # Blender's maxima
    elif case == "zero percentage":
        fresh.render.resolution_percentage = 1
        fresh.render.resolution_x = 4  # 4 × 1 % rounds to 0 pixels
    elif case == "NaN exposure":
        fresh.view_settings.exposure = NAN
    else:
        fresh.camera = None
    code = tf.headless.main(["render", "--out", str(tmp_path / "x.png")])
    err = capsys.readouterr().err
    assert code == 2 and words in err, err
    assert no_work.render.calls == 0 and not any(tmp_path.iterdir())


@pytest.mark.parametrize("kind", ["file", "symlink", "unwritable", "fifo at a table", "dir at a table"])
def test_bake_out_dir_is_refused_before_baking(bpy, tf, fresh, no_work, tmp_path, capsys, kind):
    _scene_with_a_film(bpy, fresh)
    out = tmp_path / "tables"
    if kind == "file":
        out.write_text("the user's file")
    elif kind == "symlink":
        (tmp_path / "real").mkdir()
        out.symlink_to(tmp_path / "real")
    elif kind == "unwritable":
        out = Path("/proc/self/tables")
    else:
        out.mkdir()
        if kind == "fifo at a table":
            os.mkfifo(out / "Film.exr")
        else:
            (out / "Film.exr").mkdir()
    before = _snapshot(tmp_path)
    code = tf.headless.main(["bake", "--out-dir", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and "--out-dir" in err and "Traceback" not in err, err
    assert no_work.bake.calls == 0 and _snapshot(tmp_path) == before


# ----------------------------------------------------------------------------------------------
# Whole commands: failure isolation, the fallbacks, unique names, exit codes
# ----------------------------------------------------------------------------------------------
def test_one_invalid_material_renders_the_other_unchanged(bpy, tf, fresh, tmp_path, capsys):
    """The issue's acceptance: the valid films are drawn exactly as in the scene without the
    invalid one, the invalid one in the magenta fallback, reported, exit 1 ("partial").

    The middle sphere is a valid film whose thickness attribute is all NaN (the issue's 226 black
    pixels): it is drawn at the middle of the thickness range, with a message, in both scenes.
    One scene, two renders: the World is analysed once (~20 s of the prefilter on llvmpipe).
    """
    scene = fresh
    white_world(bpy, scene)
    good = film(bpy, "Good", thickness_nm=420.0)
    bad = film(bpy, "Bad", thickness_nm=420.0)
    bad.thinfilm_sh.layers[0].index_mode = "CAUCHY"
    bad.thinfilm_sh.layers[0].cauchy_b = -10.0  # n < 0: the case that aborted the render
    varying = film(bpy, "Varying")
    s = varying.thinfilm_sh
    s.vary_thickness, s.thickness_source, s.thickness_attribute = True, "ATTRIBUTE", "thickness"
    s.thickness_min_nm, s.thickness_max_nm = 0.0, 1000.0  # 0 nm is black: where NaN used to go
    sphere(bpy, scene, "Left", (-1.9, 0.0, 0.0), radius=0.7, material=good)
    middle = sphere(bpy, scene, "Middle", (0.0, 0.0, 0.0), radius=0.7, material=varying)
    values = np.full(len(middle.data.vertices), NAN, dtype=np.float32)
    middle.data.attributes.new("thickness", "FLOAT", "POINT").data.foreach_set("value", values)
    sphere(bpy, scene, "Right", (1.9, 0.0, 0.0), radius=0.7, material=bad)
    camera(bpy, scene)
    summary_path = tmp_path / "render.json"
    # One sample per pixel: the anti-aliasing filter would blend the magenta edge into the World,
    # and the colour test below is for the fallback's own pixels.
    one = ["--supersample", "1", "--engine", "SOLID"]  # the preview's drawing: the fallbacks' own pixels
    code = tf.headless.main(
        ["render", "--out", str(tmp_path / "both.png"), "--json", str(summary_path), *one]
    )
    captured = capsys.readouterr()
    assert code == 1, captured.out + captured.err
    assert "'Bad'" in captured.err and "Cauchy" in captured.err
    summary = json.loads(summary_path.read_text())
    assert summary["objects"] == ["Left/Good", "Middle/Varying"], summary["objects"]
    assert summary["fallback_objects"] == ["Right/Bad"]
    assert set(summary["errors"]) == {"Bad"} and "n > 0" in summary["errors"]["Bad"]
    thickness_notes = [m for m in summary["messages"] if "'thickness'" in m]
    assert thickness_notes and "no finite value" in thickness_notes[0] and "middle" in thickness_notes[0]
    both = read_exr(tmp_path / "both.exr")

    bpy.data.objects.remove(bpy.data.objects["Right"])
    assert tf.headless.main(["render", "--out", str(tmp_path / "alone.png"), *one]) == 0
    alone = read_exr(tmp_path / "alone.exr")
    assert np.isfinite(both).all() and np.isfinite(alone).all()
    differ = np.any(both != alone, axis=-1)
    valid_part = np.zeros(differ.shape, dtype=bool)
    valid_part[:, : 2 * SIZE[0] // 3] = True
    assert not differ[valid_part].any(), "a valid film changed"
    magenta = both[differ]
    assert differ.sum() > 50 and np.all(magenta[:, 1] < 0.25 * np.minimum(magenta[:, 0], magenta[:, 2]))
    centre = both[SIZE[1] // 2 - 3 : SIZE[1] // 2 + 3, SIZE[0] // 2 - 3 : SIZE[0] // 2 + 3]
    assert centre.max(axis=-1).min() > 1e-3, "the NaN-thickness film has no black pixels"


def test_nan_world_strength_renders_with_the_fallback_lighting(bpy, tf, fresh, tmp_path, capsys):
    scene = fresh
    world = white_world(bpy, scene)
    world.color = (0.2, 0.1, 0.05)  # the documented fallback: the World's viewport colour
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = NAN
    sphere(bpy, scene, material=film(bpy, "Film", roughness=0.5))
    camera(bpy, scene)
    argv = [
        "render",
        "--out",
        str(tmp_path / "nan.png"),
        "--json",
        str(tmp_path / "r.json"),
        "--engine",
        "SOLID",
    ]
    code = tf.headless.main(argv)
    err = capsys.readouterr().err
    assert code == 1 and "Strength = nan" in err and "viewport color" in err, err
    image = read_exr(tmp_path / "nan.exr")
    assert np.isfinite(image).all()
    np.testing.assert_allclose(image[0, 0], (0.2, 0.1, 0.05), rtol=1e-3)  # background: the fallback
    centre = image[SIZE[1] // 2, SIZE[0] // 2]
    assert centre.max() > 1e-3, "the film is lit by the fallback, not black"
    summary = json.loads((tmp_path / "r.json").read_text())
    assert summary["world_errors"] and summary["objects"] == ["Sphere/Film"]


def test_bake_gives_every_material_its_own_file_and_a_manifest(bpy, tf, fresh, tmp_path, capsys):
    scene = fresh
    white_world(bpy, scene)
    names = ["Mat 001", "Mat.001", "Mat_001", "mat_001"]
    for i, name in enumerate(names):
        sphere(bpy, scene, f"S{i}", (2.0 * i, 0.0, 0.0), radius=0.5, material=film(bpy, name))
    out = tmp_path / "tables"
    code = tf.headless.main(["bake", "--out-dir", str(out), "--json", str(tmp_path / "bake.json")])
    assert code == 0, capsys.readouterr().err
    summary = json.loads((tmp_path / "bake.json").read_text())
    manifest = summary["manifest"]
    assert set(manifest) == set(names)
    assert len({Path(p).name.casefold() for p in manifest.values()}) == 4
    assert Path(manifest["Mat_001"]).name == "Mat_001.exr"
    assert sorted(p.name for p in out.iterdir()) == sorted(Path(p).name for p in manifest.values())
    again = tf.headless.bake_scene(scene, out)  # stable: the same names on every run
    assert again["manifest"] == manifest


def test_bake_with_one_invalid_material_bakes_the_others(bpy, tf, fresh, tmp_path, capsys):
    scene = fresh
    white_world(bpy, scene)
    bad = film(bpy, "Bad")
    bad.thinfilm_sh.layers[0].n = INF
    sphere(bpy, scene, "A", material=film(bpy, "Good"))
    sphere(bpy, scene, "B", (2.0, 0.0, 0.0), material=bad)
    code = tf.headless.main(["bake", "--out-dir", str(tmp_path / "t"), "--json", str(tmp_path / "b.json")])
    err = capsys.readouterr().err
    assert code == 1 and "'Bad'" in err and "n ≤ 1000" in err, err
    summary = json.loads((tmp_path / "b.json").read_text())
    assert set(summary["materials"]) == {"Good"} and set(summary["errors"]) == {"Bad"}
    assert set(summary["manifest"]) == {"Good"} and Path(summary["manifest"]["Good"]).is_file()


def test_a_failing_bake_is_isolated_and_an_internal_error_is_one_line(bpy, tf, fresh, monkeypatch, capsys):
    _scene_with_a_film(bpy, fresh)

    def broken(*args, **kwargs):
        raise RuntimeError("simulated bug")

    monkeypatch.setattr(tf.tables, "get_table_with_source", broken)
    assert tf.headless.main(["bake"]) == 1  # the material failed; the command itself finished
    err = capsys.readouterr().err
    assert "'Film'" in err and "simulated bug" in err and "Traceback" not in err, err
    log = Path(err.rsplit("details in ", 1)[1].split(")")[0])
    assert "RuntimeError: simulated bug" in log.read_text()
    log.unlink()
    monkeypatch.setattr(tf.headless, "scene_materials", broken)
    assert tf.headless.main(["plan"]) == 3
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "internal error" in err and "Traceback" not in err, err
    log = Path(err.rsplit("details in ", 1)[1].rstrip(")\n"))
    assert "RuntimeError: simulated bug" in log.read_text() and "Traceback" in log.read_text()
    log.unlink()


@pytest.mark.parametrize("content", [b"", b"not a blend file", b"BLENDER-v502" + bytes(64)])
def test_script_refuses_a_broken_blend_file(bpy, tf, fresh, tmp_path, capsys, content):
    spec = importlib.util.spec_from_file_location("thinfilm_headless_script", SCRIPT)
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    broken = tmp_path / "broken.blend"
    broken.write_bytes(content)
    assert script.main([str(broken), "plan"]) == 2
    err = capsys.readouterr().err
    assert "broken.blend" in err and "Traceback" not in err and err.count("\n") == 1, err
    set_cache_preference(bpy, tf.prefs, tf.cache_dir)
