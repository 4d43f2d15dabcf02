"""Headless bake / render / plan in a real bpy session: the CLI, physics, failure modes, lifecycle.

The repository is imported as the extension package ``thinfilm_sh`` (a symlink, as in
test_extension.py) and registered once for the module, with its table cache in a private folder
(the add-on preferences' Cache Directory). Each test starts from an empty factory file
(``read_homefile``, which keeps the preferences) and builds the little scene it needs; renders
are small (64×48 or so) and mostly leave the World background out (the World still lights the
films), so the module stays well under three minutes on llvmpipe.

Run the figures out loud with ``-s``: the hue table of the interference test is printed.
"""

from __future__ import annotations

import colorsys
import importlib
import importlib.util
import json
import math
import os
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.blender

from _blender_scene import camera, cube, read_exr, sphere, white_world  # noqa: E402
from _extension import EXTENSION_ID, REPO, gpu_layer, linked_extension, set_cache_preference  # noqa: E402

from precompute.materials.material import MAX_SH_ORDER  # noqa: E402

SCRIPT = REPO / "scripts" / "thinfilm_headless.py"
SIZE = (64, 48)
#: The roughness of the films in the tests of the command line, of messages and of the frame,
#: which are not about the shading path: above the SH/split-sum hand-over (policy.SH_BLEND,
#: 0.2–0.45) the film reads the SH alone, from a grid built in under a second. In the hand-over
#: a headless frame first integrates the film's exact lobe against the World (lobe_grid.build:
#: 15–100 s of numpy per film, 30–60 s here); the physics tests below render there on purpose.
PLAIN_ROUGHNESS = 0.5


# ----------------------------------------------------------------------------------------------
# Fixtures and helpers
# ----------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def tf(bpy, tmp_path_factory):
    """The extension, registered once for the module; its modules as attributes."""
    root = tmp_path_factory.mktemp("extension")
    with linked_extension(root) as package:
        try:
            package.register()
            ns = types.SimpleNamespace(package=package, cache_dir=root / "cache")
            ns.addon = importlib.import_module(f"{EXTENSION_ID}.addon")
            for dotted in (
                "addon.headless.headless",
                "addon.headless.render",
                "addon.materials.description",
                "addon.bakes.tables",
                "addon.ui.prefs",
                "addon.drawing.scene_draw",
                "addon.world.world_state",
            ):
                setattr(ns, dotted.rpartition(".")[2], importlib.import_module(f"{EXTENSION_ID}.{dotted}"))
            ns.gpu = gpu_layer()
            ns.table_io = importlib.import_module(f"{EXTENSION_ID}.precompute.tables.table_io")
            set_cache_preference(bpy, ns.prefs, ns.cache_dir)
            ns.gpu.context.ensure_gpu_context()
            yield ns
        finally:
            entry = bpy.context.preferences.addons.get(EXTENSION_ID)
            if entry is not None:
                bpy.context.preferences.addons.remove(entry)


@pytest.fixture
def fresh(bpy, tf):
    """An empty factory file with the extension registered and its private cache chosen."""
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    tf.package.register()  # harmless when already registered
    set_cache_preference(bpy, tf.prefs, tf.cache_dir)
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = SIZE
    scene.render.resolution_percentage = 100
    scene.view_settings.view_transform = "Standard"
    return scene


def studiolight(name: str) -> Path:
    from precompute.commands.cli import studiolight as find

    return find(name)


def hdri_world(bpy, scene, path, name="HDRI"):
    world = bpy.data.worlds.new(name)
    tree = world.node_tree
    env = tree.nodes.new("ShaderNodeTexEnvironment")
    if Path(path).is_file():
        env.image = bpy.data.images.load(str(path), check_existing=True)
    else:  # how a file whose HDRI was moved away looks: an image datablock pointing nowhere
        image = bpy.data.images.new(Path(path).name, 4, 4, float_buffer=True)
        image.source = "FILE"
        image.filepath = str(path)
        env.image = image
    tree.links.new(env.outputs["Color"], tree.nodes["Background"].inputs["Color"])
    scene.world = world
    return world


def film(
    bpy,
    name,
    thickness_nm=None,
    roughness=None,
    preset="SOAP_FILM",
    vary=False,
    substrate=None,
    transparency="OPAQUE",
):
    """A material previewed by the extension (``preset`` first, then the overrides); opaque unless
    ``transparency`` says otherwise (these tests check the film's reflection)."""
    mat = bpy.data.materials.new(name)
    s = mat.thinfilm_sh
    s.preset = preset
    s.enabled = True
    s.transparency = transparency
    s.vary_thickness = vary
    if thickness_nm is not None:
        s.layers[0].thickness_nm = thickness_nm
    if roughness is not None:
        s.roughness = roughness
    if substrate is not None:
        s.substrate_mode = "DIELECTRIC"
        s.substrate_ior = substrate
    return mat


def render(tf, scene, path, size=SIZE, background=False, supersample=None):
    result = tf.render.render_scene(
        scene, str(path), size[0], size[1], background=background, supersample=supersample
    )
    assert Path(result["png"]).is_file() and Path(result["exr"]).is_file(), (
        f"render wrote no PNG/EXR: {result}"
    )
    image = read_exr(result["exr"])
    assert image.shape == (size[1], size[0], 3), f"EXR of {image.shape[1]}×{image.shape[0]}, asked for {size}"
    assert np.isfinite(image).all(), f"non-finite values in the EXR ({result['messages']})"
    return image, result


def saturation(rgb) -> np.ndarray:
    rgb = np.asarray(rgb, dtype=np.float64)
    hi, lo = rgb.max(axis=-1), rgb.min(axis=-1)
    return np.where(hi > 1e-6, (hi - lo) / np.maximum(hi, 1e-12), 0.0)


