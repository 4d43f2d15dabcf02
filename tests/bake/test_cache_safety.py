"""Issue 24: every file the product writes is safe, nothing planted in the cache is trusted.

Each test reproduces one case of the issue: a full disk (the OpenEXR binding returns normally
after writing nothing), outputs at a FIFO, device, symbolic link or hard link, the JSON summary
over the table, clearing a folder that holds the user's own ``.exr`` files, and entries planted
in the cache (symbolic link, FIFO, ``/dev/zero``, size bombs, deep JSON). Hangs are caught by
running the reader in a thread with a deadline, not by timing it.
"""

import errno
import json
import os
import signal
import stat
import struct
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import OpenEXR
import pytest
from _waits import finishes

from precompute.bakes import bake
from precompute.commands import cli, cli_support
from precompute.tables import atomic_write, table_cache, table_io
from precompute.tables.atomic_write import TableWriteError, write_bytes
from precompute.tables.table_cache import CacheDirError, TableCache
from precompute.tables.table_io import TableError, read_table, write_table

try:
    import resource  # POSIX: RLIMIT_FSIZE makes the kernel refuse file growth, as a full disk does
except ImportError:
    resource = None

ROOT = Path(__file__).resolve().parents[2]  # tests/<feature>/this file
POSIX_LIMITS = pytest.mark.skipif(resource is None or not hasattr(signal, "SIGXFSZ"), reason="POSIX only")
IS_ROOT = hasattr(os, "geteuid") and os.geteuid() == 0


def is_char_device(path) -> bool:
    return stat.S_ISCHR(os.lstat(path).st_mode)


def no_temporaries(folder: Path) -> bool:
    return not [p for p in folder.iterdir() if p.name.endswith(".tmp")]


def small_table(value=1.0):
    return np.full((2, 3, 9), value)


# ----------------------------------------------------------------------------------------------
# A full disk
# ----------------------------------------------------------------------------------------------


def binding_that_writes(how):
    """An ``OpenEXR.File`` stand-in whose ``write`` returns normally after a short write."""
    real = OpenEXR.File

    class ShortWrite:
        def __init__(self, header, channels):
            self.inner = real(header, channels)

        def write(self, filename):
            self.inner.write(filename)
            raw = Path(filename).read_bytes()
            Path(filename).write_bytes(
                {"nothing": b"", "half": raw[: len(raw) // 2], "junk": raw + b"x"}[how]
            )

    return ShortWrite


@pytest.mark.parametrize("how", ["nothing", "half", "junk"])
def test_full_disk_keeps_the_previous_table_and_names_the_path(tmp_path, monkeypatch, how):
    """The binding returns normally after writing 0 bytes on a full disk: the write must fail."""
    path = tmp_path / "good.exr"
    write_table(path, small_table(1.0), {"v": 1})
    before = path.read_bytes()
    monkeypatch.setattr(OpenEXR, "File", binding_that_writes(how))
    with pytest.raises(TableWriteError) as caught:
        write_table(path, small_table(2.0), {"v": 2})
    monkeypatch.undo()
    message = str(caught.value)
    assert str(path) in message and "previous file is unchanged" in message
    assert caught.value.filename == str(path)
    assert path.read_bytes() == before and read_table(path).attributes == {"v": 1}
    assert no_temporaries(tmp_path)


def test_full_disk_on_a_new_path_leaves_nothing(tmp_path, monkeypatch):
    monkeypatch.setattr(OpenEXR, "File", binding_that_writes("nothing"))
    with pytest.raises(TableWriteError, match=r"new\.exr.*empty.*nothing was written"):
        write_table(tmp_path / "new.exr", small_table())
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("where", "code"),
    [("mkstemp", errno.EACCES), ("fsync", errno.EDQUOT), ("replace", errno.EROFS), ("fsync", errno.ENOSPC)],
)
def test_every_write_failure_is_a_clear_error(tmp_path, monkeypatch, where, code):
    path = tmp_path / "t.exr"
    write_table(path, small_table(1.0), {"v": 1})
    before = path.read_bytes()

    def fail(*args, **kwargs):
        raise OSError(code, os.strerror(code))

    target = {"mkstemp": (atomic_write.tempfile, "mkstemp"), "fsync": (atomic_write, "_fsync_file")}.get(
        where, (atomic_write, "replace_file")
    )
    monkeypatch.setattr(*target, fail)
    for call in (lambda: write_table(path, small_table(2.0)), lambda: write_bytes(path, b"{}")):
        with pytest.raises(TableWriteError) as caught:
            call()
        assert caught.value.errno == code and isinstance(caught.value, OSError)
        assert str(path) in str(caught.value) and os.strerror(code) in str(caught.value)
    monkeypatch.undo()
    assert path.read_bytes() == before and no_temporaries(tmp_path)


FULL_DISK_SCRIPT = textwrap.dedent(
    """
    import resource, signal, sys
    import numpy as np
    from precompute.tables import atomic_write, table_io
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails with EFBIG
    resource.setrlimit(resource.RLIMIT_FSIZE, (0, resource.getrlimit(resource.RLIMIT_FSIZE)[1]))
    calls = {
        "table": lambda: table_io.write_table(sys.argv[1], np.full((2, 3, 9), 2.0), {"v": 2}),
        "json": lambda: atomic_write.write_bytes(sys.argv[2], b'{"v": 2}'),
    }
    for name, call in calls.items():
        try:
            call()
            print(name, "written")
        except atomic_write.TableWriteError as exc:
            print(name, "refused:", exc)
    """
)


def no_file_growth():
    """preexec_fn: no regular file may grow in the child (the kernel's own "disk full")."""
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (0, resource.getrlimit(resource.RLIMIT_FSIZE)[1]))


