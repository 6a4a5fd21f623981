"""Blender operators and the bpy <-> numpy bridge they share."""