def hue_deg(rgb) -> float:
    rgb = np.maximum(np.asarray(rgb, dtype=np.float64), 0.0)
    return colorsys.rgb_to_hsv(*(rgb / max(rgb.max(), 1e-12)))[0] * 360.0


def hue_distance(a: float, b: float) -> float:
    return abs((a - b + 180.0) % 360.0 - 180.0)


def project(tf, scene, points, size):
    """Pixel coordinates (x right, y down; pixel centres at +0.5) of world points in the camera."""
    import bpy

    view, proj = tf.render.camera_matrices(scene, bpy.context.evaluated_depsgraph_get(), *size)
    p = np.c_[np.asarray(points, dtype=np.float64), np.ones(len(points))] @ (proj @ view).T
    ndc = p[:, :3] / p[:, 3:4]
    return np.c_[(ndc[:, 0] + 1.0) * 0.5 * size[0], (1.0 - (ndc[:, 1] + 1.0) * 0.5) * size[1]]


# ----------------------------------------------------------------------------------------------
# The command line
# ----------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def cli_blend(bpy, tf, tmp_path_factory):
    """A saved file: two spheres whose materials have equal settings, an HDRI World, a camera."""
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    set_cache_preference(bpy, tf.prefs, tf.cache_dir)
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = SIZE
    scene.render.resolution_percentage = 100
    a = film(bpy, "Film A", thickness_nm=420.0, roughness=PLAIN_ROUGHNESS)
    b = film(bpy, "Film B", thickness_nm=420.0, roughness=PLAIN_ROUGHNESS)
    sphere(bpy, scene, "Left", (-1.1, 0.0, 0.0), material=a)
    sphere(bpy, scene, "Right", (1.1, 0.0, 0.0), material=b)
    camera(bpy, scene, distance=7.0)
    hdri_world(bpy, scene, studiolight("courtyard"))
    path = tmp_path_factory.mktemp("cli") / "two_films.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path), check_existing=False)
    return path


def _open(bpy, tf, path):
    bpy.ops.wm.open_mainfile(filepath=str(path))
    set_cache_preference(bpy, tf.prefs, tf.cache_dir)
    return bpy.context.scene


def test_cli_command_is_registered_with_blender(bpy, tf, capfd):
    assert tf.headless._cli_handle is not None
    capfd.readouterr()
    # A second command with our id makes Blender warn about a duplicate: ours is registered.
    probe = bpy.utils.register_cli_command(EXTENSION_ID, lambda argv: 0)
    try:
        out = capfd.readouterr()
    finally:
        bpy.utils.unregister_cli_command(probe)
    assert f'duplicate command "{EXTENSION_ID}"' in out.out + out.err


def test_cli_render_writes_png_and_exr(bpy, tf, cli_blend, tmp_path, capsys):
    _open(bpy, tf, cli_blend)
    out = tmp_path / "render.png"
    code = tf.headless._cli(
        ["render", "--out", str(out), "--width", "64", "--height", "48", "--engine", "SOLID"]
    )
    printed = capsys.readouterr().out
    assert code == 0, printed
    assert out.is_file() and out.with_suffix(".exr").is_file()
    assert "wrote" in printed and "2 thin-film objects" in printed
    from PIL import Image

    with Image.open(out) as png:
        assert png.size == (64, 48) and png.mode == "RGBA"  # with alpha (issue 19)
    image = read_exr(out.with_suffix(".exr"))
    assert image.shape == (48, 64, 3)
    assert np.isfinite(image).all()
    assert image.max() > 0.05  # the courtyard background and the films are there


def _json_objects(text: str) -> list:
    decoder, objects, i = json.JSONDecoder(), [], 0
    while True:
        start = text.find("{", i)
        if start < 0:
            return objects
        obj, i = decoder.raw_decode(text, start)
        objects.append(obj)


def test_cli_bake_shares_one_table_between_equal_materials(bpy, tf, cli_blend, tmp_path, capsys):
    _open(bpy, tf, cli_blend)
    summary_path = tmp_path / "bake.json"
    code = tf.headless.main(["bake", "--json", str(summary_path), "--out-dir", str(tmp_path / "tables")])
    assert code == 0, capsys.readouterr().out
    summary = json.loads(summary_path.read_text())
    entries = summary["materials"]
    assert set(entries) == {"Film A", "Film B"} and summary["errors"] == {}
    assert entries["Film A"]["key"] == entries["Film B"]["key"]
    assert entries["Film A"]["shared_with"] is None
    assert entries["Film B"]["shared_with"] == "Film A"
    assert entries["Film B"]["source"] == "memory"  # the same table, not a second bake
    for entry in entries.values():
        assert Path(entry["file"]).is_file()


def test_cli_cache_dir_is_used_and_an_unsafe_one_is_a_clear_error(bpy, tf, cli_blend, tmp_path, capsys):
    """Issue 24: ``--cache-dir`` names the cache on every command; an unsafe folder (a symbolic
    link) is an ``error:`` line for ``bake`` (exit 2) and a note for ``plan``, never a traceback."""
    _open(bpy, tf, cli_blend)
    tf.tables.clear_memory_cache()
    chosen = tmp_path / "flag cache"
    assert tf.headless.main(["bake", "--cache-dir", str(chosen)]) == 0
    out = (lambda c: c.out + c.err)(capsys.readouterr())
    assert "Film A: bake" in out, out  # not read from the preference's cache, which may hold it
    stored = sorted(p.name for p in (chosen / "thinfilm_sh_tables").glob("*.exr"))
    assert len(stored) == 1  # the two equal materials share one table

    link = tmp_path / "link"
    link.symlink_to(chosen, target_is_directory=True)
    tf.tables.clear_memory_cache()
    assert tf.headless.main(["bake", "--cache-dir", str(link)]) == 2
    out = (lambda c: c.out + c.err)(capsys.readouterr())
    assert "error:" in out and "symbolic link" in out and "Traceback" not in out
    assert tf.headless.main(["plan", "--cache-dir", str(link)]) == 0
    out = (lambda c: c.out + c.err)(capsys.readouterr())
    assert "note:" in out and "symbolic link" in out and "plan-json" in out