@POSIX_LIMITS
def test_full_disk_for_real_in_a_child_process(tmp_path):
    """RLIMIT_FSIZE = 0: the kernel refuses every byte, as a full disk does; the binding still
    returns normally for a small table (the case of the issue)."""
    table, summary = tmp_path / "good.exr", tmp_path / "good.json"
    write_table(table, small_table(1.0), {"v": 1})
    summary.write_text('{"v": 1}')
    before = table.read_bytes()
    run = subprocess.run(
        [sys.executable, "-c", FULL_DISK_SCRIPT, str(table), str(summary)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert run.returncode == 0, run.stderr
    lines = run.stdout.splitlines()
    assert lines[0].startswith(f"table refused: could not write {str(table)!r}")
    assert lines[1].startswith(f"json refused: could not write {str(summary)!r}")
    assert table.read_bytes() == before and summary.read_text() == '{"v": 1}'
    assert no_temporaries(tmp_path)


@pytest.mark.skipif(not IS_ROOT, reason="mounting a small tmpfs needs root")
def test_full_disk_on_a_real_small_tmpfs(tmp_path):
    """Optional: a genuinely full file system, where the machine allows mounting one."""
    mount = tmp_path / "small"
    mount.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(mount)]).returncode:
        pytest.skip("cannot mount a tmpfs here")
    try:
        path = mount / "good.exr"
        write_table(path, small_table(1.0), {"v": 1})
        before = path.read_bytes()
        with open(mount / "filler", "wb") as filler, pytest.raises(OSError):
            while True:
                filler.write(b"\0" * 4096)
                filler.flush()
        with pytest.raises(TableWriteError, match=rf"{path.name}.*previous file is unchanged"):
            write_table(path, small_table(2.0), {"v": 2})
        assert path.read_bytes() == before and no_temporaries(mount)
    finally:
        subprocess.run(["umount", "-l", str(mount)], check=False)


# ----------------------------------------------------------------------------------------------
# Destinations that must not be replaced
# ----------------------------------------------------------------------------------------------


def plant_destination(kind, tmp_path) -> Path:
    """A destination that is not a plain regular file; /dev/null itself is never passed."""
    path = tmp_path / f"{kind}.exr"
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "symlink_to_dev_null":
        path.symlink_to("/dev/null")
    elif kind == "symlink_to_file":
        (tmp_path / "target.exr").write_bytes(b"the user's file")
        path.symlink_to(tmp_path / "target.exr")
    elif kind == "device":
        try:  # a character device node of our own, in tmp: harmless even if it were replaced
            os.mknod(path, 0o600 | stat.S_IFCHR, os.makedev(1, 3))
        except (PermissionError, AttributeError):
            pytest.skip("cannot create a device node here")
    elif kind == "hard_link":
        (tmp_path / "other.exr").write_bytes(b"the user's file")
        os.link(tmp_path / "other.exr", path)
    elif kind == "directory":
        path.mkdir()
    return path


