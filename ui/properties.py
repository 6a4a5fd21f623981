"""The panel's settings, stored on the scene (``scene.udf_reconstruction``) and saved with the file.

Generated from the fields of :class:`engine.settings.ReconstructSettings`: one Blender property
per field, with the field's label, tooltip, default, range and choices, so a new setting appears
here with no edit. Only what the engine never sees (Hide Cloud) and how the panel behaves while
a value is dragged (the Min/Max range pushing each other) are added here.
"""

from dataclasses import fields

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, StringProperty

from ..engine.settings import DEVICE_CHOICES, MODE_RANGES, ReconstructSettings, setting_info

INT_LIMIT = 2 ** 31 - 1  # Blender's integer properties are 32-bit signed


def enum_items(choices) -> list:
    """Blender enum items ``(identifier, name, description)`` for a setting's choices."""
    return [(choice.value, choice.label, choice.description) for choice in choices]


def _property(item, extra: dict):
    """The Blender property of one settings field."""
    info = setting_info(item)
    options = dict(name=info.label, description=info.description, default=item.default)
    options.update(info.ui)
    options.update(extra)
    if info.choices:
        return EnumProperty(items=enum_items(info.choices), **options)
    if isinstance(item.default, bool):
        return BoolProperty(**options)
    if isinstance(item.default, int):
        low = -INT_LIMIT if info.low is None else max(int(info.low), -INT_LIMIT)
        high = INT_LIMIT if info.high is None else min(int(info.high), INT_LIMIT)
        return IntProperty(min=low, max=high, **options)
    if isinstance(item.default, float):
        limits = {key: value for key, value in (("min", info.low), ("max", info.high))
                  if value is not None}
        return FloatProperty(**limits, **options)
    return StringProperty(**options)


def property_group(settings_type, name: str, doc: str, extra=None, updates=None):
    """A ``PropertyGroup`` class with one property per field of ``settings_type``.

    extra: more properties ``{name: property}`` the engine never sees; updates: ``{field name:
    update callback}``.
    """
    updates = updates or {}
    annotations = {item.name: _property(item, {"update": updates[item.name]}
                                        if item.name in updates else {})
                   for item in fields(settings_type)}
    annotations.update(extra or {})
    return type(name, (bpy.types.PropertyGroup,), {"__annotations__": annotations,
                                                  "__doc__": doc})


def to_settings(props, settings_type=ReconstructSettings):
    """The engine's settings for the panel values (validated; InputError when one is bad)."""
    return settings_type.from_attributes(props, single_precision=True)


def _rho_min_changed(self, context):
    # Keep rho_min <= rho_max while the user drags either end of the range.
    if self.rho_min > self.rho_max:
        self.rho_max = self.rho_min


def _rho_max_changed(self, context):
    if self.rho_max < self.rho_min:
        self.rho_min = self.rho_max


def _custom_range_changed(self, context):
    # A custom range starts from the mode's own, which the panel showed until now.
    if self.custom_range and self.radius_mode in MODE_RANGES:
        self.parent_radius, self.rho_min, self.rho_max = MODE_RANGES[self.radius_mode]


DEVICE_ITEMS = enum_items(DEVICE_CHOICES)

UDFR_SceneSettings = property_group(
    ReconstructSettings, "UDFR_SceneSettings",
    "How the Reconstruct button rebuilds a surface from the active point cloud.",
    extra={"hide_source": BoolProperty(
        name="Hide Cloud",
        description="Hide the point cloud once its mesh is made, so the mesh can be seen (the "
                    "eye icon in the Outliner shows it again)",
        default=True)},
    updates={"rho_min": _rho_min_changed, "rho_max": _rho_max_changed,
             "custom_range": _custom_range_changed})


def scene_settings(scene):
    """The scene's panel settings (registered by the package's ``register()``)."""
    return scene.udf_reconstruction


CLASSES = (UDFR_SceneSettings,)
