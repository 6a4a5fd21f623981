"""Blender user interface: scene settings, the N-panel and the preferences."""
