"""The extension registered in this process, and the scene: tori on a grid, the film, the World."""

from __future__ import annotations

import importlib
import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from .. import common
from .config import AUTOMATIC_ROUGHNESS, BASELINE_ID, EXTENSION_ID, FILM, HDRI, roughness_cases


# ----------------------------------------------------------------------------------------------
# The extension in this process
# ----------------------------------------------------------------------------------------------
class Extension:
    """The repository imported as the extension package (``thinfilm_sh``) and registered."""

    def __init__(self):
        import bpy

        self.root = Path(tempfile.mkdtemp(prefix="tf_viewport_bench_"))
        os.symlink(common.ROOT, self.root / EXTENSION_ID, target_is_directory=True)
        sys.path.insert(0, str(self.root))
        self.package = importlib.import_module(EXTENSION_ID)
        self.package.register()
        for dotted in (
            "addon.drawing.scene_draw",
            "addon.materials.props",
            "addon.materials.conversion",
            "addon.headless.headless",
            "addon.headless.render",
        ):
            setattr(self, dotted.rpartition(".")[2], importlib.import_module(f"{EXTENSION_ID}.{dotted}"))
        self.gpu = common.gpu_layer(EXTENSION_ID)
        self.gpu.context.ensure_gpu_context()
        bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
        self.package.register()  # harmless when registered; the file load cleared the caches

    def baseline(self, rev: str):
        """The draw module of git revision ``rev`` (``addon.gpu.draw``, ``addon.gpu_draw`` before the
        GPU layer was a package) as a second package (a detached worktree)."""
        tree = self.root / "baseline_tree"
        subprocess.run(
            ["git", "worktree", "add", "--detach", str(tree), rev],
            cwd=common.ROOT,
            check=True,
            capture_output=True,
        )
        os.symlink(tree, self.root / BASELINE_ID, target_is_directory=True)
        name = "addon.gpu.draw" if (tree / "addon" / "gpu" / "draw.py").is_file() else "addon.gpu_draw"
        module = importlib.import_module(f"{BASELINE_ID}.{name}")
        commit = subprocess.run(
            ["git", "log", "-1", "--format=%h %s", rev], cwd=common.ROOT, capture_output=True, text=True
        ).stdout.strip()
        return module, tree, commit

    def remove_baseline(self, tree) -> None:
        subprocess.run(
            ["git", "worktree", "remove", "--force", str(tree)],
            cwd=common.ROOT,
            check=False,
            capture_output=True,
        )


