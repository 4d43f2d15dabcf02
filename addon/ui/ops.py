"""Operators: bake (modal, a ``bake_jobs.BakeJob`` on its thread), presets, film layers, write-back,
cache.

Every operator turns a ValueError (bad settings, a missing attribute, ...) into
``self.report({'ERROR'}, message)`` and returns CANCELLED: the user sees the message, never a
traceback.

Every operator has a ``poll()`` that greys its button out, with the reason as the button's
tooltip (``poll_message_set``), when the context's material cannot be used: no film layer to
remove, nothing to write back, or a material that is not editable. Linked materials (from a
library .blend) and library overrides are read-only here: the operators that edit a material
refuse them (:func:`read_only_reason`), in ``poll`` for the context's material and in
``execute`` for one named by the ``material`` parameter, so library data is never changed in
memory (where a save would lose it). Baking a linked material is allowed: it changes nothing in
the material (its outputs live in memory, :data:`.props.OUTPUTS`). Called from a script
without a material in the context, ``poll`` lets the ``material`` parameter decide.
"""

import time

import bpy
from bl_operators.presets import AddPresetBase
from bpy.props import BoolProperty, EnumProperty, StringProperty
from bpy.types import Operator

from ..bakes import bake_jobs, tables
from ..bakes.bake_jobs import BakeJob
from ..drawing import viewport
from ..materials.conversion import apply_preset, mark_custom
from ..materials.description import description
from ..materials.principled import write_back_to_principled
from ..materials.props import PRESET_ITEMS
from . import prefs


def _context_material(context):
    """The context's material, else the active object's active material, else None."""
    mat = getattr(context, "material", None)
    if mat is None:
        obj = getattr(context, "object", None)
        mat = obj.active_material if obj is not None else None
    return mat


def _material(op, context):
    """The operator's ``material`` by name, else the context's material, else the active object's."""
    name = getattr(op, "material", "")
    if name:
        return bpy.data.materials.get(name)
    return _context_material(context)


def read_only_reason(mat) -> str | None:
    """Why ``mat``'s thin film cannot be edited here (linked, a library override, otherwise not
    editable), or None when it can."""
    if mat.library is not None:
        return (
            f"Material '{mat.name}' is linked from '{mat.library.filepath}' and cannot be edited "
            "here: make it local first (Object > Relations > Make Local)"
        )
    if mat.override_library is not None:
        return (
            f"Material '{mat.name}' is a library override: its thin film can only be edited in "
            "the library file"
        )
    if not mat.is_editable:
        return f"Material '{mat.name}' is not editable"
    return None


def _poll_material(cls, context) -> bool:
    """``poll`` of the material operators: the context's material (the Properties editor's, or
    a ``temp_override``'s) passes ``cls.refuse``."""
    mat = getattr(context, "material", None)
    if mat is None:
        return True  # a script names the material, or it is the active object's: execute checks it
    reason = cls.refuse(mat)
    if reason:
        cls.poll_message_set(reason)
        return False
    return True


def _tag_redraw(context) -> None:
    screen = getattr(context, "screen", None)
    if screen is None:
        return
    for area in screen.areas:
        if area.type in {"PROPERTIES", "VIEW_3D"}:
            area.tag_redraw()


def _store_result(settings, result, source: str, elapsed_s: float) -> None:
    settings.last_bake_ms = 1000.0 * elapsed_s
    settings.last_plan = tables.format_plan(result, source)
    settings.last_error = ""


def _report_cache_error(op, desc) -> None:
    """A table baked but not saved to the disk cache (a full disk, an unusable folder): a
    warning, the table itself is ready (in memory) and drawn."""
    problem = tables.cache_error(desc)
    if problem is not None:
        op.report({"WARNING"}, problem)


