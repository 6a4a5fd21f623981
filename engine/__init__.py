"""UDF Reconstruction engine: point clouds in, meshes out.

Everything that computes lives here and never imports bpy. Heavy dependencies (torch, scipy,
scikit-image) are imported inside the functions that need them, so importing the engine is fast.
Run ``python -m engine --help`` from the repository root for the command-line interface.
"""

__version__ = "0.1.0"