# ----------------------------------------------------------------------------------------------
# The scene
# ----------------------------------------------------------------------------------------------
def torus_mesh(name: str, triangles: int, major: float, minor: float):
    """A smooth-shaded torus of quads with about ``triangles`` triangles (numpy + foreach_set)."""
    import bpy

    quads = max(triangles // 2, 8)
    nv = max(int(round(math.sqrt(quads / 2.5))), 3)
    nu = max(int(round(quads / nv)), 3)
    u = np.arange(nu) * (2 * np.pi / nu)
    v = np.arange(nv) * (2 * np.pi / nv)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    ring = major + minor * np.cos(vv)
    co = np.stack([ring * np.cos(uu), ring * np.sin(uu), minor * np.sin(vv)], -1).reshape(-1, 3)
    i = np.arange(nu)[:, None]
    j = np.arange(nv)[None, :]
    i1, j1 = (i + 1) % nu, (j + 1) % nv
    corners = np.stack([i * nv + j, i1 * nv + j, i1 * nv + j1, i * nv + j1], -1).reshape(-1, 4)
    mesh = bpy.data.meshes.new(name)
    mesh.vertices.add(co.shape[0])
    mesh.vertices.foreach_set("co", co.astype(np.float32).ravel())
    mesh.loops.add(corners.size)
    mesh.loops.foreach_set("vertex_index", corners.astype(np.int32).ravel())
    mesh.polygons.add(corners.shape[0])
    mesh.polygons.foreach_set("loop_start", np.arange(0, corners.size, 4, dtype=np.int32))
    mesh.update(calc_edges=True)
    mesh.shade_smooth()
    return mesh


class Scene:
    """One bpy scene: the World, one film material per (l_max, case), tori and a camera."""

    def __init__(self, ext: Extension):
        import bpy

        self.ext = ext
        self.scene = bpy.context.scene
        self.scene.name = "viewport benchmark"
        self._world()
        self.materials: dict[tuple[int, str], object] = {}
        self.objects: list = []
        self.layout = (0, 0)
        cam_data = bpy.data.cameras.new("Camera")
        cam_data.lens = 50.0
        cam_data.clip_start, cam_data.clip_end = 0.1, 100.0
        self.camera = bpy.data.objects.new("Camera", cam_data)
        self.scene.collection.objects.link(self.camera)
        self.scene.camera = self.camera
        self.space, self.region = ext.render._view3d_for_depth()
        if self.space is None:
            raise RuntimeError("no VIEW_3D area in bpy.data.screens: cannot draw Workbench")
        shading = self.space.shading
        shading.type = "SOLID"
        self.space.overlay.show_overlays = False
        self.workbench_settings = (
            f"light {shading.light}, colour {shading.color_type}, outline {shading.show_object_outline},"
            f" cavity {shading.show_cavity}, shadows {shading.show_shadows}, X-ray {shading.show_xray},"
            f" viewport anti-aliasing {self.scene.display.viewport_aa}, overlays off"
        )

    def _world(self) -> None:
        import bpy

        folder = bpy.utils.system_resource("DATAFILES", path="studiolights/world")
        world = bpy.data.worlds.new(f"Studio {HDRI}")
        tree = world.node_tree
        background = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeBackground")
        env = tree.nodes.new("ShaderNodeTexEnvironment")
        env.image = bpy.data.images.load(os.path.join(folder, f"{HDRI}.exr"), check_existing=True)
        tree.links.new(env.outputs["Color"], background.inputs["Color"])
        self.scene.world = world

    def material(self, l_max: int, case: str = "sh"):
        """The film material at ``l_max`` and roughness of ``case`` (made once)."""
        import bpy

        key = (int(l_max), case)
        if key not in self.materials:
            mat = bpy.data.materials.new(f"Film l{l_max} {case}")
            tf = mat.thinfilm_sh
            self.ext.conversion.fill_from_material(tf, FILM.with_(roughness=roughness_cases()[case]))
            tf.sh_order = str(int(l_max))
            tf.enabled = True
            self.materials[key] = mat
        return self.materials[key]

    def automatic_film(self, case: str):
        """The film of roughness ``AUTOMATIC_ROUGHNESS[case]`` at its automatic SH order (made once)."""
        import bpy

        mat = bpy.data.materials.get(f"Film auto {case}")
        if mat is None:
            mat = bpy.data.materials.new(f"Film auto {case}")
            rough = AUTOMATIC_ROUGHNESS[case]
            self.ext.conversion.fill_from_material(mat.thinfilm_sh, FILM.with_(roughness=rough))
            mat.thinfilm_sh.sh_order = "AUTO"
            mat.thinfilm_sh.enabled = True
        return mat

    def set_objects(self, count: int, triangles: int) -> None:
        """Replace the tori by ``count`` tori with ``triangles`` in all, on a grid facing the camera."""
        import bpy

        if self.layout == (count, triangles):
            return
        for obj in self.objects:
            mesh = obj.data
            bpy.data.objects.remove(obj)
            bpy.data.meshes.remove(mesh)
        self.objects = []
        cols = math.ceil(math.sqrt(count))
        rows = math.ceil(count / cols)
        cell = 2.0 / cols
        template = torus_mesh("Torus", triangles // count, 0.32 * cell, 0.13 * cell)
        for k in range(count):
            mesh = template if k == 0 else template.copy()
            obj = bpy.data.objects.new(f"Torus.{k:03d}", mesh)
            r, c = divmod(k, cols)
            obj.location = (-1.0 + cell * (c + 0.5), 0.0, (rows / cols) - cell * (r + 0.5))
            obj.rotation_euler = (math.radians(70.0), math.radians(10.0 * (k % 5)), math.radians(25.0))
            self.scene.collection.objects.link(obj)
            self.objects.append(obj)
        self.layout = (count, triangles)
        self.camera.location = (0.0, -4.2, 0.35)
        self.camera.rotation_euler = (math.radians(85.0), 0.0, 0.0)
        bpy.context.view_layer.update()

    def assign(self, l_max: int, case: str = "sh", distinct: bool = False) -> None:
        """Give every torus the film material of ``l_max`` / ``case``; ``distinct``: each torus its
        own copy of it (equal settings, so one table, but one description per material and frame)."""
        import bpy

        mat = self.material(l_max, case)
        for k, obj in enumerate(self.objects):
            own = mat
            if distinct and k > 0:
                name = f"{mat.name} copy {k}"
                own = bpy.data.materials.get(name) or mat.copy()
                own.name = name
            if len(obj.data.materials) == 0:
                obj.data.materials.append(own)
            elif obj.data.materials[0] != own:
                obj.data.materials[0] = own
        bpy.context.view_layer.update()

    @property
    def triangles(self) -> int:
        return sum(2 * len(o.data.polygons) for o in self.objects)

    def matrices(self, width: int, height: int):
        import bpy

        depsgraph = bpy.context.evaluated_depsgraph_get()
        return self.ext.render.camera_matrices(self.scene, depsgraph, width, height)
