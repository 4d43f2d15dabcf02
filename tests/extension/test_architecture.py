"""The product's shape: no import cycles, the core never imports Blender, short files, small folders.

Every .py under precompute/ and addon/ is parsed with ``ast``; every import counts, at the top of
the module or inside a function (a local import does not make a cycle go away, it only hides
it). Relative imports are resolved against the importing module's package; ``from . import x``
is an edge to the submodule ``x`` when there is one, else to the package's ``__init__``.
Importing a submodule runs its package's ``__init__`` first, but that is not counted as an
edge (it would make every package that imports its own submodules a cycle).
"""

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]  # tests/<feature>/this file
PRODUCT = ("precompute", "addon")
#: Blender's modules: precompute/ runs standalone and must never import them.
BLENDER = {"bpy", "gpu", "mathutils", "bmesh", "gpu_extras", "bl_math", "blf", "idprop"}


def module_name(path: Path) -> str:
    parts = path.relative_to(REPO).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def product_modules() -> dict[str, Path]:
    return {module_name(p): p for top in PRODUCT for p in sorted((REPO / top).rglob("*.py"))}


def imports_of(name: str, path: Path, modules: dict) -> tuple[set, set]:
    """(product modules, other top-level packages) that ``name`` imports anywhere in its file."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    product, external = set(), set()

    def resolve(target: str):
        # the longest prefix that is a product module (``precompute.sh.windows.window`` → precompute.sh)
        parts = target.split(".")
        for i in range(len(parts), 0, -1):
            candidate = ".".join(parts[:i])
            if candidate in modules:
                return candidate
        return None

    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                hit = resolve(alias.name)
                (product.add(hit) if hit else external.add(alias.name.split(".")[0]))
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                # the repository root is the extension package: ``..precompute`` from addon/ is
                # the top-level precompute here
                base = package.split(".")
                if node.level - 1 > len(base):
                    continue
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if not target:
                continue
            for alias in node.names:
                hit = resolve(f"{target}.{alias.name}")  # a submodule, or a name in ``target``
                if hit:
                    product.add(hit)
                elif not node.level:
                    external.add(target.split(".")[0])
    product.discard(name)
    return product, external


def import_graph() -> tuple[dict, dict]:
    modules = product_modules()
    graph, external = {}, {}
    for name, path in modules.items():
        graph[name], external[name] = imports_of(name, path, modules)
    return graph, external


def find_cycle(graph: dict) -> list | None:
    """One cycle of ``graph`` as [a, b, …, a], or None (iterative depth-first search)."""
    state = dict.fromkeys(graph, 0)  # 0 new, 1 on the stack, 2 done
    for root in sorted(graph):
        if state[root]:
            continue
        stack = [(root, iter(sorted(graph[root])))]
        path = [root]
        state[root] = 1
        while stack:
            node, children = stack[-1]
            child = next(children, None)
            if child is None:
                stack.pop()
                path.pop()
                state[node] = 2
            elif state.get(child, 2) == 1:
                return path[path.index(child) :] + [child]
            elif state.get(child) == 0:
                state[child] = 1
                path.append(child)
                stack.append((child, iter(sorted(graph[child]))))
    return None


def test_the_graph_sees_every_kind_of_import():
    """Guards the parser: relative, parent-relative, function-local and ``from . import``."""
    graph, external = import_graph()
    assert "precompute.shading.policy" in graph["precompute.shading.split_sum"]  # from .policy import
    assert "precompute.world.hdri" in graph["precompute.shading.split_sum"]  # from ..world.hdri import
    assert "precompute.shading.lamps" in graph["precompute.shading.split_sum"]  # from . import lamps
    assert "precompute.effects.plans" in graph["precompute.commands.cli"]  # a function-local import
    assert "precompute.shading.variant" in graph["addon.gpu.shaders"]  # from ...precompute.shading.x
    assert "bpy" in external["addon.gpu.context"] and "numpy" in external["precompute.sh.harmonics"]


def test_precompute_has_no_import_cycle():
    graph, _ = import_graph()
    core = {
        k: {v for v in vs if v.startswith("precompute")}
        for k, vs in graph.items()
        if k.startswith("precompute")
    }
    cycle = find_cycle(core)
    assert cycle is None, "import cycle: " + " → ".join(cycle)


def test_the_product_has_no_import_cycle():
    graph, _ = import_graph()
    cycle = find_cycle(graph)
    assert cycle is None, "import cycle: " + " → ".join(cycle)


def test_precompute_never_imports_blender():
    """precompute/ imports neither bpy nor Blender's modules, so it runs in helper processes, CI without
    Blender and the command line."""
    _, external = import_graph()
    offenders = {
        name: sorted(pkgs & BLENDER)
        for name, pkgs in external.items()
        if name.startswith("precompute") and pkgs & BLENDER
    }
    assert not offenders, offenders


def test_the_cycle_finder_finds_cycles():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set(), "c": {"a", "b"}}) is None


#: The roots each size rule is enforced on: the whole product (issue 35).
CHECKED_ROOTS = ("precompute", "glsl", "addon")
MAX_LINES = 600  # one concern per file; a longer file is split by concern (issue 35; 800 before)
#: At most this many modules in one folder, counted as its .py files other than __init__.py
#: (__main__.py counts; subfolders, data and GLSL do not): more is a folder to cut by entity.
MAX_MODULES = 15


def line_counts(roots) -> dict:
    """{path: lines} of every .py and .glsl file under ``roots``."""
    return {
        str(p.relative_to(REPO)): len(p.read_text(encoding="utf-8").splitlines())
        for top in roots
        for p in sorted((REPO / top).rglob("*"))
        if p.suffix in (".py", ".glsl")
    }


def modules_per_folder(roots) -> dict:
    """{folder: number of .py files in it other than __init__.py} for every folder under ``roots``."""
    counts = {}
    for top in roots:
        for folder in [REPO / top, *sorted(p for p in (REPO / top).rglob("*") if p.is_dir())]:
            if folder.name == "__pycache__":
                continue
            counts[str(folder.relative_to(REPO))] = sum(
                1 for p in folder.glob("*.py") if p.name != "__init__.py"
            )
    return counts


def test_no_product_file_is_longer_than_600_lines():
    sizes = line_counts(CHECKED_ROOTS)
    assert sizes, "no product files found"
    too_long = {path: n for path, n in sizes.items() if n > MAX_LINES}
    assert not too_long, f"split these by concern (more than {MAX_LINES} lines): {too_long}"


def test_no_folder_holds_more_than_15_modules():
    counts = modules_per_folder(CHECKED_ROOTS)
    assert counts["precompute"] >= 1 and "precompute/shading" in counts and "addon/gpu" in counts, counts
    crowded = {folder: n for folder, n in counts.items() if n > MAX_MODULES}
    assert not crowded, f"cut these folders by entity (more than {MAX_MODULES} modules): {crowded}"


def test_the_size_rules_see_what_they_count(tmp_path, monkeypatch):
    """Guards the counters: __init__.py is not a module, __main__.py is; lines are lines."""
    (tmp_path / "pkg" / "sub").mkdir(parents=True)
    for name in ("__init__.py", "__main__.py", "a.py", "sub/__init__.py", "sub/b.py"):
        (tmp_path / "pkg" / name).write_text("x = 1\n" * 3, encoding="utf-8")
    (tmp_path / "pkg" / "c.glsl").write_text("float x;\n" * 700, encoding="utf-8")
    monkeypatch.setattr(__import__(__name__), "REPO", tmp_path)
    assert modules_per_folder(["pkg"]) == {"pkg": 2, "pkg/sub": 1}
    sizes = line_counts(["pkg"])
    assert sizes["pkg/c.glsl"] == 700 and sizes["pkg/a.py"] == 3