class THINFILM_OT_bake(Operator):
    """Bake (or load from the cache) the spherical-harmonic table of this material's thin film"""

    bl_idname = "thinfilm.bake"
    bl_label = "Bake Thin Film"
    bl_options = {"REGISTER"}

    @staticmethod
    def refuse(mat) -> str | None:
        """Why ``mat`` cannot be baked (no thin film), or None. Invalid settings pass: the bake
        says what is wrong with them."""
        try:
            desc = description(mat)
        except ValueError:
            return None
        if desc is None:
            return (
                f"Material '{mat.name}' has no thin film: enable Thin Film SH or set the Principled "
                "BSDF's Thin Film Thickness"
            )
        return None

    @classmethod
    def poll(cls, context):
        """A material with a thin film (or none in the context: a script names it)."""
        return _poll_material(cls, context)

    material: StringProperty(
        name="Material",
        description="Material to bake (empty: the context's material)",
        default="",
        options={"SKIP_SAVE"},
    )

    _job = None
    _timer = None
    _material_name = ""

    def _description(self, context):
        mat = _material(self, context)
        if mat is None:
            self.report({"ERROR"}, "No material to bake")
            return None, None
        try:
            desc = description(mat)
        except ValueError as exc:
            if hasattr(mat, "thinfilm_sh"):
                mat.thinfilm_sh.last_error = str(exc)
            self.report({"ERROR"}, str(exc))
            return mat, None
        if desc is None:
            self.report(
                {"ERROR"},
                f"Material {mat.name!r} has no thin film: enable Thin Film SH or set the Principled "
                "BSDF's Thin Film Thickness",
            )
        return mat, desc

    def _fail(self, mat, message: str):
        mat.thinfilm_sh.last_error = message
        self.report({"ERROR"}, message)
        return {"CANCELLED"}

    def execute(self, context):
        mat, desc = self._description(context)
        if desc is None:
            return {"CANCELLED"}
        start = time.perf_counter()
        try:
            result, source = tables.get_table_with_source(desc)
        except (ValueError, OSError) as exc:
            return self._fail(mat, tables.record_failure(desc, exc))
        _store_result(mat.thinfilm_sh, result, source, time.perf_counter() - start)
        self.report(
            {"INFO"}, f"Thin film table ready ({source}, {1000 * (time.perf_counter() - start):.0f} ms)"
        )
        _report_cache_error(self, desc)
        return {"FINISHED"}

    def invoke(self, context, event):
        if bpy.app.background:
            return self.execute(context)
        mat, desc = self._description(context)
        if desc is None:
            return {"CANCELLED"}
        hit = tables.peek_table(desc)
        if hit is not None:
            _store_result(mat.thinfilm_sh, hit, "memory", 0.0)
            return {"FINISHED"}
        self._material_name = mat.name
        self._job = BakeJob(desc, tables.open_cache()).start()  # opened here: it reads the preferences
        wm = context.window_manager
        self._timer = wm.event_timer_add(0.1, window=context.window)
        wm.modal_handler_add(self)
        wm.progress_begin(0, 100)
        self._status(context, "starting")
        return {"RUNNING_MODAL"}

    def _status(self, context, text):
        workspace = getattr(context, "workspace", None)
        if workspace is not None:
            workspace.status_text_set(
                None
                if text is None
                else f"Thin Film SH: {text} ({100 * self._job.fraction:.0f} %) — Esc to cancel"
            )

    def _finish(self, context):
        wm = context.window_manager
        if self._timer is not None:
            wm.event_timer_remove(self._timer)
            self._timer = None
        wm.progress_end()
        self._status(context, None)
        _tag_redraw(context)

    def modal(self, context, event):
        job = self._job
        if event.type == "ESC" and event.value == "PRESS":
            job.cancel()  # the thread stops at its next progress report; nothing is cached
            self._finish(context)
            self.report({"WARNING"}, "Thin film bake cancelled")
            return {"CANCELLED"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        if not job.done.is_set():
            context.window_manager.progress_update(int(100 * job.fraction))
            self._status(context, job.text)
            return {"PASS_THROUGH"}
        self._finish(context)
        mat = bpy.data.materials.get(self._material_name)
        if job.error is not None:
            message = tables.record_failure(job.desc, job.error)
            if mat is not None:
                mat.thinfilm_sh.last_error = message
            self.report({"ERROR"}, message)
            return {"CANCELLED"}
        if mat is not None and job.result is not None:
            _store_result(mat.thinfilm_sh, job.result, job.source, job.elapsed_s)
        self.report({"INFO"}, f"Thin film table ready ({job.source}, {1000 * job.elapsed_s:.0f} ms)")
        _report_cache_error(self, job.desc)
        return {"FINISHED"}

    def cancel(self, context):
        if self._job is not None:
            self._job.cancel()
        self._finish(context)


class _MaterialOperator:
    """An operator that edits a material's thin film: refuses read-only materials."""

    material: StringProperty(
        name="Material",
        description="Material to change (empty: the active material)",
        default="",
        options={"SKIP_SAVE"},
    )

    @classmethod
    def refuse(cls, mat) -> str | None:
        """Why this operator cannot run on ``mat``: read-only (:func:`read_only_reason`), or what
        :meth:`unfit` finds in its settings; None when it can."""
        return read_only_reason(mat) or cls.unfit(mat.thinfilm_sh)

    @staticmethod
    def unfit(settings) -> str | None:
        """Why these settings leave the operator nothing to do, or None (overridden)."""
        return None

    @classmethod
    def poll(cls, context):
        """The context's material is editable and this operator has something to do."""
        return _poll_material(cls, context)

    def settings(self, context):
        """The material's settings, or None after reporting why they cannot be changed."""
        mat = _material(self, context)
        if mat is None:
            self.report({"ERROR"}, "No material")
            return None
        reason = self.refuse(mat)
        if reason:
            self.report({"ERROR"}, reason)
            return None
        return mat.thinfilm_sh


class THINFILM_OT_apply_preset(_MaterialOperator, Operator):
    """Fill the film, substrate and surface settings from a preset"""

    bl_idname = "thinfilm.apply_preset"
    bl_label = "Apply Preset"
    bl_options = {"REGISTER", "UNDO"}

    preset: EnumProperty(
        name="Preset", description="The preset whose settings fill the material", items=PRESET_ITEMS[:-1]
    )

    def execute(self, context):
        settings = self.settings(context)
        if settings is None:
            return {"CANCELLED"}
        try:
            apply_preset(settings, self.preset)
        except ValueError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        return {"FINISHED"}


class THINFILM_OT_write_to_principled(_MaterialOperator, Operator):
    """Write these settings into the material's Principled BSDF so Cycles renders the same film"""

    bl_idname = "thinfilm.write_to_principled"
    bl_label = "Write to Principled BSDF"
    bl_options = {"REGISTER", "UNDO"}

    @staticmethod
    def unfit(settings) -> str | None:
        """The extension's settings off (nothing to write). A material without a Principled BSDF
        gets one."""
        return (
            None if settings.enabled else "Thin Film SH is off for this material: there is nothing to write"
        )

    def execute(self, context):
        if self.settings(context) is None:
            return {"CANCELLED"}
        mat = _material(self, context)
        try:
            notes = write_back_to_principled(mat)
        except ValueError as exc:
            self.report({"ERROR"}, f"material {mat.name!r}: {exc}")
            return {"CANCELLED"}
        for note in notes:
            self.report({"WARNING"}, note)
        self.report({"INFO"}, f"Wrote the thin film of {mat.name!r} to its Principled BSDF")
        return {"FINISHED"}


class _LayerOperator(_MaterialOperator):
    """An operator that edits the film's layer stack (:meth:`edit`), then selects a layer and
    marks the settings CUSTOM; it needs :attr:`min_layers` layers."""

    #: The layers the operator needs (its button is greyed out with fewer).
    min_layers = 0
    #: Why, by :attr:`min_layers`.
    TOO_FEW = {1: "There is no film layer to remove", 2: "Moving a film layer needs at least two layers"}

    @classmethod
    def unfit(cls, settings) -> str | None:
        """Fewer than :attr:`min_layers` layers."""
        return cls.TOO_FEW[cls.min_layers] if len(settings.layers) < cls.min_layers else None

    def edit(self, layers, active: int) -> int | None:
        """Change ``layers`` (the active one is ``active``); the layer to select after, or None
        when nothing was changed (the operator is cancelled)."""
        raise NotImplementedError

    def execute(self, context):
        settings = self.settings(context)
        if settings is None:
            return {"CANCELLED"}
        index = self.edit(settings.layers, settings.active_layer_index)
        if index is None:
            return {"CANCELLED"}
        settings.active_layer_index = index
        mark_custom(settings)
        return {"FINISHED"}


class THINFILM_OT_layer_add(_LayerOperator, Operator):
    """Add a film layer below the active one"""

    bl_idname = "thinfilm.layer_add"
    bl_label = "Add Film Layer"
    bl_options = {"REGISTER", "UNDO"}

    def edit(self, layers, active: int) -> int:
        """A new layer below the active one, selected."""
        index = min(active + 1, len(layers)) if len(layers) else 0
        layers.add()
        layers.move(len(layers) - 1, index)
        return index


class THINFILM_OT_layer_remove(_LayerOperator, Operator):
    """Remove the active film layer"""

    bl_idname = "thinfilm.layer_remove"
    bl_label = "Remove Film Layer"
    bl_options = {"REGISTER", "UNDO"}

    min_layers = 1

    def edit(self, layers, active: int) -> int | None:
        """The active layer removed; its neighbour selected."""
        if not len(layers):
            self.report({"ERROR"}, "There is no film layer to remove")
            return None
        index = min(active, len(layers) - 1)
        layers.remove(index)
        return max(0, min(index, len(layers) - 1))


class THINFILM_OT_layer_move(_LayerOperator, Operator):
    """Move the active film layer up (toward the ambient) or down (toward the substrate)"""

    bl_idname = "thinfilm.layer_move"
    bl_label = "Move Film Layer"
    bl_options = {"REGISTER", "UNDO"}

    direction: EnumProperty(
        name="Direction",
        description="Which way to move the layer in the stack",
        items=[
            ("UP", "Up", "Toward the air side (the top of the list)"),
            ("DOWN", "Down", "Toward the substrate (the bottom of the list)"),
        ],
    )
    min_layers = 2

    min_layers = 2

    def edit(self, layers, active: int) -> int | None:
        """The active layer one place up or down, still selected."""
        target = active - 1 if self.direction == "UP" else active + 1
        if 0 <= active < len(layers) and 0 <= target < len(layers):
            layers.move(active, target)
            return target
        return None


class THINFILM_OT_clear_cache(Operator):
    """Delete the baked tables from memory and the tables this add-on wrote to its cache folder
    (nothing else in the folder is touched)"""

    bl_idname = "thinfilm.clear_cache"
    bl_label = "Clear Thin Film Cache"
    bl_options = {"REGISTER"}

    @classmethod
    def poll(cls, context):
        """Always available: it changes no Blender data, only the add-on's own cache."""
        return True

    def execute(self, context):
        try:
            cache = tables.table_cache()
            removed = tables.clear_caches(cache)
        except (OSError, ValueError) as exc:  # CacheDirError: an unsafe or unusable folder
            tables.clear_memory_cache()
            self.report({"ERROR"}, f"Could not clear the table cache: {exc}")
            return {"CANCELLED"}
        self.report({"INFO"}, f"Removed {removed} cached table file(s) from {cache.tables_dir}")
        return {"FINISHED"}


#: Where user presets live, under Blender's ``scripts/presets`` folders (user and extension).
PRESET_SUBDIR = "thinfilm_sh/material"
#: The settings a user preset stores: the film and the surface, not the viewing or quality choices
#: (as the built-in presets, :func:`.props.fill_from_material`).
PRESET_VALUES = [
    f"settings.{name}"
    for name in (
        "layers",
        "vary_thickness",
        "thickness_min_nm",
        "thickness_max_nm",
        "substrate_mode",
        "substrate_ior",
        "substrate_metal",
        "substrate_n",
        "substrate_k",
        "ambient_ior",
        "roughness",
        "diffuse_base",
        "diffuse_color",
        "model",
    )
]


class THINFILM_OT_preset_add(AddPresetBase, Operator):
    """Save this material's film and surface settings as a preset of your own, or remove one"""

    bl_idname = "thinfilm.preset_add"
    bl_label = "Add Thin Film Preset"
    preset_menu = "THINFILM_MT_presets"
    preset_subdir = PRESET_SUBDIR
    preset_defines = ["settings = bpy.context.material.thinfilm_sh"]
    preset_values = PRESET_VALUES

    # AddPresetBase's hidden switches, with tooltips.
    remove_name: BoolProperty(
        name="Remove by Name",
        description="Remove the preset with this name instead of adding one",
        default=False,
        options={"HIDDEN", "SKIP_SAVE"},
    )
    remove_active: BoolProperty(
        name="Remove Active",
        description="Remove the preset chosen last in the menu instead of adding one",
        default=False,
        options={"HIDDEN", "SKIP_SAVE"},
    )

    @classmethod
    def poll(cls, context):
        """An editable material in the context (presets read and write ``context.material``)."""
        mat = getattr(context, "material", None)
        if mat is None:
            cls.poll_message_set("No material in this context")
            return False
        reason = read_only_reason(mat)
        if reason:
            cls.poll_message_set(reason)
            return False
        return True


class THINFILM_OT_toggle_overlay(Operator):
    """Show or hide thin films in this 3D viewport"""

    bl_idname = "thinfilm.toggle_overlay"
    bl_label = "Thin Film SH Overlay"
    bl_options = {"REGISTER"}

    @classmethod
    def poll(cls, context):
        """A 3D viewport, with the overlay preference on."""
        space = context.space_data
        if space is None or space.type != "VIEW_3D":
            cls.poll_message_set("Only in a 3D viewport")
            return False
        if not prefs.overlay_enabled(context):
            cls.poll_message_set("The Show Thin Film Overlay preference is off")
            return False
        return True

    def execute(self, context):
        """Flip this viewport's switch and redraw it."""
        space = context.space_data
        viewport.set_shown_in(space, not viewport.shown_in(space))
        if context.area is not None:
            context.area.tag_redraw()
        return {"FINISHED"}


class THINFILM_OT_cancel_bakes(Operator):
    """Stop the thin-film bakes running in the background for the viewport"""

    bl_idname = "thinfilm.cancel_bakes"
    bl_label = "Cancel Thin Film Bakes"
    bl_options = {"REGISTER"}

    def execute(self, context):
        """Ask the running bakes to stop at their next progress step."""
        count = bake_jobs.cancel_all()
        self.report({"INFO"}, f"Cancelled {count} thin film bake(s)")
        return {"FINISHED"}

    @classmethod
    def poll(cls, context):
        """Only while a viewport bake runs."""
        if not viewport.activity():
            cls.poll_message_set("No thin film is baking")
            return False
        return True


classes = (
    THINFILM_OT_preset_add,
    THINFILM_OT_toggle_overlay,
    THINFILM_OT_cancel_bakes,
    THINFILM_OT_bake,
    THINFILM_OT_apply_preset,
    THINFILM_OT_layer_add,
    THINFILM_OT_layer_remove,
    THINFILM_OT_layer_move,
    THINFILM_OT_write_to_principled,
    THINFILM_OT_clear_cache,
)
