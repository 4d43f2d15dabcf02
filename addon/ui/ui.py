"""The Thin Film SH panel in the Properties editor's Material tab, with its sub-panels."""

from bpy.types import Menu, Panel, UIList

from ...precompute.effects import plan_text, plans
from .. import caches
from ..bakes import tables
from ..drawing import lights as scene_lights
from ..drawing import scene_draw, viewport
from ..eevee import sync as eevee_sync
from ..materials.description import description as _description_now
from ..materials.description import description_key
from ..materials.description import warnings as _warnings_now
from ..materials.principled import principled_node
from ..thickness import linked
from ..world import world_state


def _deferred(function, mat):
    """``function(mat)`` as a panel may call it: a linked thickness that needs a Cycles bake is
    queued for the viewport's timer (:func:`.linked.deferring`), never baked inside a draw."""
    with linked.deferring():
        result = function(mat)
    if linked.has_pending():
        viewport.schedule()
    return result


def description(mat):
    """:func:`.description.description` for panels (bakes deferred, :func:`_deferred`)."""
    return _deferred(_description_now, mat)


def warnings(mat):
    """:func:`.description.warnings` for panels (bakes deferred, :func:`_deferred`)."""
    return _deferred(_warnings_now, mat)


def _settings(context):
    mat = getattr(context, "material", None)
    return mat, (getattr(mat, "thinfilm_sh", None) if mat is not None else None)


def _split_layout(panel, context):
    """(material, settings, layout) of a material panel, its layout in Blender's property-split
    style and greyed out while the film is off."""
    mat, settings = _settings(context)
    layout = panel.layout
    layout.use_property_split = True
    layout.use_property_decorate = False
    layout.active = settings.enabled
    return mat, settings, layout


class THINFILM_UL_layers(UIList):
    """Film layers from the ambient side (top) to the substrate (bottom)."""

    def draw_item(self, context, layout, data, item, icon, active_data, active_propname, index=0):
        row = layout.row(align=True)
        if item.index_mode == "CONSTANT":
            text = f"n {item.n:.3f}" + (f" + {item.k:.3f}i" if item.k else "")
        elif item.index_mode == "CAUCHY":
            text = f"Cauchy A {item.cauchy_a:.3f}"
        else:
            text = item.metal.title()
        row.label(text=f"{index + 1}. {text}", icon="MOD_THICKNESS" if index == 0 else "BLANK1")
        row.prop(item, "thickness_nm", text="nm", emboss=False)


class THINFILM_MT_presets(Menu):
    """The user's thin film presets (Blender's preset system: ``scripts/presets/thinfilm_sh/material``)."""

    bl_label = "My Presets"
    preset_subdir = "thinfilm_sh/material"
    preset_operator = "script.execute_preset"
    draw = Menu.draw_preset


class _MaterialPanel:
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "material"

    @classmethod
    def poll(cls, context):
        return _settings(context)[1] is not None


class THINFILM_PT_material(_MaterialPanel, Panel):
    """Material Properties › Thin Film SH: the switch, the preset and presets menu, any error."""

    bl_label = "Thin Film SH"
    #: After Blender's Surface, Volume, Displacement and Settings panels (order 0), before Line
    #: Art and Viewport Display (10), Animation (999) and Custom Properties (1000).
    bl_order = 5

    def draw_header(self, context):
        self.layout.prop(_settings(context)[1], "enabled", text="")

    def draw(self, context):
        mat, settings, layout = _split_layout(self, context)
        row = layout.row(align=True)
        row.prop(settings, "preset")
        row = layout.row(align=True)  # the user's own presets, beside the built-in ones
        row.enabled = mat.is_editable
        row.menu("THINFILM_MT_presets", text=THINFILM_MT_presets.bl_label)
        row.operator("thinfilm.preset_add", text="", icon="ADD")
        row.operator("thinfilm.preset_add", text="", icon="REMOVE").remove_active = True
        errors = material_errors(mat)
        if errors:
            box = layout.box()
            box.alert = True
            for line in errors:
                box.label(text=line, icon="ERROR")
        for note in _safe_warnings(mat):
            layout.label(text=note, icon="INFO")
        native = eevee_sync.status(mat)  # EEVEE-native films (addon/eevee/)
        if native:
            layout.label(text=native, icon="SHADING_RENDERED")


