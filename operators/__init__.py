"""Blender operators: Reconstruct, Cancel and Install Missing Packages (what they share with the
panel lives in ``runtime/``)."""