def test_cli_bake_json_summary_is_a_verified_write(bpy, tf, cli_blend, tmp_path, capsys):
    """The summary is written like every other output: a FIFO or a symbolic link at ``--json``
    is refused with a clear error, exit 2."""
    _open(bpy, tf, cli_blend)
    target = tmp_path / "elsewhere.json"
    target.write_text("keep")
    link = tmp_path / "summary.json"
    link.symlink_to(target)
    assert tf.headless.main(["bake", "--json", str(link)]) == 2
    out = (lambda c: c.out + c.err)(capsys.readouterr())
    assert "error:" in out and "summary.json" in out and "Traceback" not in out
    assert target.read_text() == "keep" and link.is_symlink()
    fifo = tmp_path / "pipe.json"
    os.mkfifo(fifo)
    assert tf.headless.main(["bake", "--json", str(fifo)]) == 2
    assert "error:" in (lambda c: c.out + c.err)(capsys.readouterr())


def test_cli_plan_prints_a_plan(bpy, tf, cli_blend, capsys):
    _open(bpy, tf, cli_blend)
    assert tf.headless.main(["plan"]) == 0
    plans = _json_objects(capsys.readouterr().out)
    assert {p["material"] for p in plans} == {"Film A", "Film B"}
    for p in plans:
        assert 0 <= p["sh_order"] <= MAX_SH_ORDER and p["view_samples"] >= 2 and p["wavelengths"] >= 3
        assert p["reasons"], "the plan gives its reasons"


def test_cli_bad_arguments_exit_nonzero(tf, capsys):
    assert tf.headless.main(["render"]) == 2  # --out is required: argparse's refusal, no SystemExit
    assert "--out" in capsys.readouterr().err


