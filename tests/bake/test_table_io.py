"""Baked-table files: exact round trips, half-precision bounds, refusals, and the content-keyed cache."""

import hashlib
import json
import logging
import os
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import OpenEXR
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from precompute.tables import table_io
from precompute.tables.table_cache import TableCache, default_cache_dir
from precompute.tables.table_io import (
    FORMAT_VERSION,
    Table,
    TableError,
    content_key,
    half_precision_error,
    read_table,
    write_table,
)

# IEEE half has a 10-bit mantissa: round-to-nearest errs by at most half an ulp, i.e.
# ≤ 2^-11 relative for normal numbers (|x| ≥ 2^-14) and ≤ 2^-25 absolute (half the subnormal
# spacing 2^-24) below that. These are exact bounds, not empirical ones.
HALF_REL = 2.0**-11
HALF_ABS_SUBNORMAL = 2.0**-25

ATTRS = {
    "sh_order": 8,
    "colour_space": "Linear Rec.709",
    "wavelengths_nm": [360.0, 361.5, 830.0],
    "nested": {"stack": [[1.33, 120.0], [2.4, 55.5]], "empty": [], "none": None},
    "flag": True,
    "tiny": 1e-300,
    "third": 1 / 3,
    "big_int": 2**40,  # the EXR int attribute would truncate this to 32 bits; JSON must not
    "unicode": "θ → λ ✓ 薄膜",
}


def rng_table(shape, seed=0, lo=-0.5, hi=0.5):
    return np.random.default_rng(seed).uniform(lo, hi, shape)


def rewrite(src, dst, *, header=None, drop=(), channels=None):
    """Re-encode ``src`` with OpenEXR directly: header attributes changed/dropped, pixels edited."""
    exr = OpenEXR.File(str(src), separate_channels=True)
    hdr = {k: v for k, v in exr.header().items() if k.startswith("thinfilm_sh/") and k not in drop}
    hdr.update(header or {})
    hdr.update(compression=OpenEXR.ZIP_COMPRESSION, type=OpenEXR.scanlineimage)
    chans = {name: np.array(ch.pixels) for name, ch in exr.channels().items()}
    if channels is not None:
        chans = channels(chans)
    OpenEXR.File(hdr, chans).write(str(dst))
    return dst


@pytest.fixture
def table_file(tmp_path):
    path = tmp_path / "table.exr"
    data = rng_table((3, 4, 5, 9))
    write_table(path, data, ATTRS)
    return path, data


# ----------------------------------------------------------------------------------------------
# Round trips
# ----------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "shape",
    [(9,), (1, 1), (4, 3), (2, 5, 3), (7, 33, 81, 9), (2, 3, 4, 5, 6), (3, 120)],
    ids=str,
)
def test_float_round_trip_is_bit_exact(tmp_path, shape):
    data = rng_table(shape, seed=len(shape)) * 10.0 ** np.random.default_rng(1).integers(-6, 6, shape)
    path = write_table(tmp_path / "t.exr", data, ATTRS)
    table = read_table(path)
    assert isinstance(table, Table)
    assert table.data.dtype == np.float64 and table.data.shape == shape
    assert np.array_equal(table.data, data.astype(np.float32))
    assert table.precision == "float" and table.kind == "sh_table"
    assert table.format_version == FORMAT_VERSION == 1
    assert table.attributes == ATTRS
    assert len(table.content_hash) == 64


def test_layout_last_axis_channels_then_width_then_flattened_height(tmp_path):
    """Pins the documented on-disk layout, which other tools (and the GLSL side) rely on."""
    data = rng_table((2, 3, 4, 11))
    path = write_table(tmp_path / "t.exr", data, {})
    exr = OpenEXR.File(str(path), separate_channels=True)
    names = list(exr.channels())
    assert names == [f"c{i:02d}" for i in range(11)]
    for c, name in enumerate(names):
        np.testing.assert_array_equal(
            exr.channels()[name].pixels, data.reshape(6, 4, 11)[:, :, c].astype(np.float32)
        )
    header = exr.header()
    assert header["compression"] in (OpenEXR.ZIP_COMPRESSION, OpenEXR.PIZ_COMPRESSION)
    assert header["thinfilm_sh/format_version"] == 1
    assert json.loads(header["thinfilm_sh/shape"]) == [2, 3, 4, 11]
    assert json.loads(header["thinfilm_sh/attributes"]) == {}


