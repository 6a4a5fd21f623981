"""The two data types that flow through the engine: point clouds and triangle meshes.

Plain numpy containers; every stage takes and returns them (or bare arrays).
"""

from dataclasses import dataclass
from typing import Optional

import numpy as np


@dataclass
class PointCloud:
    """Points with optional per-point normals and colours.

    points: (N, 3) float64; normals: (N, 3) float64 or None;
    colors: (N, 3) or (N, 4) float32 in [0, 1] (RGB or RGBA, linear as stored in the file) or None.
    """

    points: np.ndarray
    normals: Optional[np.ndarray] = None
    colors: Optional[np.ndarray] = None

    def __len__(self) -> int:
        return int(self.points.shape[0])


@dataclass
class Mesh:
    """A triangle mesh with optional per-vertex normals and colours.

    vertices: (V, 3) float64; faces: (F, 3) int64 (may be empty for a points-only file);
    normals: (V, 3) float64 or None; colors: (V, 3) or (V, 4) float32 in [0, 1] or None.
    """

    vertices: np.ndarray
    faces: np.ndarray
    normals: Optional[np.ndarray] = None
    colors: Optional[np.ndarray] = None

    def as_point_cloud(self) -> PointCloud:
        """The vertices as a point cloud (what a reconstruction reads from a mesh file)."""
        return PointCloud(self.vertices, self.normals, self.colors)
