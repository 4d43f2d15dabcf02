"""Build the installable extension zip with OpenEXR bundled as a wheel.

    .venv/bin/python scripts/build_extension.py [--platforms linux-x64 macos-arm64 ...] [--out dist/]

Downloads the pinned wheels (requirements.txt) for each target platform from PyPI — never numpy,
which Blender ships — into ``build/wheels/``, writes a build copy of the repository with a
manifest listing them (``wheels = [...]`` and ``platforms = [...]``), and builds one zip per
platform with Blender's own extension tool (``blender_ext.py build``, shipped in the bpy
package). Nothing built is committed: ``build/`` and ``dist/`` are ignored.
"""

from __future__ import annotations

import argparse
import importlib.util
import pathlib
import re
import shutil
import subprocess
import sys

ROOT = pathlib.Path(__file__).resolve().parent.parent
#: Blender platform tag → pip --platform tags (newest first) for Python 3.13.
PLATFORMS = {
    "linux-x64": ["manylinux_2_28_x86_64", "manylinux_2_17_x86_64", "manylinux2014_x86_64"],
    "linux-arm64": ["manylinux_2_28_aarch64", "manylinux_2_17_aarch64", "manylinux2014_aarch64"],
    "macos-arm64": ["macosx_11_0_arm64", "macosx_10_15_universal2"],
    "macos-x64": ["macosx_10_15_x86_64", "macosx_10_15_universal2"],
    "windows-x64": ["win_amd64"],
}
#: numpy comes with Blender: never bundled. colour-science is not needed at run time: the colour
#: tables ship as data (precompute/data/colour/), so the zip is ≈ 82 % smaller than with it.
BUNDLED = ("OpenEXR",)


def pinned_requirements() -> list[str]:
    lines = (ROOT / "requirements.txt").read_text().splitlines()
    reqs = [line.split("#")[0].strip() for line in lines]
    return [r for r in reqs if r and any(r.lower().startswith(b.lower()) for b in BUNDLED)]


def download(platform: str, dest: pathlib.Path) -> list[pathlib.Path]:
    dest.mkdir(parents=True, exist_ok=True)
    before = set(dest.glob("*.whl"))
    cmd = [
        sys.executable,
        "-m",
        "pip",
        "download",
        "--only-binary=:all:",
        "--no-deps",
        "--python-version",
        "3.13",
        "--implementation",
        "cp",
        "-d",
        str(dest),
    ]
    for tag in PLATFORMS[platform]:
        cmd += ["--platform", tag]
    subprocess.run(cmd + pinned_requirements(), check=True)
    wheels = sorted(set(dest.glob("*.whl")) - before) or sorted(dest.glob("*.whl"))
    if any(w.name.lower().startswith("numpy") for w in wheels):
        raise SystemExit("refusing to bundle numpy: Blender ships its own")
    return wheels


def blender_ext_tool() -> pathlib.Path:
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        raise SystemExit(
            "the bpy package is needed for Blender's extension build tool (scripts/setup.sh installs it)"
        )
    hits = sorted(
        pathlib.Path(list(spec.submodule_search_locations)[0]).glob(
            "*/scripts/addons_core/bl_pkg/cli/blender_ext.py"
        )
    )
    if not hits:
        raise SystemExit("blender_ext.py not found inside the bpy package")
    return hits[0]


def build(platform: str, out: pathlib.Path) -> pathlib.Path:
    work = ROOT / "build" / platform
    if work.exists():
        shutil.rmtree(work)
    ignore = shutil.ignore_patterns(
        ".git",
        ".venv",
        "build",
        "dist",
        "out",
        "__pycache__",
        ".pytest_cache",
        ".hypothesis",
        ".ruff_cache",
        "tests",
        "benchmarks",
        "docs",
        ".ci",
    )
    shutil.copytree(ROOT, work, ignore=ignore)
    wheels = download(platform, ROOT / "build" / "wheels" / platform)
    (work / "wheels").mkdir()
    for wheel in wheels:
        shutil.copy2(wheel, work / "wheels" / wheel.name)
    manifest = (work / "blender_manifest.toml").read_text()
    listed = ", ".join(f'"./wheels/{w.name}"' for w in wheels)
    manifest = re.sub(
        r"(?m)^(type = .*)$", rf'\1\nplatforms = ["{platform}"]\nwheels = [{listed}]', manifest, count=1
    )
    (work / "blender_manifest.toml").write_text(manifest)
    out.mkdir(parents=True, exist_ok=True)
    subprocess.run(
        [
            sys.executable,
            str(blender_ext_tool()),
            "build",
            "--source-dir",
            str(work),
            "--output-dir",
            str(out),
        ],
        check=True,
    )
    built = sorted(out.glob("*.zip"), key=lambda p: p.stat().st_mtime)[-1]
    final = out / f"thinfilm_sh-{platform}.zip"
    built.replace(final)
    print(f"built {final} with {', '.join(w.name for w in wheels)}")
    return final


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--platforms", nargs="+", default=["linux-x64"], choices=sorted(PLATFORMS))
    parser.add_argument("--out", default=str(ROOT / "dist"))
    args = parser.parse_args(argv)
    for platform in args.platforms:
        build(platform, pathlib.Path(args.out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