def test_many_channels_sort_numerically(tmp_path):
    """A table with over 99 channels keeps its channel order: names sort numerically (c007 before c100), or
    coefficients would be read into the wrong slots."""
    data = rng_table((2, 120))
    path = write_table(tmp_path / "t.exr", data, {})
    names = sorted(OpenEXR.File(str(path), separate_channels=True).channels())
    assert names == [f"c{i:03d}" for i in range(120)]
    assert np.array_equal(read_table(path).data, data.astype(np.float32))


def test_attributes_accept_numpy_and_tuples(tmp_path):
    attrs = {"order": np.int64(8), "grid": np.linspace(0.0, 1.0, 3), "pair": (1, 2.5)}
    table = read_table(write_table(tmp_path / "t.exr", np.ones((2, 3)), attrs))
    assert table.attributes == {"order": 8, "grid": [0.0, 0.5, 1.0], "pair": [1, 2.5]}
    assert type(table.attributes["order"]) is int


def test_kind_round_trip_and_check(tmp_path):
    path = write_table(tmp_path / "t.exr", np.ones((2, 3)), {}, kind="per_channel_table")
    assert read_table(path).kind == "per_channel_table"
    assert read_table(path, kind="per_channel_table").kind == "per_channel_table"
    with pytest.raises(TableError, match=r"stale or mismatched table: kind expected 'sh_table'"):
        read_table(path, kind="sh_table")


def test_table_is_immutable(table_file):
    """A table read from the cache cannot be changed in place: it is shared between materials and threads."""
    table = read_table(table_file[0])
    assert not table.data.flags.writeable
    with pytest.raises(ValueError):
        table.data[0, 0, 0, 0] = 1.0
    with pytest.raises(AttributeError):
        table.kind = "other"  # frozen dataclass


def test_overwrite_replaces_contents(tmp_path):
    """Writing a table over an older file replaces its data and header completely; no stale attribute
    survives to mislabel the new table."""
    path = tmp_path / "t.exr"
    write_table(path, np.zeros((2, 3)), {"v": 1})
    write_table(path, np.ones((4, 2)), {"v": 2})
    table = read_table(path)
    assert table.attributes == {"v": 2} and np.array_equal(table.data, np.ones((4, 2)))


# ----------------------------------------------------------------------------------------------
# Half precision
# ----------------------------------------------------------------------------------------------

half_values = st.one_of(
    st.floats(-65504.0, 65504.0, allow_nan=False, allow_infinity=False),
    st.floats(-1.0, 1.0, allow_nan=False),
    st.floats(-1e-4, 1e-4, allow_nan=False),  # around and below half's smallest normal 6.1e-5
)


@given(hnp.arrays(np.float64, hnp.array_shapes(min_dims=1, max_dims=4, max_side=6), elements=half_values))
def test_half_round_trip_within_rounding_bound(data):
    with tempfile.TemporaryDirectory() as tmp:
        table = read_table(write_table(Path(tmp) / "h.exr", data, {"p": "half"}, precision="half"))
    assert table.precision == "half"
    assert np.array_equal(table.data, data.astype(np.float16))  # exactly what half rounding gives
    err = np.abs(table.data - data)
    bound = np.maximum(HALF_REL * np.abs(data), HALF_ABS_SUBNORMAL)
    assert np.all(err <= bound), float(np.max(err / bound))
    measured = half_precision_error(data)
    assert measured.max_abs == float(err.max())
    assert measured.max_rel <= HALF_REL


def test_half_precision_error_known_values():
    # 1 + 2^-11 is the midpoint between halves 1 and 1 + 2^-10; ties-to-even rounds down to 1.
    x = 1.0 + 2.0**-11
    err = half_precision_error([x, 0.5, -2.0])
    assert err.max_abs == 2.0**-11
    assert err.max_rel == pytest.approx(2.0**-11 / x, rel=1e-15)
    assert half_precision_error([0.25, 1024.0, 0.0]) == (0.0, 0.0)
    with pytest.raises(ValueError, match="65504"):
        half_precision_error([70000.0])