DESTINATIONS = ["fifo", "symlink_to_dev_null", "symlink_to_file", "device", "hard_link", "directory"]


def snapshot(path: Path):
    st = os.lstat(path)
    return (st.st_mode, st.st_ino, st.st_nlink, os.readlink(path) if stat.S_ISLNK(st.st_mode) else None)


@pytest.mark.parametrize("kind", DESTINATIONS)
def test_writes_refuse_a_destination_that_is_not_a_regular_file(tmp_path, kind):
    path = plant_destination(kind, tmp_path)
    before = snapshot(path)
    for call in (
        lambda: write_table(path, small_table()),
        lambda: write_bytes(path, b"{}"),
        lambda: atomic_write.write_file(path, lambda tmp: Path(tmp).write_bytes(b"x")),
    ):
        _, exc = finishes(call)
        assert isinstance(exc, TableWriteError), exc
        assert str(path) in str(exc) and "refusing to write" in str(exc)
    assert snapshot(path) == before
    assert is_char_device("/dev/null")
    for other in ("target.exr", "other.exr"):
        if (tmp_path / other).exists():
            assert (tmp_path / other).read_bytes() == b"the user's file"
    assert no_temporaries(tmp_path)


class FakeBake:
    """What cli.cmd_bake uses of a bake result, without baking (these tests are about files)."""

    data = np.linspace(0.0, 1.0, 2 * 3 * 4 * 9).reshape(2, 3, 4, 9)

    def attributes(self):
        return {"kind": "sh_table", "fake": True}

    def summary(self):
        return {"shape": list(self.data.shape)}


@pytest.fixture
def fake_bake(monkeypatch):
    monkeypatch.setattr(bake, "bake", lambda material, progress=None: FakeBake())


@pytest.fixture
def no_bake(monkeypatch):
    def refuse(*args, **kwargs):
        raise AssertionError("the destination should have been refused before baking")

    monkeypatch.setattr(bake, "bake", refuse)


BAKE = ["bake", "--preset", "soap_film", "--quiet"]


@pytest.mark.parametrize("kind", DESTINATIONS)
def test_cli_bake_out_at_a_special_file_is_refused_before_baking(tmp_path, capsys, no_bake, kind):
    path = plant_destination(kind, tmp_path)
    before = snapshot(path)
    code, exc = finishes(lambda: cli.main([*BAKE, "--out", str(path), "--json", str(tmp_path / "s.json")]))
    assert exc is None and code == 2
    assert str(path) in capsys.readouterr().err
    assert snapshot(path) == before and is_char_device("/dev/null")
    assert not (tmp_path / "s.json").exists()


def test_cli_bake_json_at_a_fifo_is_refused_before_baking(tmp_path, capsys, no_bake):
    fifo = plant_destination("fifo", tmp_path)
    code, _ = finishes(lambda: cli.main([*BAKE, "--out", str(tmp_path / "t.exr"), "--json", str(fifo)]))
    assert code == 2 and str(fifo) in capsys.readouterr().err
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode) and not (tmp_path / "t.exr").exists()


@pytest.mark.parametrize("kind", ["fifo", "symlink_to_dev_null"])
def test_cli_render_out_at_a_special_file_is_refused_before_rendering(tmp_path, capsys, no_bake, kind):
    path = plant_destination(kind, tmp_path)
    png = path.with_suffix(".png")
    os.replace(path, png)  # the PNG is --out; its .exr sibling is checked as well
    before = snapshot(png)
    code, _ = finishes(lambda: cli.main(["render", "--preset", "soap_film", "--quiet", "--out", str(png)]))
    assert code == 2 and str(png) in capsys.readouterr().err
    assert snapshot(png) == before and is_char_device("/dev/null")


@pytest.mark.parametrize("name", ["render.exr", "render.EXR"])
def test_cli_render_out_naming_an_exr_is_refused(tmp_path, capsys, no_bake, name):
    out = tmp_path / name
    assert cli.main(["render", "--preset", "soap_film", "--quiet", "--out", str(out)]) == 2
    assert "give --out a .png path" in capsys.readouterr().err and not out.exists()


def test_cli_out_json_keeps_the_table_and_the_summary(tmp_path, fake_bake):
    out = tmp_path / "x.json"
    assert cli.main([*BAKE, "--out", str(out)]) == 0
    table = read_table(out)
    assert np.array_equal(table.data, FakeBake.data.astype(np.float32))
    summary = json.loads((tmp_path / "x.json.json").read_text())
    assert summary["output"] == str(out) and summary["file_bytes"] == out.stat().st_size
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.json", "x.json.json"]