def material_errors(mat) -> list[str]:
    """The material panel's error lines: the last Bake button error, a failed background bake
    of the current settings (the viewport does not retry it until they change) and why its
    table is not in the disk cache."""
    settings = getattr(mat, "thinfilm_sh", None)
    lines = [settings.last_error] if settings is not None and settings.last_error else []
    try:
        desc = description(mat)
    except ValueError:
        return lines  # the warnings below say why
    if desc is None:
        return lines
    key = description_key(desc)
    failed = tables.FAILURES.get(key)  # tables.failure, by the key at hand
    if failed is not None and failed not in lines:
        lines.append(f"Bake failed: {failed} (not retried until the settings change)")
    problem = tables.CACHE_ERRORS.get(key)  # tables.cache_error
    if problem is not None:
        lines.append(problem[:1].upper() + problem[1:])
    return lines


def _safe_warnings(mat) -> list[str]:
    try:
        return warnings(mat)
    except ValueError as exc:
        return [str(exc)]


class _SubPanel(_MaterialPanel):
    bl_parent_id = "THINFILM_PT_material"

    def draw(self, context):
        mat, settings, layout = _split_layout(self, context)
        self.draw_settings(context, layout, mat, settings)


class THINFILM_PT_film(_SubPanel, Panel):
    """The film layers: index and thickness of each."""

    bl_label = "Film"

    def draw_settings(self, context, layout, mat, settings):
        row = layout.row()
        row.template_list(
            "THINFILM_UL_layers", "", settings, "layers", settings, "active_layer_index", rows=3
        )
        col = row.column(align=True)
        col.operator("thinfilm.layer_add", icon="ADD", text="")
        col.operator("thinfilm.layer_remove", icon="REMOVE", text="")
        col.separator()
        col.operator("thinfilm.layer_move", icon="TRIA_UP", text="").direction = "UP"
        col.operator("thinfilm.layer_move", icon="TRIA_DOWN", text="").direction = "DOWN"
        if 0 <= settings.active_layer_index < len(settings.layers):
            layer = settings.layers[settings.active_layer_index]
            col = layout.column()
            col.prop(layer, "index_mode")
            if layer.index_mode == "CONSTANT":
                col.prop(layer, "n")
                col.prop(layer, "k")
            elif layer.index_mode == "CAUCHY":
                col.prop(layer, "cauchy_a")
                col.prop(layer, "cauchy_b", text="B (µm²)")
                col.prop(layer, "cauchy_c", text="C (µm⁴)")
            else:
                col.prop(layer, "metal")
            col.prop(layer, "thickness_nm", text="Thickness (nm)")
        layout.prop(settings, "model")


class THINFILM_PT_thickness(_SubPanel, Panel):
    """Thickness varying over the surface: range and the attribute or texture driving it."""

    bl_label = "Thickness Variation"
    bl_options = {"DEFAULT_CLOSED"}

    def draw_header(self, context):
        self.layout.prop(_settings(context)[1], "vary_thickness", text="")

    def draw_settings(self, context, layout, mat, settings):
        layout.active = settings.enabled and settings.vary_thickness
        col = layout.column(align=True)
        col.prop(settings, "thickness_min_nm", text="Top Layer Min (nm)")
        col.prop(settings, "thickness_max_nm", text="Max (nm)")
        layout.prop(settings, "thickness_source")
        if settings.thickness_source == "ATTRIBUTE":
            obj = context.object
            mesh = obj.data if obj is not None and obj.type == "MESH" else None
            if mesh is not None:
                layout.prop_search(settings, "thickness_attribute", mesh, "attributes", text="Attribute 0–1")
            else:
                layout.prop(settings, "thickness_attribute", text="Attribute 0–1")
        elif settings.thickness_source in {"NOISE", "BLENDER_NOISE"}:
            layout.prop(settings, "noise_scale")
            layout.prop(settings, "noise_seed")
        else:
            layout.template_ID(settings, "thickness_image", open="image.open")
            obj = context.object
            if obj is not None and obj.type == "MESH":
                layout.prop_search(settings, "thickness_uv_map", obj.data, "uv_layers", text="UV Map")
            else:
                layout.prop(settings, "thickness_uv_map")
        obj = context.object
        if obj is not None:  # NaN values, a missing attribute: what the last draw found
            for note in scene_draw.object_notes(obj.name):
                layout.label(text=note, icon="ERROR")