def test_half_realistic_tables_error():
    """Sign-symmetric SH-like values and [0, 1] reflectances both stay within 2^-11 relative."""
    for lo, hi in ((-0.5, 0.5), (0.0, 1.0)):
        err = half_precision_error(rng_table((16, 32, 81, 9), seed=3, lo=lo, hi=hi))
        assert err.max_rel <= HALF_REL
        assert err.max_abs <= HALF_REL * max(abs(lo), abs(hi))  # half an ulp at the top binade
        assert err.max_rel > 0.9 * HALF_REL  # 1.3M samples get close to the worst case


def test_half_refuses_values_that_overflow(tmp_path):
    path = tmp_path / "h.exr"
    write_table(path, np.array([[65504.0, -65504.0]]), {}, precision="half")  # the largest finite half
    assert np.array_equal(read_table(path).data, [[65504.0, -65504.0]])
    path.unlink()
    with pytest.raises(ValueError, match=r"above half's largest finite value 65504"):
        write_table(path, np.array([[1.0, -65505.0]]), {}, precision="half")
    with pytest.raises(ValueError, match=r"would become Inf as float"):
        write_table(path, np.array([[1e39, 0.0]]), {}, precision="float")
    assert list(tmp_path.iterdir()) == []


def test_float_and_half_file_sizes(tmp_path):
    """Half pixels hold 2 bytes instead of 4; ZIP is lossless so random data barely shrinks."""
    data = rng_table((16, 32, 81, 9))
    full = os.path.getsize(write_table(tmp_path / "f.exr", data, ATTRS))
    half = os.path.getsize(write_table(tmp_path / "h.exr", data, ATTRS, precision="half"))
    raw = data.size * 4
    assert raw * 0.9 < full < raw * 1.05
    assert 0.4 * full < half < 0.55 * full


# ----------------------------------------------------------------------------------------------
# Refusals on write
# ----------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("data", "attributes", "precision", "message"),
    [
        (np.array([[1.0, np.nan]]), {}, "float", r"data must be finite"),
        (np.array([[1.0, np.inf]]), {}, "half", r"data must be finite"),
        (np.array([[1.0 + 1j]]), {}, "float", r"data must be real"),
        (np.zeros((0, 3)), {}, "float", r"empty"),
        (np.float64(1.0), {}, "float", r"at least one axis"),
        (np.ones((2, 2)), {"x": float("nan")}, "float", r"attributes must be JSON-serialisable"),
        (np.ones((2, 2)), {"x": object()}, "float", r"attributes must be JSON-serialisable"),
        (np.ones((2, 2)), {1: "int key"}, "float", r"attributes keys must be strings"),
        (np.ones((2, 2)), {}, "double", r"precision must be one of"),
    ],
)
def test_write_refuses_bad_input_before_writing(tmp_path, data, attributes, precision, message):
    with pytest.raises(ValueError, match=message):
        write_table(tmp_path / "t.exr", data, attributes, precision=precision)
    assert list(tmp_path.iterdir()) == []  # no file, no temporary left behind


