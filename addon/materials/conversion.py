"""The extension's settings ↔ a :class:`precompute.materials.material.Material`.

- :func:`description_from_props` — the Material the settings (``material.thinfilm_sh``,
  :mod:`.props`) describe (ValueError naming a bad parameter);
- :func:`fill_from_material` / :func:`apply_preset` — a Material (or a preset) back into them.

Editing a physical setting by hand switches ``preset`` to CUSTOM (:func:`mark_custom`, except
while :func:`applying` a Material); choosing a preset fills the settings.

Numbers read from Blender are float32; :func:`f32` turns them back into the shortest decimal
that rounds to the same float32 (1.33 stays 1.33, not 1.3300000429153442), so a description
from the UI equals the preset or CLI material with the same values and shares its cache key.
"""

import contextlib

import numpy as np

from ...precompute.materials.material import AUTO, PRESETS, Layer, Material, Quality
from ...precompute.optics import metals
from ..colour_space import working_space

__all__ = ["applying", "apply_preset", "description_from_props", "f32", "fill_from_material", "mark_custom"]

_applying = 0  # > 0 while fill_from_material writes properties (they must not mark CUSTOM)


def f32(value) -> float:
    """The shortest decimal that rounds to the same float32 as ``value`` (NaN/Inf pass through)."""
    return float(str(np.float32(value)))


def _metal_name(identifier: str) -> str:
    return metals.get_metal(identifier.lower()).name


def _enum_id(name: str) -> str:
    return name.upper()


def _layer_spec(layer):
    mode = layer.index_mode
    if mode == "CAUCHY":
        return {"cauchy": [f32(layer.cauchy_a), f32(layer.cauchy_b), f32(layer.cauchy_c)]}
    if mode == "METAL":
        return {"metal": _metal_name(layer.metal)}
    n, k = f32(layer.n), f32(layer.k)
    return [n, k] if k != 0.0 else n


def _substrate_spec(props):
    mode = props.substrate_mode
    if mode == "METAL":
        return {"metal": _metal_name(props.substrate_metal)}
    if mode == "CUSTOM":
        n, k = f32(props.substrate_n), f32(props.substrate_k)
        return [n, k] if k != 0.0 else n
    return f32(props.substrate_ior)


def _quality(props) -> Quality:
    def count(value):
        return AUTO if int(value) == 0 else int(value)

    return Quality(
        sh_order=AUTO if props.sh_order == "AUTO" else int(props.sh_order),
        view_samples=count(props.view_samples),
        thickness_samples=count(props.thickness_samples),
        wavelength_count=count(props.wavelength_count),
    )


def description_from_props(props, colour_space: str | None = None) -> Material:
    """The Material of the extension's settings (ValueError naming the bad parameter)."""
    layers = tuple(Layer(_layer_spec(layer), f32(layer.thickness_nm)) for layer in props.layers)
    return Material(
        layers=layers,
        substrate=_substrate_spec(props),
        ambient=f32(props.ambient_ior),
        roughness=f32(props.roughness),
        thickness_range_nm=(
            (f32(props.thickness_min_nm), f32(props.thickness_max_nm)) if props.vary_thickness else None
        ),
        base_color=tuple(f32(v) for v in props.diffuse_color) if props.diffuse_base else None,
        model=props.model.lower(),
        colour_mode=props.colour_mode.lower(),
        colour_space=colour_space or working_space(),
        illuminant=props.illuminant,
        quality=_quality(props),
    )


@contextlib.contextmanager
def _filling():
    global _applying
    _applying += 1
    try:
        yield
    finally:
        _applying -= 1


def applying() -> bool:
    """True while :func:`fill_from_material` is writing properties."""
    return _applying > 0


def mark_custom(props) -> None:
    """The user changed a physical setting by hand: the preset no longer describes it."""
    if not applying() and props.preset != "CUSTOM":
        with _filling():
            props.preset = "CUSTOM"


def _set_index(target, spec, prefix: str, allow_cauchy: bool) -> None:
    """Write an IndexSpec into (prefix)mode/n/k/metal/cauchy properties."""
    if isinstance(spec, dict):
        ((kind, value),) = spec.items()
        if kind == "metal":
            setattr(target, prefix + "mode" if prefix else "index_mode", "METAL")
            setattr(target, prefix + "metal" if prefix else "metal", _enum_id(metals.get_metal(value).name))
            return
        if kind == "cauchy" and allow_cauchy:
            a, b, c = (list(value) + [0.0, 0.0, 0.0])[:3]
            target.index_mode = "CAUCHY"
            target.cauchy_a, target.cauchy_b, target.cauchy_c = a, b, c
            return
        raise ValueError(f"index kind {kind!r} cannot be edited in the panel (use the CLI)")
    n, k = (float(spec), 0.0) if isinstance(spec, (int, float)) else (float(spec[0]), float(spec[1]))
    if prefix:  # substrate
        if k == 0.0:
            target.substrate_mode = "DIELECTRIC"
            target.substrate_ior = n
        else:
            target.substrate_mode = "CUSTOM"
            target.substrate_n, target.substrate_k = n, k
    else:
        target.index_mode = "CONSTANT"
        target.n, target.k = n, k


def fill_from_material(props, material: Material) -> None:
    """Write a Material's physical settings into the extension's properties.

    Film stack, substrate, ambient, roughness, thickness range, diffuse base and model are set;
    the viewing choices (colour mode, illuminant, quality) are left as the user set them.
    """
    with _filling():
        props.layers.clear()
        for layer in material.layers:
            item = props.layers.add()
            _set_index(item, layer.index, "", allow_cauchy=True)
            item.thickness_nm = float(layer.thickness_nm)
        props.active_layer_index = 0
        _set_index(props, material.substrate, "substrate_", allow_cauchy=False)
        props.ambient_ior = float(material.ambient)
        props.roughness = float(material.roughness)
        props.vary_thickness = material.thickness_range_nm is not None
        if material.thickness_range_nm is not None:
            props.thickness_min_nm, props.thickness_max_nm = map(float, material.thickness_range_nm)
        props.diffuse_base = material.base_color is not None
        if material.base_color is not None:
            props.diffuse_color = tuple(material.base_color)
        props.model = material.model.upper()


def apply_preset(props, name: str) -> None:
    """Fill the properties from ``PRESETS[name]`` (lower-case key or enum identifier)."""
    key = name.lower()
    if key not in PRESETS:
        raise ValueError(f"unknown preset {name!r}; choose one of {sorted(PRESETS)}")
    fill_from_material(props, PRESETS[key])
    with _filling():
        props.preset = key.upper()