def test_script_renders_a_file_in_a_subprocess(cli_blend, tmp_path):
    out = tmp_path / "script.png"
    cmd = [
        sys.executable,
        str(SCRIPT),
        str(cli_blend),
        "render",
        "--out",
        str(out),
        "--width",
        "48",
        "--height",
        "36",
        "--no-background",
        "--engine",
        "SOLID",  # EEVEE's first render compiles its shaders for minutes on llvmpipe
    ]
    cache = tmp_path / "env cache"  # THINFILM_SH_CACHE is honoured inside Blender too (issue 24)
    env = {**os.environ, "THINFILM_SH_CACHE": str(cache)}
    proc = subprocess.run(
        cmd, capture_output=True, text=True, timeout=300, cwd=tmp_path, check=False, env=env
    )
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert out.is_file() and out.with_suffix(".exr").is_file()
    tables = sorted(p.name for p in (cache / "thinfilm_sh_tables").glob("*.exr"))
    # both films share one table, and their EEVEE path (synced when the file loads, issue 33)
    # one more: its film is the glossy lobe alone (addon/eevee/source.py)
    assert len(tables) == 2, f"tables written to the THINFILM_SH_CACHE folder: {tables}"
    image = read_exr(out.with_suffix(".exr"))
    assert image.shape == (36, 48, 3) and np.isfinite(image).all() and image.max() > 0.0

    missing = subprocess.run(
        [sys.executable, str(SCRIPT), str(tmp_path / "nope.blend"), "plan"],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert missing.returncode == 2 and "nope.blend" in missing.stderr


def _script_module():
    spec = importlib.util.spec_from_file_location("thinfilm_headless_script", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_script_batch_renders_every_file_in_a_folder(bpy, tf, cli_blend, tmp_path, capsys):
    """``--all-scenes DIR --out-dir OUT``, in this process (the subprocess path is tested above)."""
    script = _script_module()
    folder = tmp_path / "scenes"
    folder.mkdir()
    (folder / "a.blend").write_bytes(cli_blend.read_bytes())
    (folder / "broken.blend").write_bytes(b"not a blend file")
    code = script.main(
        [
            "--all-scenes",
            str(folder),
            "--out-dir",
            str(tmp_path / "out"),
            "--width",
            "32",
            "--height",
            "24",
            "--no-background",
            "--engine",
            "SOLID",  # the batch is tested, not EEVEE (test_frame.py): its first frame compiles for minutes
        ]
    )
    printed = capsys.readouterr()
    assert code == 1, "a broken file fails the batch"
    assert "rendered 1/2 files" in printed.out and "broken.blend" in printed.out
    image = read_exr(tmp_path / "out" / "a.exr")
    assert image.shape == (24, 32, 3) and np.isfinite(image).all()
    set_cache_preference(bpy, tf.prefs, tf.cache_dir)


# ----------------------------------------------------------------------------------------------
# Physics
# ----------------------------------------------------------------------------------------------
#: Film index and thicknesses of the interference test (soap film: water in air on both sides).
#: Each thickness is a frame with its own integrated lobe grid (30–60 s): the fast set renders
#: 130 nm and the 200 nm "sensitive tint" (5°/nm), the full set (``slow``) all four.
SOAP_N = 1.33
HUE_THICKNESSES_NM = (
    130.0,
    pytest.param(160.0, marks=pytest.mark.slow),
    200.0,
    pytest.param(250.0, marks=pytest.mark.slow),
)
#: The rendered hue must be the normal-incidence hue of a film between (1 − 3 %)·d and
#: (1 + 0.5 %)·d. Why: at roughness 0.35 (α = 0.1225) the GGX lobe around the normal mixes
#: in microfacets tilted by ~5–20°, whose light crosses the film at cos θt = √(1 − sin²θ/n²)
#: ≈ 0.99–0.98: the optical path is 1–2 % shorter, so the colour is that of a slightly thinner
#: film (measured: 1.2–1.4 % at all four thicknesses; at roughness 0.05 it is < 0.3 %). The
#: +0.5 % side allows for the table's thickness and angle interpolation only. In hue degrees
#: that is 3–20° depending on the thickness (the magenta of 200 nm is the "sensitive tint",
#: 5°/nm), which is why the tolerance is stated in thickness.
THICKNESS_TOLERANCE = (-0.03, 0.005)


def _normal_incidence_rgb(thickness_nm, n_film=SOAP_N, substrate=1.0):
    from precompute.colour import rgb_spaces, spectra
    from precompute.optics import reflectance

    wl = spectra.wavelength_grid(471)  # 1 nm bins over 360–830 nm
    r = reflectance([1.0, n_film, substrate], [thickness_nm], wl, [1.0])[0]
    return rgb_spaces.xyz_to_rgb_matrix("Linear Rec.709") @ spectra.spectrum_to_xyz(r, wl), r, wl


def test_reference_spectrum_peaks_at_the_first_order_condition():
    """The exact optics behind the expected hues: a free film reflects most at 2nd = (m + ½)λ."""
    for d in (100.0, 130.0):
        _, r, wl = _normal_incidence_rgb(d)
        expected = 4.0 * SOAP_N * d  # m = 0
        assert abs(wl[np.argmax(r)] - expected) <= 1.0, (d, wl[np.argmax(r)], expected)


@pytest.mark.parametrize("d", HUE_THICKNESSES_NM)
def test_soap_film_hue_follows_thin_film_interference(bpy, tf, fresh, tmp_path, d):
    """The sphere's centre has the hue of a free soap film of thickness ``d`` at normal incidence
    (exact optics, 1 nm bins), within THICKNESS_TOLERANCE stated as an equivalent thickness."""
    scene = fresh
    white_world(bpy, scene)
    mat = film(bpy, "Soap", thickness_nm=d, roughness=0.35)
    sphere(bpy, scene, material=mat)
    camera(bpy, scene, distance=5.0)
    image, result = render(tf, scene, tmp_path / f"hue_{d:g}.png")
    assert result["objects"] == ["Sphere/Soap"], result["messages"]
    h, w = image.shape[:2]
    centre = image[h // 2 - 2 : h // 2 + 2, w // 2 - 2 : w // 2 + 2].reshape(-1, 3).mean(axis=0)
    expected_hue = hue_deg(_normal_incidence_rgb(d)[0])
    got = hue_deg(centre)
    # The thickness whose normal-incidence colour has the rendered hue (hue is monotonic in d
    # over ±20 % around each of these thicknesses).
    grid = np.arange(0.8, 1.2, 0.0005)
    hues = np.array([hue_deg(_normal_incidence_rgb(f * d)[0]) for f in grid])
    f_eff = grid[np.argmin([hue_distance(got, x) for x in hues])]
    row = (
        f"{d:5.0f} nm  expected hue {expected_hue:6.1f}°  rendered {got:6.1f}°  "
        f"Δ {hue_distance(got, expected_hue):5.1f}°  equivalent thickness {f_eff * d:6.1f} nm "
        f"({(f_eff - 1) * 100:+.2f} %)  saturation {saturation(centre):.2f}"
    )
    print(f"\nsoap film (n 1.33 in air), roughness 0.35, white World, sphere centre:\n  {row}")
    assert saturation(centre) > 0.3, f"no interference colour at the sphere's centre: {row}"
    assert THICKNESS_TOLERANCE[0] <= f_eff - 1.0 <= THICKNESS_TOLERANCE[1], (
        f"the rendered hue is that of another thickness (allowed {THICKNESS_TOLERANCE}): {row}"
    )


@pytest.mark.parametrize("roughness", [PLAIN_ROUGHNESS, pytest.param(0.35, marks=pytest.mark.slow)])
def test_zero_thickness_film_is_the_bare_substrate(bpy, tf, fresh, tmp_path, roughness):
    """A 0 nm film renders as the bare substrate, through the SH path (fast set) and through the
    hand-over's integrated lobe grid and split sum (0.35, full set: two lobe grids, 60–130 s)."""
    scene = fresh
    hdri_world(bpy, scene, studiolight("courtyard"))
    zero = film(bpy, "Zero Film", thickness_nm=0.0, roughness=roughness, substrate=1.5)
    bare = bpy.data.materials.new("Bare")
    s = bare.thinfilm_sh
    s.preset = "CUSTOM"  # enabling must not fill in a preset's film
    s.enabled = True
    s.vary_thickness = False
    s.roughness = roughness
    s.substrate_mode, s.substrate_ior = "DIELECTRIC", 1.5
    assert len(s.layers) == 0
    assert tf.description.description(bare).layers == ()
    obj = sphere(bpy, scene, material=zero)
    camera(bpy, scene)
    a, ra = render(tf, scene, tmp_path / "zero.png")
    obj.data.materials[0] = bare
    b, rb = render(tf, scene, tmp_path / "bare.png")
    assert ra["objects"] == ["Sphere/Zero Film"] and rb["objects"] == ["Sphere/Bare"]
    mask = b.max(axis=-1) > 0
    assert mask.sum() > 0.3 * mask.size / 2
    diff = np.abs(a - b)[mask]
    assert diff.max() <= 1e-3 * np.abs(b[mask]).max(), (
        f"a 0 nm film differs from the bare substrate by max |Δ| {diff.max():.3g} (≤ 1e-3 of the peak)"
    )
    assert np.all(diff <= 1e-3 * np.abs(b[mask]) + 1e-6), (
        f"a 0 nm film differs from the bare substrate: largest relative Δ "
        f"{np.max(diff / (b[mask] + 1e-9)):.3g} (≤ 1e-3)"
    )


def test_depth_masking_by_an_opaque_cube(bpy, tf, fresh, tmp_path):
    scene = fresh
    white_world(bpy, scene)
    sphere(bpy, scene, material=film(bpy, "Green Film", thickness_nm=300.0, roughness=0.2))
    camera(bpy, scene, distance=6.0)
    size = (96, 72)
    # One sample per pixel: this is about depth, and the frame's 4× pixel filter would spread
    # the cube's edge (and Blender's outline of it) over the filter's ±1.5 px too.
    without, _ = render(tf, scene, tmp_path / "no_cube.png", size, supersample=1)
    block = cube(bpy, scene, location=(-0.5, -2.0, 0.0), size=0.8)
    with_cube, result = render(tf, scene, tmp_path / "cube.png", size, supersample=1)
    assert result["objects"] == ["Sphere/Green Film"]

    # The cube's front face (y = −2.4) in pixels; the whole cube's outline.
    front = project(tf, scene, [(-0.9, -2.4, -0.4), (-0.1, -2.4, 0.4)], size)
    corners = np.array([(x, y, z) for x in (-0.9, -0.1) for y in (-2.4, -1.6) for z in (-0.4, 0.4)])
    outline = project(tf, scene, corners, size)
    ys, xs = np.mgrid[0 : size[1], 0 : size[0]] + 0.5
    inside = (
        (xs > front[:, 0].min() + 1)
        & (xs < front[:, 0].max() - 1)
        & (ys > front[:, 1].min() + 1)
        & (ys < front[:, 1].max() - 1)
    )
    near = (
        (xs > outline[:, 0].min() - 1.5)
        & (xs < outline[:, 0].max() + 1.5)
        & (ys > outline[:, 1].min() - 1.5)
        & (ys < outline[:, 1].max() + 1.5)
    )
    sphere_pixels = saturation(without) > 0.3
    covered = inside & sphere_pixels
    assert covered.sum() >= 100, "the cube should hide a good part of the sphere"
    # Behind the cube: no film colour, the grey of Blender's Solid drawing.
    assert saturation(with_cube[covered]).max() < 0.05
    assert np.abs(with_cube[covered] - without[covered]).max() > 0.01
    # Away from the cube nothing changed (two GPU renders: float32 rounding at most).
    np.testing.assert_allclose(
        with_cube[~near],
        without[~near],
        rtol=0,
        atol=1e-6,
        err_msg="pixels away from the cube changed when the cube was added: depth leaks elsewhere",
    )
    del block


# ----------------------------------------------------------------------------------------------
# Clear messages and a sane picture for broken input
# ----------------------------------------------------------------------------------------------
def test_missing_hdri_file(bpy, tf, fresh, tmp_path):
    """A World whose HDRI file is missing renders anyway, and the message names the missing file: a batch
    render does not die on one broken path."""
    scene = fresh
    missing = tmp_path / "gone" / "missing_sky.exr"
    hdri_world(bpy, scene, missing)
    sphere(bpy, scene, material=film(bpy, "Film", thickness_nm=350.0, roughness=PLAIN_ROUGHNESS))
    camera(bpy, scene)
    image, result = render(tf, scene, tmp_path / "missing.png", background=True)
    text = "\n".join(result["messages"])
    assert "missing_sky.exr" in text, result["messages"]
    assert result["objects"] == ["Sphere/Film"]
    assert np.isfinite(image).all()


def test_corrupt_cache_file_is_rebaked(bpy, tf, fresh, tmp_path, caplog):
    scene = fresh
    white_world(bpy, scene)
    mat = film(bpy, "Cached", thickness_nm=365.0, roughness=PLAIN_ROUGHNESS)
    sphere(bpy, scene, material=mat)
    camera(bpy, scene)
    first, _ = render(tf, scene, tmp_path / "first.png")
    desc = tf.description.description(mat)
    path = tf.tables.table_cache().path_for(tf.description.description_key(desc))
    assert path.is_file() and str(path).startswith(str(tf.cache_dir))
    path.write_bytes(b"this is not an OpenEXR file" * 100)
    tf.tables.clear_memory_cache()
    tf.scene_draw.CACHES.clear()
    bakes = tf.tables.bake_count
    with caplog.at_level("WARNING"):
        again, result = render(tf, scene, tmp_path / "again.png")
    assert tf.tables.bake_count == bakes + 1
    assert result["objects"] == ["Sphere/Cached"]
    assert any(path.name in rec.getMessage() for rec in caplog.records), [
        r.getMessage() for r in caplog.records
    ]
    assert path.with_name(path.name + ".corrupt").is_file()
    tf.table_io.read_table(path)  # the re-baked entry is valid again
    np.testing.assert_allclose(again, first, rtol=0, atol=1e-6)


def test_object_without_faces(bpy, tf, fresh, tmp_path):
    """A film material on a mesh without faces (points only) is skipped with a message while the other
    objects still render."""
    scene = fresh
    white_world(bpy, scene)
    mat = film(bpy, "Film", thickness_nm=350.0, roughness=PLAIN_ROUGHNESS)
    mesh = bpy.data.meshes.new("Points")
    mesh.from_pydata([(0.0, 0.0, 0.0), (0.5, 0.0, 0.0), (0.0, 0.0, 0.5)], [], [])
    mesh.materials.append(mat)
    points = bpy.data.objects.new("Points", mesh)
    scene.collection.objects.link(points)
    sphere(bpy, scene, "Ball", (1.2, 0.0, 0.0), radius=0.5, material=mat)
    camera(bpy, scene)
    image, result = render(tf, scene, tmp_path / "points.png")
    assert any("Points" in m and "no faces" in m for m in result["messages"]), result["messages"]
    assert result["objects"] == ["Ball/Film"]
    assert image.max() > 0.0


def test_nan_thickness_from_python(bpy, tf, fresh, tmp_path):
    """A NaN thickness set from Python is reported by material name and that object is left out, while the
    good film beside it renders."""
    scene = fresh
    white_world(bpy, scene)
    bad = film(bpy, "Bad Film", thickness_nm=350.0, roughness=PLAIN_ROUGHNESS)
    good = film(bpy, "Good Film", thickness_nm=350.0, roughness=PLAIN_ROUGHNESS)
    bad.thinfilm_sh.layers[0].thickness_nm = float("nan")
    assert math.isnan(bad.thinfilm_sh.layers[0].thickness_nm), "RNA kept the NaN (what a script can do)"
    sphere(bpy, scene, "Broken", (-1.1, 0.0, 0.0), radius=0.8, material=bad)
    sphere(bpy, scene, "Fine", (1.1, 0.0, 0.0), radius=0.8, material=good)
    camera(bpy, scene, distance=7.0)
    image, result = render(tf, scene, tmp_path / "nan.png")
    assert result["objects"] == ["Fine/Good Film"], "the broken object is skipped, the other drawn"
    named = [m for m in result["messages"] if "Bad Film" in m]
    assert named and "thickness" in named[0], result["messages"]
    assert np.isfinite(image).all() and image.max() > 0.0


@pytest.mark.parametrize("case", ["no world", "world without nodes"])
def test_world_without_nodes(bpy, tf, fresh, tmp_path, case):
    """A scene without a World, or a World without nodes, renders, with a message naming the World,
    instead of failing the batch."""
    scene = fresh
    if case == "no world":
        scene.world = None
    else:
        world = bpy.data.worlds.new("Empty")
        world.node_tree.nodes.clear()
        scene.world = world
    sphere(bpy, scene, material=film(bpy, "Film", thickness_nm=350.0, roughness=PLAIN_ROUGHNESS))
    camera(bpy, scene)
    image, result = render(tf, scene, tmp_path / "noworld.png", background=True)
    assert any("World" in m for m in result["messages"]), result["messages"]
    assert result["objects"] == ["Sphere/Film"]
    assert np.isfinite(image).all()


# ----------------------------------------------------------------------------------------------
# Files and lifecycle
# ----------------------------------------------------------------------------------------------
def test_saved_and_reopened_file_renders_identically(bpy, tf, fresh, tmp_path):
    scene = fresh
    hdri_world(bpy, scene, studiolight("forest"))
    mat = film(bpy, "Bubble", roughness=0.2, vary=True)  # soap_film: 0–1000 nm from noise
    mat.thinfilm_sh.thickness_source = "NOISE"
    mat.thinfilm_sh.noise_scale = 1.5
    sphere(bpy, scene, material=mat)
    cube(bpy, scene, "Box", (1.3, 1.0, -0.8), size=0.8)  # a Solid-drawn object too
    camera(bpy, scene)
    # One sample per pixel: Blender's Solid drawing of the cube at 4× is not bit-reproducible
    # across a reload (its edge pixels moved by ≤ 3e-5); our own state is what is tested here.
    before, _ = render(tf, scene, tmp_path / "before.png", background=True, supersample=1)
    path = tmp_path / "saved.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path), check_existing=False)
    bpy.ops.wm.open_mainfile(filepath=str(path))
    set_cache_preference(bpy, tf.prefs, tf.cache_dir)
    after, result = render(tf, bpy.context.scene, tmp_path / "after.png", background=True, supersample=1)
    assert result["objects"] == ["Sphere/Bubble"]
    np.testing.assert_allclose(after, before, rtol=0, atol=1e-6)


def _ours(handlers) -> list:
    return [h for h in handlers if getattr(h, "__module__", "").startswith(EXTENSION_ID)]


def test_register_unregister_cycles_leave_nothing_behind(bpy, tf, capfd):
    package, addon, headless = tf.package, tf.addon, tf.headless
    handler_lists = {
        name: getattr(bpy.app.handlers, name)
        for name in dir(bpy.app.handlers)
        if isinstance(getattr(bpy.app.handlers, name), list)
    }
    capfd.readouterr()
    try:
        for cycle in range(10):
            package.unregister()
            assert headless._cli_handle is None, f"cycle {cycle}: CLI command still registered"
            leftovers = {name: _ours(h) for name, h in handler_lists.items() if _ours(h)}
            assert not leftovers, f"cycle {cycle}: handlers left: {leftovers}"
            assert [c.__name__ for c in addon.classes if c.is_registered] == [], f"cycle {cycle}"
            assert not hasattr(bpy.types.Material, "thinfilm_sh")
            package.unregister()  # twice is harmless

            package.register()
            handle = headless._cli_handle
            package.register()  # twice must not register anything twice
            assert headless._cli_handle is handle is not None
            for name in ("load_post", "depsgraph_update_post"):
                mine = _ours(getattr(bpy.app.handlers, name))
                # one per module that registers one (the viewport, the EEVEE films), none twice
                assert len(mine) == len({(h.__module__, h.__name__) for h in mine}) >= 1, (
                    f"cycle {cycle}: {name} holds {[f'{h.__module__}.{h.__name__}' for h in mine]}"
                )
            assert all(c.is_registered for c in addon.classes)
            assert hasattr(bpy.types.Material, "thinfilm_sh")
    finally:
        package.register()
        set_cache_preference(bpy, tf.prefs, tf.cache_dir)
    out = capfd.readouterr()
    assert "duplicate command" not in out.out + out.err


def test_studio_lamps_are_shaded_per_light_and_can_be_turned_off(bpy, tf, fresh, tmp_path):
    """bpy's studio HDRI: its lamps are lifted out (lamp loop + film texture on the draw item),
    and the picture keeps its light: with "World Lamps" off (the whole World through SH and the
    prefilter) the mean brightness of a rough film stays within 10 %, since both carry the same
    power. A diffuse base keeps the whole World (no lamp loop)."""
    scene = fresh
    hdri_world(bpy, scene, studiolight("studio"))
    mat = film(bpy, "Glossy", thickness_nm=500.0, roughness=0.6)
    sphere(bpy, scene, material=mat)
    camera(bpy, scene, distance=5.0)

    def items():
        return tf.scene_draw.collect(bpy.context.evaluated_depsgraph_get())[0]

    (item,) = items()
    image_entry = tf.world_state.STATE.lighting.environment
    assert image_entry is not None and image_entry.lamps is not None
    assert 1 <= image_entry.lamps.count <= tf.gpu.layout.MAX_LAMPS and image_entry.lamps.share > 0.5
    assert item.film is not None and item.lighting.lamp_count == image_entry.lamps.count
    summary = tf.world_state.lamps_summary(True)  # the Surface panel's line
    assert summary.startswith(f"World lamps: {image_entry.lamps.count}, ") and "per lamp" in summary, summary
    assert "off" in tf.world_state.lamps_summary(False)
    # The lighting of a lamp-shaded film is the World's SH minus the lamps' SH.
    whole = tf.world_state.STATE.lighting.sh.coeffs
    assert item.lighting.coefficients[0, 1] < 0.5 * whole[0, 1]
    on, _ = render(tf, scene, tmp_path / "lamps_on.png")

    mat.thinfilm_sh.world_lamps = False
    (item_off,) = items()
    assert item_off.film is None and item_off.lighting.lamp_count == 0
    # A rough film (SH weight 1) reads no prefilter, so none is made for it (issue 22); the
    # glossy films' prefilters: test_prefilters_are_computed_only_for_the_films_that_read_them.
    assert item_off.prefiltered is None and item_off.sh_weight == 1.0
    off, _ = render(tf, scene, tmp_path / "lamps_off.png")
    sphere_px = on.sum(axis=-1) > 0
    ratio = off[sphere_px].mean() / on[sphere_px].mean()
    assert 0.9 < ratio < 1.1, ratio

    mat.thinfilm_sh.world_lamps = True
    mat.thinfilm_sh.diffuse_base = True
    (item_diffuse,) = items()
    assert item_diffuse.film is None and item_diffuse.lighting.lamp_count == 0


# ----------------------------------------------------------------------------------------------
# Principled films, prefilters on demand, the anti-aliased frame (issue 22)
# ----------------------------------------------------------------------------------------------
def principled_film(bpy, name, roughness, base=(0.0, 0.0, 0.0), thickness_nm=500.0):
    mat = bpy.data.materials.new(name)
    node = next(n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    node.inputs["Base Color"].default_value = (*base, 1.0)
    node.inputs["Roughness"].default_value = roughness
    node.inputs["IOR"].default_value = 1.5
    node.inputs["Thin Film Thickness"].default_value = thickness_nm
    node.inputs["Thin Film IOR"].default_value = 1.33
    return mat


def test_prefilters_are_computed_only_for_the_films_that_read_them(bpy, tf, fresh, monkeypatch):
    """Under bpy's studio HDRI (it has lamps): a rough film makes no prefilter; a glossy black-base
    Principled film gets the World's lamps and the prefilter with them lifted out, and only it;
    a glossy film under a diffuse base adds the whole World's prefilter. Counted at the one
    function that computes a prefilter, through the draw's real code path."""
    prefilter_mod = importlib.import_module(f"{EXTENSION_ID}.precompute.world.prefilter")
    calls = []
    real = prefilter_mod.prefilter

    def counting(image, *args, **kwargs):
        calls.append("lifted" if kwargs.get("lamp_mask") is not None else "whole")
        return real(image, *args, **kwargs)

    monkeypatch.setattr(prefilter_mod, "prefilter", counting)
    scene = fresh
    hdri_world(bpy, scene, studiolight("studio"))
    camera(bpy, scene)

    def items():
        found, _ = tf.scene_draw.collect(bpy.context.evaluated_depsgraph_get())
        return {item.name.split("/")[0]: item for item in found}

    sphere(bpy, scene, "Rough", material=principled_film(bpy, "Rough", roughness=0.6))
    rough = items()["Rough"]
    assert calls == [] and rough.prefiltered is None  # SH only: no prefilter at all
    assert rough.film is not None and rough.lighting.lamp_count > 0  # black Base Color: the lamps

    sphere(bpy, scene, "Glossy", (2.5, 0.0, 0.0), material=principled_film(bpy, "Glossy", roughness=0.1))
    glossy = items()["Glossy"]
    assert calls == ["lifted"]
    assert glossy.film is not None and glossy.lighting.lamp_count > 0
    assert glossy.prefiltered is tf.world_state.STATE.lighting.textures.prefiltered()

    base = principled_film(bpy, "Grey", roughness=0.1, base=(0.5, 0.5, 0.5))
    sphere(bpy, scene, "Grey", (-2.5, 0.0, 0.0), material=base)
    found = items()
    assert calls == ["lifted", "whole"]
    assert found["Grey"].film is None and found["Grey"].lighting.lamp_count == 0  # a diffuse base
    assert found["Grey"].prefiltered is tf.world_state.STATE.lighting.textures.prefiltered_whole()
    items()
    assert calls == ["lifted", "whole"]  # kept: nothing is prefiltered twice


def test_headless_frame_applies_the_scenes_pixel_filter(bpy, tf, fresh, tmp_path):
    """Cycles' default filter (Blackman–Harris, 1.5 px) on a 4× frame by default; a 1 px box on
    the 4× frame is exactly the block mean of a frame rendered 4× larger, one sample a pixel."""
    scene = fresh
    white_world(bpy, scene)
    sphere(bpy, scene, material=film(bpy, "Film", thickness_nm=350.0, roughness=PLAIN_ROUGHNESS))
    camera(bpy, scene)
    default, result = render(tf, scene, tmp_path / "default.png")
    assert result["supersample"] == tf.render.SUPERSAMPLE == 4
    assert result["pixel_filter"] == ["BLACKMAN_HARRIS", 1.5]
    scene.cycles.pixel_filter_type, scene.cycles.filter_width = "BOX", 1.0
    box, result = render(tf, scene, tmp_path / "box.png")
    assert result["pixel_filter"] == ["BOX", 1.0]
    w, h = SIZE
    big = tf.render.render_scene(
        scene, str(tmp_path / "big.png"), 4 * w, 4 * h, background=False, supersample=1
    )
    assert big["supersample"] == 1 and big["pixel_filter"] is None
    fine = read_exr(big["exr"])
    np.testing.assert_allclose(box, fine.reshape(h, 4, w, 4, 3).mean(axis=(1, 3)), atol=1e-6)
    # The wider Blackman–Harris support softens the silhouette: its edge pixels differ from the
    # box's, its interior (away from the silhouette) hardly.
    assert np.abs(default - box).max() > 1e-3
    inside = (fine.reshape(h, 4, w, 4, 3).min(axis=(1, 3, 4)) > 0) & (box.min(axis=-1) > 0)
    core = inside.copy()
    for _ in range(2):
        core[1:-1, 1:-1] &= core[:-2, 1:-1] & core[2:, 1:-1] & core[1:-1, :-2] & core[1:-1, 2:]
    assert np.abs(default - box)[core].max() < 0.05 * box[core].max()


def test_instances_from_an_excluded_collection_render_bake_and_plan(bpy, tf, fresh, tmp_path):
    """Issue 19: film objects instanced from an excluded collection are rendered (no "cannot be
    hidden" traceback), baked and planned; a ``hide_render`` film object is not drawn."""
    scene = fresh
    source = bpy.data.collections.new("Source")
    scene.collection.children.link(source)
    ball = sphere(bpy, scene, "Ball", radius=0.8, material=film(bpy, "InstFilm"))
    for collection in list(ball.users_collection):
        collection.objects.unlink(ball)
    source.objects.link(ball)
    bpy.context.view_layer.layer_collection.children["Source"].exclude = True
    for x in (-1.2, 1.2):
        empty = bpy.data.objects.new(f"Instancer{x:+}", None)
        empty.instance_type, empty.instance_collection, empty.location = "COLLECTION", source, (x, 0.0, 0.0)
        scene.collection.objects.link(empty)
    hidden = sphere(
        bpy, scene, "Hidden", location=(0.0, 0.0, 2.0), radius=0.3, material=film(bpy, "HiddenFilm")
    )
    hidden.hide_render = True
    camera(bpy, scene, distance=6.0)
    found, errors = tf.headless.scene_materials(scene)
    assert set(found) == {"InstFilm"} and not errors, (set(found), errors)
    image, result = render(tf, scene, tmp_path / "inst.png", supersample=1)
    assert result["objects"] == ["Ball/InstFilm", "Ball/InstFilm"], result["objects"]
    left, right = image[:, : SIZE[0] // 2].max(), image[:, SIZE[0] // 2 :].max()
    assert left > 0.01 and right > 0.01, (left, right)  # both instances drawn


def test_cli_frames_write_one_file_per_frame_computing_the_world_once(
    bpy, tf, fresh, tmp_path, capsys, monkeypatch
):
    """Issue 19: ``--frames 1-3`` writes three frames; the World (unchanged across them) is
    analysed once; ``--scene``/``--camera`` pick what is rendered, and a wrong name is exit 2."""
    scene = fresh
    sphere(bpy, scene, "Ball", material=film(bpy, "FramesFilm"))
    camera(bpy, scene, distance=6.0)
    scene.world = bpy.data.worlds.new("Frames World")
    scene.world.color = (0.31, 0.27, 0.19)  # a World no other test analysed
    analysed = []
    analysis = importlib.import_module(f"{EXTENSION_ID}.addon.world.world_analysis")
    original = analysis.analyse_world
    monkeypatch.setattr(analysis, "analyse_world", lambda *a, **k: analysed.append(1) or original(*a, **k))
    out = tmp_path / "shot_###.png"
    argv = ["render", "--out", str(out), "--frames", "1-3", "--engine", "SOLID", "--supersample", "1"]
    code = tf.headless._cli([*argv, "--json", str(tmp_path / "frames.json"), "--resolution", "32x24"])
    printed = capsys.readouterr().out
    assert code == 0, printed
    for frame in (1, 2, 3):
        assert (tmp_path / f"shot_{frame:03d}.png").is_file() and (
            tmp_path / f"shot_{frame:03d}.exr"
        ).is_file()
        assert f"frame {frame} ({frame}/3)" in printed
    assert len(analysed) == 1, f"the World was analysed {len(analysed)} times for 3 frames"
    summary = json.loads((tmp_path / "frames.json").read_text())
    assert [f["frame"] for f in summary["frames"]] == [1, 2, 3]
    assert all(f["size"] == [32, 24] for f in summary["frames"])
    code = tf.headless._cli(["render", "--out", str(tmp_path / "x.png"), "--scene", "Nope"])
    err = capsys.readouterr().err
    assert code == 2 and "--scene" in err and repr(scene.name) in err, err
    code = tf.headless._cli(["render", "--out", str(tmp_path / "x.png"), "--camera", "Nope"])
    err = capsys.readouterr().err
    assert code == 2 and "--camera" in err, err