def test_crash_mid_write_keeps_old_file_and_leaves_no_temp(tmp_path, monkeypatch):
    path = tmp_path / "t.exr"
    write_table(path, np.zeros((2, 3)), {"v": 1})
    before = path.read_bytes()

    class CrashingFile:
        def __init__(self, header, channels):
            pass

        def write(self, filename):
            Path(filename).write_bytes(before[: len(before) // 2])  # half a file, then die
            raise OSError("disk full")

    monkeypatch.setattr(OpenEXR, "File", CrashingFile)
    with pytest.raises(OSError, match="disk full"):
        write_table(path, np.ones((2, 3)), {"v": 2})
    monkeypatch.undo()
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.exr"]
    assert read_table(path).attributes == {"v": 1}


# ----------------------------------------------------------------------------------------------
# Refusals on read
# ----------------------------------------------------------------------------------------------


def test_missing_file_names_the_path(tmp_path):
    path = tmp_path / "nope.exr"
    with pytest.raises(FileNotFoundError, match="nope.exr"):
        read_table(path)


@pytest.mark.parametrize("cut", ["half", "header", "last_byte", "empty"])
def test_truncated_file_is_refused(table_file, cut):
    """A truncated cache file (a killed write, a full disk) is refused with an error naming the file, never
    read as a wrong table."""
    path, _ = table_file
    raw = path.read_bytes()
    keep = {"half": len(raw) // 2, "header": 40, "last_byte": len(raw) - 1, "empty": 0}[cut]
    path.write_bytes(raw[:keep])
    with pytest.raises(TableError, match=r"table\.exr.* is truncated or not an OpenEXR file"):
        read_table(path)


@pytest.mark.parametrize("magic", [False, True])
def test_garbage_bytes_are_refused(tmp_path, magic):
    """Random bytes, even behind OpenEXR's magic number, are refused with an error naming the file: a corrupt
    cache entry cannot crash Blender."""
    garbage = np.random.default_rng(7).integers(0, 256, 5000, dtype=np.uint8).tobytes()
    path = tmp_path / "garbage.exr"
    path.write_bytes((b"\x76\x2f\x31\x01" if magic else b"") + garbage)
    with pytest.raises(TableError, match=r"garbage\.exr.* is truncated or not an OpenEXR file"):
        read_table(path)


def test_plain_exr_is_not_a_table(tmp_path):
    path = tmp_path / "photo.exr"
    rgb = {c: np.zeros((4, 8), np.float32) for c in "RGB"}
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}, rgb).write(
        str(path)
    )
    with pytest.raises(TableError, match=r"photo\.exr.*'thinfilm_sh/format_version' is missing"):
        read_table(path)


@pytest.mark.parametrize(
    "attr", ["format_version", "kind", "shape", "precision", "attributes", "content_hash"]
)
def test_missing_header_attribute_is_named(table_file, tmp_path, attr):
    bad = rewrite(table_file[0], tmp_path / "bad.exr", drop=[f"thinfilm_sh/{attr}"])
    with pytest.raises(TableError, match=rf"bad\.exr.*header attribute 'thinfilm_sh/{attr}' is missing"):
        read_table(bad)


@pytest.mark.parametrize(
    ("header", "message"),
    [
        ({"thinfilm_sh/format_version": "1"}, r"'thinfilm_sh/format_version' must be an int, got str"),
        ({"thinfilm_sh/shape": 7}, r"'thinfilm_sh/shape' must be a string, got int"),
        ({"thinfilm_sh/shape": "[3, 4,"}, r"'thinfilm_sh/shape' is not valid JSON"),
        ({"thinfilm_sh/shape": "[3, 0, 5, 9]"}, r"'thinfilm_sh/shape' must list positive ints"),
        ({"thinfilm_sh/precision": "double"}, r"'thinfilm_sh/precision' must be one of"),
        ({"thinfilm_sh/attributes": "[1, 2]"}, r"'thinfilm_sh/attributes' must be a JSON object"),
        ({"thinfilm_sh/content_hash": "abc"}, r"'thinfilm_sh/content_hash' is not a sha256"),
    ],
)
def test_wrong_header_attribute_is_named(table_file, tmp_path, header, message):
    bad = rewrite(table_file[0], tmp_path / "bad.exr", header=header)
    with pytest.raises(TableError, match=message):
        read_table(bad)


def test_unsupported_format_version(table_file, tmp_path):
    """A table written by a newer format is refused with both versions named, not misread by this reader."""
    bad = rewrite(table_file[0], tmp_path / "bad.exr", header={"thinfilm_sh/format_version": 2})
    with pytest.raises(TableError, match=r"unsupported format version 2; this reader supports version 1"):
        read_table(bad)


def test_modified_pixel_fails_the_hash(table_file, tmp_path):
    def nudge(chans):
        chans["c04"][5, 3] = np.nextafter(chans["c04"][5, 3], np.float32(np.inf))  # one ulp
        return chans

    bad = rewrite(table_file[0], tmp_path / "bad.exr", channels=nudge)
    with pytest.raises(
        TableError, match=r"bad\.exr.*contents do not match the stored hash: the file is corrupt"
    ):
        read_table(bad)


def test_edited_attributes_fail_the_hash(table_file, tmp_path):
    edited = json.dumps({**ATTRS, "sh_order": 6}, sort_keys=True)
    bad = rewrite(table_file[0], tmp_path / "bad.exr", header={"thinfilm_sh/attributes": edited})
    with pytest.raises(TableError, match=r"contents do not match the stored hash"):
        read_table(bad)


def test_nan_pixel_is_refused(table_file, tmp_path):
    """A NaN in a stored table is refused (with the count) before it reaches the shader, where it would paint
    the film black or white."""

    def poison(chans):
        chans["c00"][0, 0] = np.nan
        return chans

    bad = rewrite(table_file[0], tmp_path / "bad.exr", channels=poison)
    with pytest.raises(TableError, match=r"data contains NaN or Inf in 1 entries"):
        read_table(bad)


def test_wrong_channel_names(table_file, tmp_path):
    """Channels that do not match the header's shape are refused: the data could not be laid out as the
    shader expects."""

    def rename(chans):
        chans["X"] = chans.pop("c08")
        return chans

    bad = rewrite(table_file[0], tmp_path / "bad.exr", channels=rename)
    with pytest.raises(TableError, match=r"channel names do not match shape \(3, 4, 5, 9\)"):
        read_table(bad)


def test_shape_mismatch_between_header_and_pixels(table_file, tmp_path):
    bad = rewrite(table_file[0], tmp_path / "bad.exr", header={"thinfilm_sh/shape": "[4, 4, 5, 9]"})
    with pytest.raises(TableError, match=r"shape mismatch: header shape \(4, 4, 5, 9\) needs 16×5 pixels"):
        read_table(bad)


def test_pixel_type_must_match_precision(table_file, tmp_path):
    bad = rewrite(
        table_file[0],
        tmp_path / "bad.exr",
        channels=lambda ch: {k: v.astype(np.float16) for k, v in ch.items()},
    )
    with pytest.raises(TableError, match=r"holds float16 pixels but the header says precision 'float'"):
        read_table(bad)


def test_expect_mismatch_names_key_expected_and_found(table_file):
    path, data = table_file
    ok = read_table(path, expect={"sh_order": 8, "colour_space": "Linear Rec.709", "nested": ATTRS["nested"]})
    assert np.array_equal(ok.data, data.astype(np.float32))
    with pytest.raises(
        TableError, match=r"stale or mismatched table: attribute 'sh_order' expected 6, found 8"
    ):
        read_table(path, expect={"sh_order": 6})
    with pytest.raises(
        TableError, match=r"attribute 'colour_space' expected 'ACEScg', found 'Linear Rec.709'"
    ):
        read_table(path, expect={"colour_space": "ACEScg"})
    with pytest.raises(TableError, match=r"attribute 'film' expected 'TiO2', found no such attribute"):
        read_table(path, expect={"film": "TiO2"})
    with pytest.raises(TableError, match=r"attribute 'flag' expected 1, found True"):
        read_table(path, expect={"flag": 1})  # bool and int are different facts
    assert read_table(path, expect={"wavelengths_nm": (360.0, 361.5, 830.0)}).attributes == ATTRS


# ----------------------------------------------------------------------------------------------
# Content keys and the cache
# ----------------------------------------------------------------------------------------------


def test_content_key_is_canonical_and_pinned():
    assert content_key({"a": 1}) == hashlib.sha256(b'{"a":1}').hexdigest()[:16]
    assert len(content_key(ATTRS)) == 16
    assert content_key({"a": 1, "b": [1, 2]}) == content_key({"b": (1, 2), "a": np.int64(1)})
    assert content_key({"thickness": 300.0}) != content_key({"thickness": 300.5})
    assert content_key({"sh_order": 8}) != content_key({"sh_order": 8, "colour_space": "ACEScg"})
    assert content_key({"x": 1}) != content_key({"x": True})


def test_cache_store_then_load_hits(tmp_path):
    cache = TableCache(tmp_path / "sub" / "cache")  # created on demand
    key = content_key({"film": "TiO2", "d": 300.0})
    assert cache.load(key) is None
    assert not cache.directory.exists()
    data = rng_table((4, 5, 9))
    path = cache.store(key, data, ATTRS, precision="half")
    assert path == cache.path_for(key) and path.is_file()
    table = cache.load(key, expect={"sh_order": 8})
    assert table is not None and table.precision == "half"
    assert np.array_equal(table.data, data.astype(np.float16))
    assert table.attributes == ATTRS


def test_cache_corrupt_entry_is_moved_aside_and_never_used(tmp_path, caplog):
    cache = TableCache(tmp_path)
    key = content_key({"k": 1})
    data = rng_table((3, 5, 9))
    path = cache.store(key, data, {"k": 1})
    raw = path.read_bytes()
    path.write_bytes(raw[: len(raw) // 2])
    with caplog.at_level(logging.WARNING, logger="precompute.tables.table_cache"):
        assert cache.load(key) is None
    assert not path.exists()
    aside = path.with_name(path.name + ".corrupt")
    assert aside.read_bytes() == raw[: len(raw) // 2]
    assert "truncated or not an OpenEXR file" in caplog.text and str(aside) in caplog.text
    assert cache.load(key) is None  # a miss, not the corrupt file
    cache.store(key, data, {"k": 1})
    assert np.array_equal(cache.load(key).data, data.astype(np.float32))


def test_cache_expect_mismatch_is_a_miss(tmp_path):
    cache = TableCache(tmp_path)
    cache.store("k1", np.ones((2, 3)), {"sh_order": 8})
    assert cache.load("k1", expect={"sh_order": 6}) is None
    assert not cache.path_for("k1").exists()


def test_cache_clear_and_key_validation(tmp_path):
    cache = TableCache(tmp_path)
    for key in ("a", "b"):
        cache.store(key, np.ones((2, 3)), {})
    cache.path_for("b").with_name("b.exr.corrupt").write_bytes(b"x")  # entries live in a subfolder
    (tmp_path / "unrelated.txt").write_text("keep me")
    assert cache.clear() == 3
    assert sorted(p.name for p in tmp_path.iterdir()) == ["unrelated.txt"]
    for key in ("../evil", "", "a/b", "a.exr", 5):
        with pytest.raises(ValueError, match="key must be"):
            cache.path_for(key)


def test_cache_concurrent_writers_of_one_key(tmp_path):
    cache = TableCache(tmp_path)
    candidates = [np.full((8, 16, 9), float(i)) for i in range(8)]
    with ThreadPoolExecutor(max_workers=8) as pool:
        list(pool.map(lambda d: cache.store("shared", d, {"v": float(d[0, 0, 0])}), candidates))
    table = cache.load("shared")
    assert table is not None
    assert np.array_equal(table.data, candidates[int(table.attributes["v"])])
    assert sorted(p.name for p in cache.path_for("shared").parent.iterdir()) == ["shared.exr"]  # no temps


def test_default_cache_dir_env(tmp_path, monkeypatch):
    """The cache folder follows THINFILM_SH_CACHE, then XDG_CACHE_HOME (docs/cache.md), so pipelines can
    place the cache where their farm expects it."""
    monkeypatch.setenv("THINFILM_SH_CACHE", str(tmp_path / "override"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert default_cache_dir() == tmp_path / "override"
    cache = TableCache()
    assert cache.directory == tmp_path / "override"
    cache.store("k", np.ones((2, 2)), {})
    assert cache.path_for("k").is_file() and cache.path_for("k").is_relative_to(tmp_path / "override")

    monkeypatch.delenv("THINFILM_SH_CACHE")
    assert default_cache_dir() == tmp_path / "xdg" / "thinfilm_sh"
    monkeypatch.setenv("XDG_CACHE_HOME", "relative/ignored")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.setenv("USERPROFILE", str(tmp_path / "home"))
    assert default_cache_dir() == tmp_path / "home" / ".cache" / "thinfilm_sh"


def test_module_never_imports_bpy_and_uses_relative_imports():
    source = Path(table_io.__file__).read_text(encoding="utf-8")
    assert "bpy" not in source.replace("never imports ``bpy``", "")
    assert "from precompute" not in source and "import precompute" not in source