def test_cli_json_and_out_naming_one_file_is_refused(tmp_path, capsys, no_bake):
    same = tmp_path / "same.exr"
    assert cli.main([*BAKE, "--out", str(same), "--json", str(same)]) == 2
    assert "--json and --out both name" in capsys.readouterr().err and not same.exists()
    other = tmp_path / "sub" / ".." / "same.exr"  # the same file spelled differently
    assert cli.main([*BAKE, "--out", str(same), "--json", str(other)]) == 2


def test_cli_default_summary_sits_beside_the_table(tmp_path, fake_bake):
    assert cli.main([*BAKE, "--out", str(tmp_path / "soap.exr")]) == 0
    assert cli.main([*BAKE, "--out", str(tmp_path / "T.JSON")]) == 0  # one file on macOS and Windows
    assert sorted(p.name for p in tmp_path.iterdir()) == ["T.JSON", "T.JSON.json", "soap.exr", "soap.json"]


def test_cli_full_disk_fails_and_keeps_the_previous_table(tmp_path, monkeypatch, capsys, fake_bake):
    out, summary = tmp_path / "good.exr", tmp_path / "good.json"
    assert cli.main([*BAKE, "--out", str(out)]) == 0
    before, summary_before = out.read_bytes(), summary.read_bytes()
    monkeypatch.setattr(OpenEXR, "File", binding_that_writes("nothing"))
    assert cli.main([*BAKE, "--out", str(out)]) == cli_support.EXIT_IO  # a write failed during work
    err = capsys.readouterr().err
    assert f"could not write {str(out)!r}" in err and "previous file is unchanged" in err
    assert out.read_bytes() == before and summary.read_bytes() == summary_before
    assert no_temporaries(tmp_path)


