"""The effect plan as text for people: a material's or a scene's plan, one line per choice."""

from __future__ import annotations

from .plans import EFFECTS, MaterialPlan, ScenePlan


# ----------------------------------------------------------------------------------------------
# Text
# ----------------------------------------------------------------------------------------------
def fmt_bytes(count: int) -> str:
    """A byte count in B, KiB or MiB."""
    if count >= 1 << 20:
        return f"{count / (1 << 20):.2f} MiB"
    if count >= 1 << 10:
        return f"{count / (1 << 10):.1f} KiB"
    return f"{count} B"


def effect_summary(mp: MaterialPlan) -> str:
    """ "interference, single film, dispersion, …" — the effects that are on, in words."""
    on = [name for name in EFFECTS if mp.effects[name]]
    if mp.effects["interference"] and not mp.effects["stack"]:
        on.insert(1, "single film")
    return ", ".join(on) if on else "none (bare substrate)"


def _material_lines(name: str, mp: MaterialPlan, scene: ScenePlan | None = None) -> list[str]:
    p = mp.plan
    shape = "×".join(str(n) for n in mp.table_shape)
    head = f"material {name!r}" if name else "material"
    lines = [f"{head}: {effect_summary(mp)}"]
    if scene is not None:
        sharing = scene.tables[mp.key]
        if sharing[0] != name:
            lines.append(f"  shares the table of {sharing[0]!r} (equal settings): no bake of its own")
        elif mp.key in scene.cached:
            lines.append("  table already cached: no bake")
    lines.append("  effects: " + ", ".join(f"{n} {'on' if mp.effects[n] else 'off'}" for n in EFFECTS))
    lines.append(
        f"  table {shape} float32 = {fmt_bytes(mp.table_bytes)} (GPU texture {fmt_bytes(mp.texture_bytes)}); "
        f"SH order {p.sh_order}, {p.view_samples} view angles, {p.thickness_samples} thickness row(s), "
        f"{mp.wavelength_nodes} wavelength nodes, ≈ {mp.u_degree} u nodes/interval"
    )
    seconds = mp.bake_seconds if scene is None else scene.bake_seconds_each[name]
    lines.append(
        f"  bake ≈ {seconds:.2g} s; shader {' '.join(f'{k}={v}' for k, v in mp.shader.defines)}: "
        f"{mp.shader.floats_fetched} floats fetched, {mp.shader.texel_fetches} texel fetches, "
        f"{mp.shader.uniform_loads} uniform loads, {mp.shader.multiply_adds} multiply-adds per pixel"
    )
    lines.append("  why:")
    for key, reason in mp.reasons.items():
        lines.append(f"    {key}: {reason}")
    return lines


def format_plan(plan, name: str = "") -> str:
    """Human-readable text of a :class:`MaterialPlan` (``name`` optional) or a :class:`ScenePlan`."""
    if isinstance(plan, MaterialPlan):
        return "\n".join(_material_lines(name, plan))
    if not isinstance(plan, ScenePlan):
        raise TypeError(f"format_plan takes a MaterialPlan or a ScenePlan, got {type(plan).__name__}")
    lines = [f"scene: {plan.reasons['scene']}"]
    if plan.materials:
        lines.append(
            f"  total: {len(plan.tables)} table(s), {fmt_bytes(plan.table_bytes)} float32 "
            f"(GPU {fmt_bytes(plan.texture_bytes)}), bake ≈ {plan.bake_seconds:.2g} s"
        )
    for key in ("cache", "world"):
        if key in plan.reasons:
            lines.append(f"  {key}: {plan.reasons[key]}")
    for name, mp in plan.materials.items():
        lines.extend(_material_lines(name, mp, plan))
    return "\n".join(lines)
