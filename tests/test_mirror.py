"""The numpy ↔ GLSL mirror is one list (precompute/shading/mirror.py): every name on it exists on
both sides, and docs/ARCHITECTURE.md shows exactly that list.

Pure Python: the GLSL is read as text (tests/drawing/test_gpu_draw.py and its neighbours run it).
"""

import importlib
import re
from pathlib import Path

import pytest

from precompute.shading import codegen, mirror

REPO = Path(__file__).resolve().parent.parent
GLSL = REPO / "glsl"


def defined_functions(source: str) -> set:
    """Names of the functions a GLSL source defines (a return type, the name, an opening bracket)."""
    source = re.sub(r"/\*.*?\*/", " ", source, flags=re.S)
    return set(
        re.findall(r"^\s*(?:[A-Za-z_]\w*)\s+([A-Za-z_]\w*)\s*\([^;]*?\)\s*\{", source, flags=re.M | re.S)
    )


@pytest.mark.parametrize("row", mirror.MIRROR, ids=lambda row: row.chunk + ":" + row.numpy[0])
def test_every_numpy_name_imports(row):
    """Every numpy function the GLSL mirror table names exists: the table that pairs shader code with its
    reference cannot point at nothing."""
    for name in row.numpy:
        module, _, attribute = f"precompute.{name}".rpartition(".")
        assert hasattr(importlib.import_module(module), attribute), (
            f"mirror.py lists {name}, which does not exist"
        )


@pytest.mark.parametrize("row", mirror.MIRROR, ids=lambda row: row.chunk + ":" + row.numpy[0])
def test_every_glsl_function_is_defined_in_its_chunk(row):
    if row.chunk == "defines":
        assert not row.glsl
        return
    if row.chunk == "generated":
        source = codegen.banded_source(codegen.MAX_L)
    else:
        path = GLSL / row.chunk
        assert path.is_file(), f"mirror.py names {row.chunk}, which glsl/ does not have"
        source = path.read_text(encoding="utf-8")
    missing = set(row.glsl) - defined_functions(source)
    assert row.glsl and not missing, f"{row.chunk} does not define {sorted(missing)} (listed in mirror.py)"


def test_the_function_finder_finds_definitions_not_calls():
    source = (
        "float tf_a(float x)\n{\n  return tf_b(x);\n}\n"
        "/* vec3 tf_c(vec3 y) { } */\nvoid tf_d(out float e[4]) {}\n"
    )
    assert defined_functions(source) == {"tf_a", "tf_d"}


def test_every_chunk_with_a_numpy_twin_is_listed():
    """A chunk of glsl/ is on the list unless it is an entry point, shared helpers or a test of its own."""
    listed = {row.chunk for row in mirror.MIRROR}
    unlisted = {
        "tf_common.glsl",
        "tf_main_frag.glsl",
        "tf_main_vert.glsl",
        "tf_background_frag.glsl",
        "tf_background_vert.glsl",
    }
    chunks = {p.name for p in GLSL.glob("*.glsl")}
    assert chunks - unlisted == listed - {"defines", "generated"}, sorted(chunks - unlisted ^ listed)


def test_the_architecture_page_shows_the_list():
    """docs/ARCHITECTURE.md's table is markdown_table() (scripts/mirror_table.py rewrites it)."""
    page = (REPO / "docs" / "ARCHITECTURE.md").read_text(encoding="utf-8")
    assert page.count(mirror.BEGIN) == 1 and page.count(mirror.END) == 1, "the table's markers"
    shown = page[page.index(mirror.BEGIN) + len(mirror.BEGIN) : page.index(mirror.END)].strip()
    assert shown == mirror.markdown_table(), "run .venv/bin/python scripts/mirror_table.py"
    assert mirror.replace_table(page) == page


def test_a_drifted_table_is_seen():
    page = f"x\n{mirror.BEGIN}\n| stale |\n{mirror.END}\ny\n"
    fixed = mirror.replace_table(page)
    assert (
        "| stale |" not in fixed and mirror.markdown_table() in fixed and fixed.endswith(f"{mirror.END}\ny\n")
    )
    with pytest.raises(ValueError, match="markers"):
        mirror.replace_table("no table here")