@POSIX_LIMITS
def test_cli_full_disk_for_real_in_a_child_process(tmp_path):
    """The issue's reproduction: ``bake --out good.exr`` on a full disk replaced a valid table with
    0 bytes and exited 0. Here the kernel refuses every byte (RLIMIT_FSIZE = 0) in a real bake."""
    out = tmp_path / "good.exr"
    write_table(out, small_table(1.0), {"v": 1})
    before = out.read_bytes()
    material = ["--film-index", "1.33", "--thickness", "300", "--substrate", "1.5"]
    quality = ["--sh-order", "2", "--view-samples", "2", "--wavelengths", "16"]
    run = subprocess.run(
        [sys.executable, "-m", "precompute", "bake", *material, *quality, "--quiet", "--out", str(out)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
        preexec_fn=no_file_growth,
    )
    assert run.returncode != 0
    assert f"could not write {str(out)!r}" in run.stderr and "Traceback" not in run.stderr
    assert out.read_bytes() == before and not out.with_suffix(".json").exists()
    assert no_temporaries(tmp_path)


# ----------------------------------------------------------------------------------------------
# Entries planted in the cache
# ----------------------------------------------------------------------------------------------


def exr_attribute(name: str, type_name: str, value: bytes) -> bytes:
    return name.encode() + b"\0" + type_name.encode() + b"\0" + struct.pack("<i", len(value)) + value


def header_only_exr(width: int, height: int, channels: int, strings: dict) -> bytes:
    """A hand-made OpenEXR header (no pixels) declaring a ``width`` × ``height`` data window."""
    chlist = b"".join(
        f"c{i:02d}".encode() + b"\0" + struct.pack("<iB3xii", 2, 0, 1, 1) for i in range(channels)
    )
    window = struct.pack("<4i", 0, 0, width - 1, height - 1)
    attributes = [
        exr_attribute("channels", "chlist", chlist + b"\0"),
        exr_attribute("compression", "compression", bytes([3])),
        exr_attribute("dataWindow", "box2i", window),
        exr_attribute("displayWindow", "box2i", window),
        exr_attribute("lineOrder", "lineOrder", b"\0"),
        exr_attribute("pixelAspectRatio", "float", struct.pack("<f", 1.0)),
        exr_attribute("screenWindowCenter", "v2f", struct.pack("<2f", 0.0, 0.0)),
        exr_attribute("screenWindowWidth", "float", struct.pack("<f", 1.0)),
        exr_attribute("thinfilm_sh/format_version", "int", struct.pack("<i", 1)),
        *(exr_attribute(k, "string", v.encode()) for k, v in strings.items()),
    ]
    return b"\x76\x2f\x31\x01" + struct.pack("<i", 2) + b"".join(attributes) + b"\0" + bytes(64)


def rewrite_header(src: Path, dst: Path, **strings) -> None:
    """Re-encode a valid table with some ``thinfilm_sh/*`` string attributes replaced."""
    exr = OpenEXR.File(str(src), separate_channels=True)
    header = {k: v for k, v in exr.header().items() if k.startswith("thinfilm_sh/")}
    header.update({f"thinfilm_sh/{k}": v for k, v in strings.items()})
    header.update(compression=OpenEXR.ZIP_COMPRESSION, type=OpenEXR.scanlineimage)
    OpenEXR.File(header, {n: np.array(c.pixels) for n, c in exr.channels().items()}).write(str(dst))


def plant_entry(kind: str, path: Path, tmp_path: Path) -> None:
    elsewhere = tmp_path / "elsewhere.exr"
    write_table(elsewhere, small_table(), {"v": 1})
    if kind == "symlink_to_a_valid_table":
        path.symlink_to(elsewhere)
    elif kind == "fifo":
        os.mkfifo(path)
    elif kind == "link_to_dev_zero":
        path.symlink_to("/dev/zero")
    elif kind == "directory":
        path.mkdir()
    elif kind == "1e10_channels":
        rewrite_header(elsewhere, path, shape="[10000000000]")
    elif kind == "2e9_view_samples_shape":
        rewrite_header(elsewhere, path, shape="[1, 2000000000, 3, 9]")
    elif kind == "2e9_view_samples_window":
        raw = header_only_exr(5, 2_000_000_000, 9, {"thinfilm_sh/shape": "[1, 2000000000, 5, 9]"})
        assert len(raw) < 1024  # the "1 KB header"
        path.write_bytes(raw)
    elif kind == "1e4_channels_window":
        path.write_bytes(header_only_exr(1, 1, 10_000, {"thinfilm_sh/shape": "[10000]"}))
    elif kind == "50000_deep_json":
        rewrite_header(elsewhere, path, attributes="[" * 50_000 + "]" * 50_000)
    else:
        raise AssertionError(kind)


PLANTED = [
    "symlink_to_a_valid_table",
    "fifo",
    "link_to_dev_zero",
    "directory",
    "1e10_channels",
    "2e9_view_samples_shape",
    "2e9_view_samples_window",
    "1e4_channels_window",
    "50000_deep_json",
]


@pytest.mark.parametrize("kind", PLANTED)
def test_planted_entry_is_refused_quickly_and_quarantined(tmp_path, kind):
    cache = TableCache(tmp_path / "cache")
    cache.store("other", small_table(), {"v": 0})  # creates the cache's folders
    key = "a" * 64
    path = cache.path_for(key)
    plant_entry(kind, path, tmp_path)

    _, exc = finishes(lambda: read_table(path))
    assert isinstance(exc, TableError), repr(exc)  # never RecursionError, MemoryError, OSError
    assert str(path) in str(exc)

    loaded, exc = finishes(lambda: cache.load(key, expect={"v": 1}))
    assert exc is None and loaded is None
    assert not os.path.lexists(path)
    assert os.path.lexists(path.with_name(path.name + ".corrupt"))  # moved aside, not followed
    assert is_char_device("/dev/zero") and read_table(tmp_path / "elsewhere.exr").attributes == {"v": 1}

    cache.store(key, small_table(3.0), {"v": 1})  # the next run re-bakes instead of failing again
    assert cache.load(key, expect={"v": 1}) is not None


def test_reader_refuses_devices_without_reading_them():
    _, exc = finishes(lambda: read_table("/dev/zero"))
    assert isinstance(exc, TableError) and "character device" in str(exc)


def test_writer_refuses_what_the_reader_would(tmp_path):
    with pytest.raises(ValueError, match="beyond what a table file may hold"):
        write_table(tmp_path / "t.exr", np.ones(table_io.MAX_CHANNELS + 1))
    assert list(tmp_path.iterdir()) == []


# ----------------------------------------------------------------------------------------------
# Clearing
# ----------------------------------------------------------------------------------------------


def test_clear_deletes_only_the_caches_own_files(tmp_path):
    """The folder is the user's (their HDRIs live there): only tagged entries in the subfolder go."""
    folder = tmp_path / "my_project"
    folder.mkdir()
    rgb = {c: np.full((4, 8), 0.5, np.float32) for c in "RGB"}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    OpenEXR.File(header, rgb).write(str(folder / "studio.exr"))  # the user's HDRI
    (folder / "notes.txt").write_text("keep")
    cache = TableCache(folder)
    for key in ("k1", "b" * 64):
        cache.store(key, small_table(), {"key": key})
    tables = cache.tables_dir
    write_table(tables / ("c" * 64 + ".exr"), small_table(), {})  # a table, but not the cache's
    OpenEXR.File(header, rgb).write(str(tables / ("d" * 64 + ".exr")))  # key-like name, no tag
    OpenEXR.File(header, rgb).write(str(tables / "My HDRI.exr"))
    (tmp_path / "outside.exr").write_bytes(b"user data")
    (tables / ("e" * 64 + ".exr")).symlink_to(tmp_path / "outside.exr")
    mislabelled = cache.path_for("k2")
    cache.store("k3", small_table(), {})
    os.replace(cache.path_for("k3"), mislabelled)  # tagged k3 under the name k2: not ours to delete

    assert cache.clear() == 2
    assert sorted(p.name for p in folder.iterdir()) == ["notes.txt", "studio.exr", TableCache.SUBFOLDER]
    assert sorted(p.name for p in tables.iterdir()) == sorted(
        ["c" * 64 + ".exr", "d" * 64 + ".exr", "My HDRI.exr", "e" * 64 + ".exr", "k2.exr"]
    )
    assert (tmp_path / "outside.exr").read_bytes() == b"user data"
    assert OpenEXR.File(str(folder / "studio.exr")).header()["compression"] == OpenEXR.ZIP_COMPRESSION


def test_clear_removes_quarantined_entries_and_the_empty_subfolder(tmp_path):
    folder = tmp_path / "f"
    cache = TableCache(folder)
    cache.store("k", small_table(), {})
    cache.path_for("k").write_bytes(b"corrupt")
    assert cache.load("k") is None
    assert cache.clear() == 1  # the .corrupt file
    assert list(folder.iterdir()) == [] and folder.is_dir()
    assert cache.clear() == 0


# ----------------------------------------------------------------------------------------------
# The cache directory
# ----------------------------------------------------------------------------------------------


@pytest.fixture
def xdg(tmp_path, monkeypatch):
    """The default cache directory, inside tmp_path."""
    monkeypatch.delenv("THINFILM_SH_CACHE", raising=False)
    monkeypatch.delenv("THINFILM_SH_CACHE_MAX_BYTES", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    return tmp_path / "xdg" / "thinfilm_sh"


def test_default_cache_dir_is_created_private(xdg):
    cache = TableCache()
    assert cache.directory == xdg and cache.private
    cache.store("k", small_table(), {})
    for folder in (xdg, cache.tables_dir):
        st = os.lstat(folder)
        assert stat.S_ISDIR(st.st_mode) and stat.S_IMODE(st.st_mode) == 0o700
        assert st.st_uid == os.geteuid()


def test_env_var_names_the_cache_everywhere(tmp_path, monkeypatch):
    monkeypatch.setenv("THINFILM_SH_CACHE", str(tmp_path / "chosen"))
    cache = TableCache()
    assert cache.directory == tmp_path / "chosen" and not cache.private
    cache.store("k", small_table(), {})
    assert cache.path_for("k").is_file() and cache.path_for("k").is_relative_to(tmp_path / "chosen")


@pytest.mark.parametrize("which", ["default", "named", "subfolder"])
def test_symlinked_cache_dir_is_refused(tmp_path, xdg, which):
    target = tmp_path / "someone_elses"
    target.mkdir()
    if which == "default":
        xdg.parent.mkdir()
        xdg.symlink_to(target)
        cache = TableCache()
    elif which == "named":
        (tmp_path / "link").symlink_to(target)
        cache = TableCache(tmp_path / "link")
    else:
        cache = TableCache(tmp_path / "real")
        cache.directory.mkdir()
        cache.tables_dir.symlink_to(target)
    for call in (lambda: cache.store("k", small_table()), lambda: cache.load("k"), cache.clear):
        with pytest.raises(CacheDirError, match="is a symbolic link: refused"):
            call()
    assert list(target.iterdir()) == []


@pytest.mark.skipif(not IS_ROOT, reason="giving a directory to another uid needs root")
@pytest.mark.parametrize("which", ["default", "named", "subfolder"])
def test_foreign_owned_cache_dir_is_refused(tmp_path, xdg, which):
    foreign = {
        "default": xdg,
        "named": tmp_path / "shared",
        "subfolder": tmp_path / "c" / TableCache.SUBFOLDER,
    }
    folder = foreign[which]
    folder.mkdir(parents=True, mode=0o700)
    os.chown(folder, 4242, 4242)
    cache = TableCache() if which == "default" else TableCache(folder if which == "named" else folder.parent)
    for call in (lambda: cache.store("k", small_table()), lambda: cache.load("k"), cache.clear):
        with pytest.raises(CacheDirError, match=r"belongs to uid 4242, not to you"):
            call()
    assert list(folder.iterdir()) == []


def test_writable_by_others(tmp_path, xdg):
    """The default directory must not be writable by others; a directory the user names may be
    (they chose to share it), but the cache's own subfolder never is."""
    xdg.mkdir(parents=True)
    os.chmod(xdg, 0o777)
    with pytest.raises(CacheDirError, match="writable by other users"):
        TableCache().store("k", small_table())
    shared = tmp_path / "team"
    shared.mkdir()
    os.chmod(shared, 0o775)
    cache = TableCache(shared)
    cache.store("k", small_table())
    assert stat.S_IMODE(os.lstat(cache.tables_dir).st_mode) == 0o700
    os.chmod(cache.tables_dir, 0o777)
    with pytest.raises(CacheDirError, match="writable by other users"):
        cache.load("k")


# ----------------------------------------------------------------------------------------------
# Eviction
# ----------------------------------------------------------------------------------------------


def age(path: Path, seconds_ago: float) -> None:
    t = os.stat(path).st_mtime - seconds_ago
    os.utime(path, (t, t))


def test_eviction_keeps_the_most_recently_used_under_the_limit(tmp_path):
    probe = TableCache(tmp_path / "probe")
    size = probe.store("p", small_table(), {"key": "k0"}).stat().st_size
    cache = TableCache(tmp_path / "c", max_bytes=int(2.5 * size))
    for i in range(4):
        cache.store(f"k{i}", small_table(), {"key": "k0"})  # equal sizes
        age(cache.path_for(f"k{i}"), 100 - i)  # k0 oldest … k3 newest
    names = sorted(p.name for p in cache.tables_dir.iterdir())
    assert names == ["k2.exr", "k3.exr"] and cache.size_bytes() <= cache.max_bytes

    assert cache.load("k2") is not None  # a hit makes k2 the most recently used
    cache.store("k4", small_table(), {"key": "k0"})
    assert sorted(p.name for p in cache.tables_dir.iterdir()) == ["k2.exr", "k4.exr"]


def test_eviction_keeps_the_new_entry_and_spares_foreign_files(tmp_path):
    cache = TableCache(tmp_path / "c", max_bytes=10)  # smaller than any table
    cache.store("old", small_table())
    foreign = cache.tables_dir / ("f" * 64 + ".exr")
    write_table(foreign, small_table(), {})  # untagged: not the cache's to delete
    age(foreign, 50)
    cache.store("new", small_table())
    assert sorted(p.name for p in cache.tables_dir.iterdir()) == sorted([foreign.name, "new.exr"])


def test_eviction_limit_from_the_environment(monkeypatch, tmp_path):
    assert TableCache(tmp_path).max_bytes == table_cache.DEFAULT_CACHE_MAX_BYTES == 2 * 1024**3
    for text, expected in (("1048576", 2**20), ("500M", 500 * 2**20), ("2GiB", 2 * 2**30), ("0", 0)):
        monkeypatch.setenv("THINFILM_SH_CACHE_MAX_BYTES", text)
        assert TableCache(tmp_path).max_bytes == expected
    assert TableCache(tmp_path, max_bytes=123).max_bytes == 123  # the argument wins
    monkeypatch.setenv("THINFILM_SH_CACHE_MAX_BYTES", "lots")
    with pytest.raises(ValueError, match="THINFILM_SH_CACHE_MAX_BYTES"):
        TableCache(tmp_path)