class THINFILM_PT_substrate(_SubPanel, Panel):
    """What lies under the film (dielectric, metal or n + ik) and above it (ambient index)."""

    bl_label = "Substrate"

    def draw_settings(self, context, layout, mat, settings):
        layout.prop(settings, "substrate_mode")
        if settings.substrate_mode == "DIELECTRIC":
            layout.prop(settings, "substrate_ior")
        elif settings.substrate_mode == "METAL":
            layout.prop(settings, "substrate_metal")
        else:
            col = layout.column(align=True)
            col.prop(settings, "substrate_n")
            col.prop(settings, "substrate_k")
        layout.prop(settings, "ambient_ior")


class THINFILM_PT_surface(_SubPanel, Panel):
    """Roughness, diffuse base, World lamps, colour mode and illuminant."""

    bl_label = "Surface"

    def draw_settings(self, context, layout, mat, settings):
        layout.prop(settings, "roughness")
        layout.label(text=tables.shading_path(settings.roughness), icon="INFO")
        row = layout.row(heading="Diffuse Base")
        row.prop(settings, "diffuse_base", text="")
        sub = row.row()
        sub.active = settings.diffuse_base
        sub.prop(settings, "diffuse_color", text="")
        row = layout.row()
        row.active = not settings.diffuse_base
        row.prop(settings, "world_lamps")
        layout.label(text=world_state.lamps_summary(settings.world_lamps and not settings.diffuse_base))
        layout.label(text=scene_lights.lights_summary(context.scene))
        layout.prop(settings, "colour_mode")
        layout.prop(settings, "illuminant")
        layout.prop(settings, "transparency")


class THINFILM_PT_quality(_SubPanel, Panel):
    """Sampling of the baked table (auto or set), the last bake, Bake and Clear Cache."""

    bl_label = "Quality"
    bl_options = {"DEFAULT_CLOSED"}

    def draw_settings(self, context, layout, mat, settings):
        chosen = tables.parse_plan(settings.last_plan)

        def auto_prop(name, text):
            row = layout.row()
            row.prop(settings, name, text=text)
            value = getattr(settings, name)
            if value in (0, "AUTO") and name in chosen:
                row.label(text=f"→ {chosen[name]}")

        auto_prop("sh_order", "SH Order")
        auto_prop("view_samples", "View Angles (0 auto)")
        auto_prop("thickness_samples", "Thicknesses (0 auto)")
        auto_prop("wavelength_count", "Wavelengths (0 auto)")
        if settings.last_plan:
            box = layout.box()
            col = box.column(align=True)
            col.scale_y = 0.8
            for line in settings.last_plan.splitlines():
                col.label(text=line)
            col.label(text=f"Last bake: {settings.last_bake_ms:.0f} ms")
        row = layout.row(align=True)
        row.operator("thinfilm.bake", icon="RENDER_STILL")
        row.operator("thinfilm.clear_cache", icon="TRASH", text="")


class THINFILM_PT_principled(_MaterialPanel, Panel):
    """Reading and writing a Principled BSDF's thin film."""

    bl_label = "Principled Interop"
    bl_parent_id = "THINFILM_PT_material"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        mat, settings = _settings(context)
        layout = self.layout
        node = principled_node(mat)
        if not settings.enabled:
            layout.prop(settings, "preview_principled")
            if not settings.preview_principled:
                layout.label(text="The Principled film is not previewed: Cycles still renders it")
        if not settings.enabled and settings.preview_principled:
            try:
                desc = description(mat)
            except ValueError as exc:
                layout.label(text=str(exc), icon="ERROR")
                desc = None
            if desc is not None:
                layer = desc.layers[0]
                layout.label(text="Previewed from Principled BSDF", icon="NODE_MATERIAL")
                layout.label(text=f"Film n {layer.index:g}, {layer.thickness_nm:g} nm")
            elif node is None:
                layout.label(text="No Principled BSDF")
            else:
                layout.label(text="Principled Thin Film Thickness is 0: not previewed")
        elif settings.enabled:
            layout.label(text="Cycles renders the Principled BSDF's single film")
        row = layout.row()
        row.enabled = settings.enabled
        row.operator("thinfilm.write_to_principled", icon="EXPORT")


