"""Issue 23, pure side: hostile material values, command lines, EXR and cache files, output names.

Each case asserts a clean outcome: a ``ValueError`` naming the parameter, or a refusal (exit 2)
naming the option before any work, or — for damaged files — a :class:`TableError` and a cache
that re-bakes; never a traceback, a hang, a non-finite pixel written without a message, or an
overwritten file. "Before any work" is asserted by counting (the bake function is replaced by one
that fails the test), "never a hang" by a thread deadline that no correct refusal comes near
(each takes milliseconds). The Blender side (material settings, Worlds, mesh data, the headless
commands) is tests/extension/test_hostile_blender.py; the exit codes are docs/cli-exit-codes.md.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import OpenEXR
import pytest
from _waits import finishes

from precompute.bakes import bake
from precompute.commands import cli, cli_support
from precompute.materials import validate
from precompute.materials.conductors import conductor_from_rgb
from precompute.materials.material import FALLBACK, Layer, Material, Quality
from precompute.tables.table_cache import TableCache
from precompute.tables.table_io import TableError, read_table, write_table

NAN, INF = float("nan"), float("inf")


# ----------------------------------------------------------------------------------------------
# Materials: every value is checked when the description is built
# ----------------------------------------------------------------------------------------------
def _layers(index=1.33, thickness=300.0):
    return {"layers": (Layer(index, thickness),)}


def _table(wl=(360.0, 600.0, 830.0), n=(1.5, 1.5, 1.5), k=(0.0, 0.0, 0.0)):
    return {"table": {"wavelengths_nm": list(wl), "n": list(n), "k": list(k)}}


MATERIALS = [
    # (changes, words the message must contain)
    (_layers(NAN), "layers[0].index n must be finite"),
    (_layers(INF), "layers[0].index n must be finite"),
    (_layers(-1.0), "n > 0"),
    (_layers(0.0), "n > 0"),
    (_layers(1001.0), "n ≤ 1000"),
    (_layers(3.4028234663852886e38), "n ≤ 1000"),  # what Blender stores for inf
    (_layers([1.5, NAN]), "layers[0].index k must be finite"),
    (_layers([1.5, -0.1]), "extinction k ≥ 0"),
    (_layers([1.5, 1001.0]), "k ≤ 1000"),
    (_layers([NAN, 0.0]), "layers[0].index n"),
    (_layers(True), "layers[0].index"),
    (_layers("glass"), "layers[0].index"),
    (_layers(None), "layers[0].index"),
    (_layers([1.0, 2.0, 3.0]), "layers[0].index"),
    (_layers({}), "layers[0].index"),
    (_layers({"cauchy": [NAN]}), "Cauchy coefficients[0] must be finite"),
    (_layers({"cauchy": [1.5, NAN]}), "Cauchy coefficients[1] must be finite"),  # the issue's
    (_layers({"cauchy": [1.5, -1.0]}), "n > 0"),  # the Cauchy B that makes n negative
    (_layers({"cauchy": [1.5, 0.0, -0.5]}), "n > 0"),
    (_layers({"cauchy": [1.3, -0.8, 0.1]}), "n > 0"),  # positive at both ends, negative at 500 nm
    (_layers({"cauchy": []}), "at least 1"),
    (_layers({"cauchy": [1.5, 0.0, 0.0, 1.0]}), "at most 3"),
    (_layers({"cauchy": "abc"}), "list of numbers"),
    (_layers({"cauchy": [1.5, 1e300]}), "n ≤ 1000"),
    (_layers({"cauchy": [-1.5, 1.0]}), "Cauchy A"),
    (_layers({"sellmeier": {"B": [1.0], "C": [0.25]}}), "resonance at 500.0 nm"),
    (_layers({"sellmeier": {"B": [-5.0], "C": [0.0]}}), "n²"),
    (_layers({"sellmeier": {"B": [1.0]}}), "keys 'B' and 'C'"),
    (_layers({"sellmeier": {"B": [0.1] * 17, "C": [0.0] * 17}}), "at most 16"),
    (_layers({"sellmeier": {"B": [NAN], "C": [0.01]}}), "Sellmeier B[0] must be finite"),
    (_layers({"sellmeier": {"B": [1.0], "C": [0.01, 0.02]}}), "must have 1 values"),
    (_layers(_table(wl=(400.0, 800.0), n=(1.5, 1.5), k=(0, 0))), "covers 400–800 nm"),
    (_layers(_table(wl=(360.0, 360.0, 830.0))), "increase strictly"),
    (_layers(_table(n=(1.5, NAN, 1.5))), "table n[1] must be finite"),
    (_layers(_table(k=(0.0, -1.0, 0.0))), "extinction k ≥ 0"),
    (_layers(_table(n=(1.5, 1.5, 0.0))), "n > 0"),
    (_layers(_table(wl=np.linspace(360, 830, 10_001), n=[1.5] * 10_001, k=[0] * 10_001)), "at most 10000"),
    (_layers(_table(n=(1.5, 1.5))), "must have 3 values"),
    (_layers({"metal": "unobtainium"}), "unobtainium"),
    (_layers({"metal": 5}), "named by a string"),
    (_layers({"metal": ["gold"]}), "named by a string"),
    (_layers({"plasma": 1.0}), "unknown index kind"),
    (_layers({"cauchy": [1.5], "metal": "gold"}), "layers[0].index"),
    (_layers(thickness=NAN), "layers[0].thickness_nm must be finite"),
    (_layers(thickness=INF), "layers[0].thickness_nm must be finite"),
    (_layers(thickness=-1.0), "layers[0].thickness_nm"),
    (_layers(thickness=100_001.0), "100 µm"),
    (_layers(thickness=True), "layers[0].thickness_nm must be a number"),
    (_layers(thickness="300"), "layers[0].thickness_nm must be a number"),
    (_layers(thickness=None), "layers[0].thickness_nm must be a number"),
    ({"layers": tuple(Layer(1.5, 10.0) for _ in range(129))}, "at most 128 layers"),
    ({"layers": "abc"}, "layers must be a list"),
    ({"layers": 5}, "layers must be a list"),
    ({"layers": [[1.5]]}, "layers[0] must be (index, thickness_nm)"),
    ({"layers": [{"index": 1.5}]}, "layers[0] must be (index, thickness_nm)"),
    ({"substrate": NAN}, "substrate n must be finite"),
    ({"substrate": {"metal": "gold!"}}, "substrate"),
    ({"substrate": [2.0, INF]}, "substrate k must be finite"),
    ({"ambient": NAN}, "ambient must be finite"),
    ({"ambient": 0.5}, "ambient must lie in [1, 1000]"),
    ({"ambient": 1001.0}, "ambient must lie in [1, 1000]"),
    ({"ambient": True}, "ambient must be a number"),
    ({"roughness": NAN}, "roughness must be finite"),
    ({"roughness": -0.1}, "roughness must lie in [0, 1]"),
    ({"roughness": 1.1}, "roughness must lie in [0, 1]"),
    ({"roughness": INF}, "roughness must be finite"),
    ({"roughness": "0.3"}, "roughness must be a number"),
    ({"roughness": None}, "roughness must be a number"),
    ({"thickness_range_nm": (NAN, 1.0)}, "thickness_range_nm min must be finite"),
    ({"thickness_range_nm": (5.0, 1.0)}, "min < max"),
    ({"thickness_range_nm": (1.0, INF)}, "thickness_range_nm max must be finite"),
    ({"thickness_range_nm": (0.0, 2e5)}, "thickness_range_nm max must lie in [0, 100000]"),
    ({"thickness_range_nm": (1.0, 2.0, 3.0)}, "(min, max)"),
    ({"thickness_range_nm": "ab"}, "(min, max)"),
    ({"base_color": (NAN, 0.0, 0.0)}, "base_color R must be finite"),
    ({"base_color": (0.0, 2.0, 0.0)}, "base_color G must lie in [0, 1]"),
    ({"base_color": (1.0, 1.0)}, "three values"),
    ({"base_color": "red"}, "three values"),
    ({"model": "magic"}, "model"),
    ({"model": ["exact"]}, "model"),
    ({"model": "glassner2000", "layers": (Layer(1.5, 100.0), Layer(1.4, 100.0))}, "exactly one layer"),
    ({"colour_space": 5}, "colour_space must be a name"),
    ({"colour_space": "sRGB-ish"}, "sRGB-ish"),
    ({"illuminant": None}, "illuminant must be a name"),
    ({"illuminant": "D99"}, "D99"),
    ({"quality": Quality(sh_order=13)}, "quality.sh_order"),
    ({"quality": Quality(view_samples=1)}, "quality.view_samples"),
    ({"quality": Quality(wavelength_count=10**9)}, "quality.wavelength_count"),
    ({"quality": Quality(sh_order=2.5)}, "quality.sh_order must be an integer"),
    ({"quality": Quality(thickness_samples="many")}, "quality.thickness_samples"),
    ({"quality": {"bogus": 1}}, "quality must be a Quality"),
]


@pytest.mark.parametrize(("changes", "words"), MATERIALS, ids=[w for _, w in MATERIALS])
def test_invalid_material_is_named_at_once(changes, words):
    _, exc = finishes(lambda: Material(**changes))
    assert isinstance(exc, ValueError), repr(exc)
    assert words in str(exc), str(exc)


@pytest.mark.parametrize(
    "data",
    [
        {"layers": [{"idx": 1.5}]},
        {"colour": 1},
        {"layers": 5},
        {"layers": [[1.5, 300.0]], "roughness": NAN},
        {"quality": {"sh_order": "lots"}},
    ],
)
def test_material_from_hostile_dict_is_a_value_error(data):
    with pytest.raises(ValueError):
        Material.from_dict(data)


def test_extreme_but_valid_values_are_accepted():
    """The limits refuse garbage, not physics or interop: the largest indices, 100 µm, 128 layers."""
    Material(layers=(Layer(1000.0, 100_000.0),), substrate=[4.0, 1000.0], roughness=1.0)
    # A Principled metal with a bright Base Color and a low Specular Tint: Gulbrandsen's fit gives
    # n ≈ 398, k up to ≈ 199 (why the limits are 1000, not 100).
    Material(layers=(), substrate=conductor_from_rgb((1.0, 1.0, 1.0), (0.0, 0.0, 0.0)))
    Material(layers=(), substrate=conductor_from_rgb((0.99, 0.5, 0.1), (0.2, 0.9, 1.0)))
    Material(layers=tuple(Layer(1.5 if i % 2 else 2.3, 80.0) for i in range(128)))
    Material(layers=(Layer({"sellmeier": {"B": [1.03961212], "C": [0.00600069867]}}, 100.0),))
    Material(layers=(Layer({"cauchy": [1.5, 0.2, -0.01]}, 100.0),))  # vertex outside the range
    assert FALLBACK.base_color == (1.0, 0.0, 1.0) and not FALLBACK.layers


# ----------------------------------------------------------------------------------------------
# python -m precompute: bad options are refused before any work (exit 2), with the option named
# ----------------------------------------------------------------------------------------------
class Guard:
    def __init__(self):
        self.calls = 0

    def __call__(self, *args, **kwargs):
        self.calls += 1
        raise AssertionError("bake was called: the input should have been refused first")


@pytest.fixture
def no_bake(monkeypatch):
    guard = Guard()
    monkeypatch.setattr(bake, "bake", guard)
    return guard


def _plant(kind: str, tmp_path: Path) -> str:
    """A path where an output must not go; ``tmp_path`` holds whatever it needs."""
    if kind == "dir":
        (tmp_path / "out.png").mkdir()
        return str(tmp_path / "out.png")
    if kind == "exr-dir":  # the EXR beside the PNG would replace a directory
        (tmp_path / "out.exr").mkdir()
        return str(tmp_path / "out.png")
    if kind == "fifo":
        os.mkfifo(tmp_path / "out.png")
        return str(tmp_path / "out.png")
    if kind == "symlink":
        (tmp_path / "real.png").write_bytes(b"the user's file")
        (tmp_path / "out.png").symlink_to(tmp_path / "real.png")
        return str(tmp_path / "out.png")
    if kind == "device":
        return "/dev/full"
    if kind == "unwritable":
        return "/proc/self/no-such-folder/out.png"
    if kind == "parent-is-file":
        (tmp_path / "notes.txt").write_text("the user's notes")
        return str(tmp_path / "notes.txt" / "out.png")
    if kind == "trailing-slash":
        return str(tmp_path / "folder") + "/"
    if kind == "empty":
        return ""
    raise AssertionError(kind)


def _snapshot(tmp_path: Path) -> dict:
    return {
        p.relative_to(tmp_path).as_posix(): (p.lstat().st_mode, p.read_bytes() if p.is_file() else None)
        for p in sorted(tmp_path.rglob("*"))
        if not p.is_fifo()
    }


WORDS = {
    "dir": "directory",
    "exr-dir": ".exr",
    "fifo": "FIFO",
    "symlink": "symbolic link",
    "device": "character device",
    "unwritable": "cannot",
    "parent-is-file": "not a folder",
    "trailing-slash": "folder",
    "empty": "needs a file path",
}
SMALL = ["--film-index", "1.33", "--thickness", "300", "--substrate", "1.5", "--sh-order", "2"]
SMALL += ["--view-samples", "2", "--wavelengths", "16", "--quiet"]


def _run(argv, capsys):
    code, exc = finishes(lambda: cli.main(argv))
    assert exc is None, repr(exc)  # never an exception out of main: one line and a code
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return code, err


@pytest.mark.parametrize("kind", list(WORDS))
@pytest.mark.parametrize("option", ["render --out", "bake --out", "bake --json"])
def test_output_path_is_refused_before_work(tmp_path, capsys, no_bake, option, kind):
    if kind == "exr-dir" and option != "render --out":
        pytest.skip("only render writes an .exr beside its output")
    command, flag = option.split()
    path = _plant(kind, tmp_path)
    before = _snapshot(tmp_path)
    extra = ["--out", str(tmp_path / "t.exr")] if flag == "--json" else []
    code, err = _run([command, *SMALL, *extra, flag, path], capsys)
    assert code == 2 and flag in err and WORDS[kind] in err, err
    assert no_bake.calls == 0 and _snapshot(tmp_path) == before


OPTIONS = [
    # (command, extra arguments, words the message must contain)
    ("render", ["--size", "0"], "--size"),
    ("render", ["--size", "-1"], "--size"),
    ("render", ["--size", "16385"], "--size"),
    ("render", ["--size", "100000"], "--size"),  # the 74.5 GiB allocation
    ("render", ["--size", "abc"], "--size"),
    ("render", ["--size", "nan"], "--size"),
    ("render", ["--size", "1.5"], "--size"),
    ("render", ["--size", ""], "--size"),
    ("render", ["--exposure", "nan"], "--exposure"),
    ("render", ["--exposure", "inf"], "--exposure"),
    ("render", ["--exposure", "-inf"], "--exposure"),
    ("render", ["--exposure", "1e308"], "--exposure"),  # the OverflowError
    ("render", ["--exposure", "1e400"], "--exposure"),
    ("render", ["--exposure", "65"], "--exposure"),
    ("render", ["--exposure", "-65"], "--exposure"),
    ("render", ["--exposure", "abc"], "--exposure"),
    ("render", ["--hdri", "no-such-hdri"], "no-such-hdri"),
    ("render", ["--hdri", "{tmp}/notes.txt"], "not an OpenEXR file"),
    ("render", ["--hdri", "{tmp}/truncated.exr"], "truncated.exr"),
    ("render", ["--hdri", "{tmp}"], "does not exist"),
    ("bake", ["--thickness", "nan"], "thickness_nm must be finite"),
    ("bake", ["--thickness", "inf"], "thickness_nm must be finite"),
    ("bake", ["--thickness", "-1"], "thickness_nm"),
    ("bake", ["--thickness", "1e9"], "100 µm"),
    ("bake", ["--roughness", "nan"], "roughness"),
    ("bake", ["--roughness", "2"], "roughness"),
    ("bake", ["--film-index", "nan"], "layers[0].index"),
    ("bake", ["--film-index", "inf"], "layers[0].index"),
    ("bake", ["--film-index", "-1"], "n > 0"),
    ("bake", ["--film-index", "1e999"], "layers[0].index"),
    ("bake", ["--film-index", "1,2,3"], "--film-index"),
    ("bake", ["--film-index", "nan,0"], "layers[0].index"),
    ("bake", ["--film-index", "1.5,-1"], "extinction"),
    ("bake", ["--film-index", "unobtainium"], "unobtainium"),
    ("bake", ["--substrate", "nan"], "substrate"),
    ("bake", ["--substrate", "plutonium"], "plutonium"),
    ("bake", ["--ambient", "nan"], "ambient"),
    ("bake", ["--ambient", "0.5"], "ambient"),
    ("bake", ["--base-color", "nan", "0", "0"], "base_color"),
    ("bake", ["--base-color", "2", "0", "0"], "base_color"),
    ("bake", ["--layers", "not json"], "--layers"),
    ("bake", ["--layers", "{}"], "--layers"),
    ("bake", ["--layers", "[[1.5]]"], "--layers row 0"),
    ("bake", ["--layers", "[[1.5, 300, 1]]"], "--layers row 0"),
    ("bake", ["--layers", '[["gold", 100]]'], "layers[0].index"),
    ("bake", ["--layers", '[[1.5, "300"]]'], "layers[0].thickness_nm"),
    ("bake", ["--layers", "[[1e400, 100]]"], "layers[0].index"),
    ("bake", ["--layers", "[" * 100_000 + "]" * 100_000], "--layers"),
    ("bake", ["--layers", json.dumps([[1.5, 10]] * 129)], "at most 128 layers"),
    ("bake", ["--thickness-range", "5", "1"], "min < max"),
    ("bake", ["--thickness-range", "nan", "3"], "thickness_range_nm"),
    ("bake", ["--thickness-range", "0", "1e9"], "thickness_range_nm"),
    ("bake", ["--sh-order", "99"], "quality.sh_order"),
    ("bake", ["--sh-order", "-1"], "quality.sh_order"),
    ("bake", ["--sh-order", "abc"], "--sh-order"),
    ("bake", ["--view-samples", "1"], "quality.view_samples"),
    ("bake", ["--wavelengths", "1e9"], "--wavelengths"),
    ("bake", ["--wavelengths", "100000000"], "quality.wavelength_count"),
    ("bake", ["--illuminant", "D99"], "D99"),
    ("bake", ["--model", "magic"], "--model"),
    ("bake", ["--preset", "nope"], "--preset"),
    ("plan", ["--film-index", "nan"], "layers[0].index"),
    ("plan", ["--layers", "[[1.5]]"], "--layers"),
]


@pytest.mark.parametrize(("command", "args", "words"), OPTIONS, ids=[" ".join(a)[:40] for _, a, _ in OPTIONS])
def test_bad_option_is_refused_before_work(tmp_path, capsys, no_bake, command, args, words):
    (tmp_path / "notes.txt").write_text("not an image")
    good = tmp_path / "good.exr"
    write_table(good, np.ones((2, 3, 9)))
    (tmp_path / "truncated.exr").write_bytes(good.read_bytes()[:60])
    args = [a.replace("{tmp}", str(tmp_path)) for a in args]
    out = [] if command == "plan" else ["--out", str(tmp_path / "out" / "x.png")]
    code, err = _run([command, *args, *out, *(["--quiet"] if command != "plan" else [])], capsys)
    assert code == 2 and words in err, err
    assert no_bake.calls == 0 and not (tmp_path / "out").exists()


def _nan_hdri(path: Path) -> Path:
    image = np.full((16, 32, 3), 0.5, dtype=np.float32)
    image[2:6, 3:9] = np.nan
    image[10, :, 2] = np.inf
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION}, {"RGB": image}).write(str(path))
    return path


def test_nan_pixels_in_the_hdri_give_a_finite_picture_and_a_message(tmp_path, capsys):
    hdri = _nan_hdri(tmp_path / "sky.exr")
    out = tmp_path / "ball.png"
    code, err = _run(["render", *SMALL, "--size", "16", "--hdri", str(hdri), "--out", str(out)], capsys)
    assert code == cli_support.EXIT_PARTIAL and "56 NaN/Inf pixels left out" in err, err
    with OpenEXR.File(str(out.with_suffix(".exr"))) as f:
        rgb = np.asarray(f.channels()["RGB"].pixels)
    assert rgb.shape == (16, 16, 3) and np.isfinite(rgb).all() and rgb.max() > 0.0


def test_an_internal_error_is_one_line_and_a_log(tmp_path, capsys, monkeypatch):
    def bug(*args, **kwargs):
        raise ZeroDivisionError("simulated bug")

    monkeypatch.setattr(bake, "bake", bug)
    code, err = _run(["bake", *SMALL, "--out", str(tmp_path / "t.exr")], capsys)
    assert code == cli_support.EXIT_INTERNAL and err.count("\n") == 1 and "internal error" in err, err
    log = Path(err.rsplit("details in ", 1)[1].rstrip(")\n"))
    text = log.read_text()
    assert "Traceback" in text and "ZeroDivisionError: simulated bug" in text
    assert oct(log.stat().st_mode & 0o777) == "0o600"
    log.unlink()
    assert not (tmp_path / "t.exr").exists()


def test_interrupt_is_exit_130(tmp_path, capsys, monkeypatch):
    """Ctrl-C during a bake ends the command with exit code 130 and says so, as shells and farm managers
    expect."""

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(bake, "bake", interrupted)
    code, err = _run(["bake", *SMALL, "--out", str(tmp_path / "t.exr")], capsys)
    assert code == cli_support.EXIT_INTERRUPTED and "interrupted" in err


# ----------------------------------------------------------------------------------------------
# The shared checks
# ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("value", "ok"),
    [
        (1, True),
        (16384, True),
        (0, False),
        (-3, False),
        (16385, False),
        (True, False),
        (2.5, False),
        ("x", False),
    ],
)
def test_image_size_limits(value, ok):
    """--size accepts the documented range and refuses anything else with the option named."""
    if ok:
        assert cli_support.image_size("--size", value) == value
    else:
        with pytest.raises(cli_support.UsageError, match="--size"):
            cli_support.image_size("--size", value)


@pytest.mark.parametrize(
    ("value", "ok"), [(0.0, True), (-64.0, True), (64.0, True), (64.5, False), (NAN, False), (1e308, False)]
)
def test_exposure_limits(value, ok):
    """--exposure accepts finite values in the documented range and refuses the rest with the option named."""
    if ok:
        assert cli_support.exposure("--exposure", value) == value
    else:
        with pytest.raises(cli_support.UsageError, match="--exposure"):
            cli_support.exposure("--exposure", value)


NAMES = [
    (
        ["Mat 001", "Mat.001", "Mat_001"],
        {"Mat_001": "Mat_001.exr", "Mat 001": "Mat_001-2.exr", "Mat.001": "Mat_001-3.exr"},
    ),
    (["A", "a"], {"A": "A.exr", "a": "a-2.exr"}),  # one file on macOS and Windows
    (
        ["Mat_001-2", "Mat 001", "Mat_001"],
        {"Mat_001": "Mat_001.exr", "Mat_001-2": "Mat_001-2.exr", "Mat 001": "Mat_001-3.exr"},
    ),
    (["CON", "nul"], {"CON": "CON_.exr", "nul": "nul_.exr"}),
    (["", "/"], {"": "material.exr", "/": "_.exr"}),
    (["../../etc/passwd"], {"../../etc/passwd": "______etc_passwd.exr"}),
    (["Vidro Ç", "Vidro_Ç"], {"Vidro Ç": "Vidro__.exr", "Vidro_Ç": "Vidro__-2.exr"}),
    (["x" * 300], {"x" * 300: "x" * 100 + ".exr"}),
]


@pytest.mark.parametrize(("names", "expected"), NAMES, ids=[",".join(n)[:30] for n, _ in NAMES])
def test_unique_file_names(names, expected):
    """Output names of materials are unique even when names differ only in case or in characters a file
    system cannot hold, and stable under reordering: no render overwrites another."""
    found = cli_support.unique_file_names(names)
    assert found == expected
    assert len({f.casefold() for f in found.values()}) == len(names)
    assert cli_support.unique_file_names(list(reversed(names))) == found  # stable


def test_validate_limits_are_stated():
    """The validation limits are the ones docs/hostile-input.md states (index ≤ 1000, thickness ≤ 100 µm,
    360–830 nm)."""
    assert validate.MAX_INDEX_N == 1000.0 and validate.MAX_THICKNESS_NM == 100_000.0
    assert validate.VISIBLE_GRID_NM[0] == 360.0 and validate.VISIBLE_GRID_NM[-1] == 830.0


# ----------------------------------------------------------------------------------------------
# EXR tables and the cache: damaged files are refused and re-baked (the reader's guarantees kept)
# ----------------------------------------------------------------------------------------------
def _good(tmp_path: Path) -> bytes:
    path = tmp_path / "good.exr"
    write_table(path, np.linspace(0.0, 1.0, 54).reshape(2, 3, 9), {"v": 1})
    return path.read_bytes()


def _with_pixels(tmp_path: Path, value) -> bytes:
    """A table re-encoded with every pixel ``value`` and the original header (hash now wrong)."""
    src = tmp_path / "good.exr"
    exr = OpenEXR.File(str(src), separate_channels=True)
    header = {k: v for k, v in exr.header().items() if k.startswith("thinfilm_sh/")}
    header.update(compression=OpenEXR.ZIP_COMPRESSION, type=OpenEXR.scanlineimage)
    channels = {n: np.full_like(np.array(c.pixels), value) for n, c in exr.channels().items()}
    out = tmp_path / "crafted.exr"
    OpenEXR.File(header, channels).write(str(out))
    return out.read_bytes()


DAMAGE = {
    "empty": lambda raw, tmp: b"",
    "4 bytes": lambda raw, tmp: raw[:4],
    "8 bytes": lambda raw, tmp: raw[:8],
    "header cut": lambda raw, tmp: raw[:100],
    "half": lambda raw, tmp: raw[: len(raw) // 2],
    "last byte missing": lambda raw, tmp: raw[:-1],
    "wrong magic": lambda raw, tmp: b"\0\0\0\0" + raw[4:],
    "a PNG": lambda raw, tmp: b"\x89PNG\r\n\x1a\n" + bytes(64),
    "last pixel byte flipped": lambda raw, tmp: raw[:-1] + bytes([raw[-1] ^ 0xFF]),
    "NaN pixels": lambda raw, tmp: _with_pixels(tmp, np.nan),
    "Inf pixels": lambda raw, tmp: _with_pixels(tmp, np.inf),
    "zeros under the old hash": lambda raw, tmp: _with_pixels(tmp, 0.0),
    "random bytes": lambda raw, tmp: np.random.default_rng(23).bytes(len(raw)),
}


@pytest.mark.parametrize("damage", list(DAMAGE))
def test_damaged_table_is_refused_and_the_cache_rebakes(tmp_path, damage):
    raw = _good(tmp_path)
    cache = TableCache(tmp_path / "cache")
    cache.store("k" * 16, np.zeros((2, 3, 9)), {"v": 1})
    path = cache.path_for("k" * 16)
    path.write_bytes(DAMAGE[damage](raw, tmp_path))

    _, exc = finishes(lambda: read_table(path))
    assert isinstance(exc, TableError) and str(path) in str(exc), repr(exc)
    loaded, exc = finishes(lambda: cache.load("k" * 16, expect={"v": 1}))
    assert exc is None and loaded is None  # moved aside: the next run bakes again
    assert path.with_name(path.name + ".corrupt").exists() and not path.exists()


@pytest.mark.parametrize("kind", ["directory", "fifo", "symlink", "dev-zero"])
def test_table_path_that_is_not_a_file_is_refused(tmp_path, kind):
    path = tmp_path / "t.exr"
    if kind == "directory":
        path.mkdir()
    elif kind == "fifo":
        os.mkfifo(path)
    elif kind == "symlink":
        (tmp_path / "good.exr").write_bytes(_good(tmp_path))
        path.symlink_to(tmp_path / "good.exr")
    else:
        path.symlink_to("/dev/zero")
    _, exc = finishes(lambda: read_table(path))
    assert isinstance(exc, TableError), repr(exc)
