"""Helpers the Blender tests share: generated clouds as Blender objects, a stand-in for an
operator's ``report``, and a recorder that a panel or preferences ``draw`` can draw into, so the
bpy module (no window) can check what it would show."""

import bpy
import numpy as np


def sphere_points(count: int, radius: float):
    """(count, 3) points evenly spread on a sphere around the origin (Fibonacci lattice)."""
    i = np.arange(count) + 0.5
    polar = np.arccos(1.0 - 2.0 * i / count)
    azimuth = np.pi * (1.0 + 5.0 ** 0.5) * i
    return radius * np.c_[np.cos(azimuth) * np.sin(polar), np.sin(azimuth) * np.sin(polar),
                          np.cos(polar)]


def add_cloud(name: str, points, colors=None):
    """A vertex-only mesh object holding ``points`` (and a ``Col`` point colour), linked to the
    scene's collection, selected and active."""
    mesh = bpy.data.meshes.new(name)
    mesh.vertices.add(len(points))
    mesh.attributes["position"].data.foreach_set(
        "vector", np.asarray(points, dtype=np.float32).ravel())
    if colors is not None:
        attribute = mesh.color_attributes.new("Col", 'FLOAT_COLOR', 'POINT')
        attribute.data.foreach_set("color", np.asarray(colors, dtype=np.float32).ravel())
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    obj.select_set(True)
    return obj


def scene_state():
    """What a failed run must not change: the objects with their data, visibility and selection,
    the active object, and the mesh data-blocks."""
    layer = bpy.context.view_layer
    objects = sorted((o.name, o.data.name if o.data else None, o.hide_get(), o.select_get(),
                      tuple(c.name for c in o.users_collection)) for o in layer.objects)
    active = layer.objects.active.name if layer.objects.active else None
    return objects, active, sorted(m.name for m in bpy.data.meshes)


class Reports:
    """Stands in for an operator's ``report`` when a job is finished by hand."""

    def __init__(self):
        self.messages = []

    def report(self, kind, message):
        self.messages.append((set(kind), message))


# --- a panel, drawn into a recorder -------------------------------------------------------------

_UI = bpy.types.UILayout.bl_rna
_ICONS = {item.identifier for item in _UI.functions["label"].parameters["icon"].enum_items}


class Layout:
    """Records what a panel draws: labels (with alert), props (with enabled), operators.

    Strict about the API: every call, keyword, attribute and icon must exist on Blender's
    ``UILayout``, so a draw that passes here does not fail in a real sidebar."""

    def __init__(self, log, parent=None):
        object.__setattr__(self, "log", log)
        object.__setattr__(self, "parent", parent)
        object.__setattr__(self, "enabled", True)
        object.__setattr__(self, "alert", False)

    def __setattr__(self, name, value):
        assert name in _UI.properties, f"UILayout has no attribute {name!r}"
        object.__setattr__(self, name, value)

    @staticmethod
    def _check(function, positional, kwargs):
        parameters = [p.identifier for p in _UI.functions[function].parameters
                      if p.identifier != "layout"]
        assert positional <= len(parameters), f"{function}: too many arguments"
        for name in kwargs:
            assert name in parameters, f"UILayout.{function} has no keyword {name!r}"
        icon = kwargs.get("icon")
        assert icon is None or icon in _ICONS, f"no icon {icon!r}"

    def _child(self, function, args, kwargs):
        self._check(function, len(args), kwargs)
        return Layout(self.log, self)

    def row(self, *args, **kwargs):
        return self._child("row", args, kwargs)

    def column(self, *args, **kwargs):
        return self._child("column", args, kwargs)

    def box(self, *args, **kwargs):
        return self._child("box", args, kwargs)

    def split(self, *args, **kwargs):
        return self._child("split", args, kwargs)

    def _flag(self, name):
        layout = self
        while layout is not None:
            if getattr(layout, name) != (name == "enabled"):
                return name != "enabled"
            layout = layout.parent
        return name == "enabled"

    def label(self, text="", icon='NONE', **kwargs):
        self._check("label", 0, dict(kwargs, icon=icon))
        self.log.append(("label", text, icon, self._flag("alert")))

    def prop(self, data, name, text=None, **kwargs):
        self._check("prop", 2, kwargs)
        assert name in data.bl_rna.properties, f"no property {name!r}"
        self.log.append(("prop", name, text, self._flag("enabled")))

    def prop_enum(self, data, name, value, text=None, **kwargs):
        self._check("prop_enum", 3, kwargs)
        assert value in {i.identifier for i in data.bl_rna.properties[name].enum_items}
        self.log.append(("prop_enum", value, text, self._flag("enabled")))

    def operator(self, idname, text="", **kwargs):
        self._check("operator", 1, kwargs)
        category, name = idname.split(".")
        assert hasattr(getattr(bpy.ops, category), name), f"no operator {idname}"
        self.log.append(("operator", idname, text, self._flag("enabled")))

    def progress(self, text="", **kwargs):
        self._check("progress", 0, kwargs)
        self.log.append(("progress", text, None, True))


class Drawn:
    def __init__(self, log):
        self.log = log

    @property
    def labels(self):
        return [text for kind, text, _, _ in self.log if kind == "label"]

    @property
    def alerts(self):
        return [text for kind, text, _, alert in self.log if kind == "label" and alert]

    def prop(self, name):
        return next(entry for entry in self.log if entry[0] == "prop" and entry[1] == name)

    def enum(self, value):
        return next(entry for entry in self.log if entry[0] == "prop_enum" and entry[1] == value)

    @property
    def button(self):
        return next(entry for entry in self.log if entry[0] == "operator"
                    and entry[1] == "udf_reconstruction.reconstruct")


class Host:
    """Stands in for the panel (``self`` of ``draw``): holds the layout it draws into."""

    def __init__(self, layout):
        self.layout = layout