# ----------------------------------------------------------------------------------------------
# Plan: what the active material needs simulated (precompute.effects), never a bake
# ----------------------------------------------------------------------------------------------
_PLAN_MEMO_SIZE = 64
#: MaterialPlans by description key (the most recent _PLAN_MEMO_SIZE; see :mod:`.caches`).
_PLANS = caches.register("plans", caches.LRU(_PLAN_MEMO_SIZE), scope=caches.SESSION)
#: Roughness values whose automatic SH order has been resolved (kept for the record: since the
#: order is read from a table, planning any roughness is instant).
_ORDERS_SEEN: set = caches.register("plan_orders_seen", set(), scope=caches.SESSION)


def _remember_plan(key, mp):
    _PLANS[key] = mp
    _ORDERS_SEEN.add(float(mp.material.roughness))


def plan_for(desc, wait: bool = False):
    """The :class:`precompute.effects.plans.MaterialPlan` of ``desc``, memoised by description key.

    Planning bakes nothing and computes no kernel: the automatic SH order is read from
    ``precompute.bakes.sh_order.ORDER_BREAKPOINTS``, so a new roughness plans at once (≈ 1 ms) on the
    main thread. ``wait`` is accepted for callers written when a new roughness had to wait for a
    timer; it changes nothing now. A material that cannot be planned raises ValueError.
    """
    key = description_key(desc)
    mp = _PLANS.get(key)
    if mp is None:
        mp = plans.material_plan(desc)
        _remember_plan(key, mp)
    return mp


def plan_lines(mp) -> list[str]:
    """The panel's summary of a plan: effects, table, orders, costs (one label each)."""
    p = mp.plan
    warm = mp.bake_time(kernel_cold=False, order_kernel_cold=False)["total"]
    shape = "×".join(str(n) for n in mp.table_shape)
    defines = " ".join(name if value == "1" else f"{name}={value}" for name, value in mp.shader.defines)
    return [
        f"Effects: {plan_text.effect_summary(mp)}",
        f"Table {shape} float32, {plan_text.fmt_bytes(mp.table_bytes)}"
        f" (GPU {plan_text.fmt_bytes(mp.texture_bytes)})",
        f"SH order {p.sh_order} · {p.view_samples} view angles · {p.thickness_samples} thickness rows · "
        f"{mp.wavelength_nodes} wavelengths",
        f"Bake ≈ {mp.bake_seconds:.2g} s (first in a session), ≈ {warm:.2g} s with a warm kernel",
        f"Shader {defines}: {mp.shader.floats_fetched} floats, {mp.shader.multiply_adds} multiply-adds/pixel",
    ]


class THINFILM_PT_plan(_SubPanel, Panel):
    """Which effects the material needs and what they cost (the effect plan)."""

    bl_label = "Plan"
    bl_options = {"DEFAULT_CLOSED"}

    def draw_settings(self, context, layout, mat, settings):
        layout.use_property_split = False
        layout.active = True  # the plan also describes a material previewed from its Principled BSDF
        try:
            desc = description(mat)
        except ValueError as exc:
            layout.label(text=str(exc), icon="ERROR")
            return
        if desc is None:
            layout.label(text="No thin film is previewed: nothing is baked or drawn", icon="INFO")
            return
        try:
            mp = plan_for(desc)
        except ValueError as exc:
            layout.label(text=str(exc), icon="ERROR")
            return
        col = layout.column(align=True)
        flow = col.grid_flow(columns=2, even_columns=True, align=True)
        for name in plans.EFFECTS:
            icon = "CHECKBOX_HLT" if mp.effects[name] else "CHECKBOX_DEHLT"
            flow.label(text=name.replace("_", " ").capitalize(), icon=icon)
        box = layout.box()
        lines = box.column(align=True)
        lines.scale_y = 0.8
        for line in plan_lines(mp)[1:]:
            lines.label(text=line)
        if tables.peek_table(desc) is not None:
            lines.label(text="Its table is in memory: no bake needed", icon="CHECKMARK")
        why = layout.box().column(align=True)
        why.scale_y = 0.8
        why.label(text="Why", icon="QUESTION")
        for name, reason in mp.reasons.items():
            why.label(text=f"{name.replace('_', ' ')}: {reason}")


classes = (
    THINFILM_MT_presets,
    THINFILM_UL_layers,
    THINFILM_PT_material,
    THINFILM_PT_film,
    THINFILM_PT_thickness,
    THINFILM_PT_substrate,
    THINFILM_PT_surface,
    THINFILM_PT_quality,
    THINFILM_PT_plan,
    THINFILM_PT_principled,
)
