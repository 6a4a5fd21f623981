"""DCUDF mesh extraction from unsigned distance fields: :func:`extract_surface` is the entry."""

from .extract import MeshingResult, MeshingSettings, extract_surface
from ..udf_grid import UDFGrid

__all__ = ["extract_surface", "MeshingSettings", "MeshingResult", "UDFGrid"]
