"""A generated floor of furnished rooms in metres, scanned from the positions of each room.

Rooms (``lab.bench.shapes.rooms``) are laid out on a grid ``PITCH`` metres apart, each with its
own walls, furniture and 2-4 scanner positions. Each room is scanned on its own (its walls hide
the others) to the same number of points, so the cloud grows with the floor's area. The ground
truth is exact: the rooms' meshes.
"""

import math
from typing import Tuple

import numpy as np

from engine.geometry import Mesh

from .scan import virtual_scan
from .shapes.rooms import build_room, room_layout

PITCH = (6.5, 5.5)
"""Metres between the rooms' corners along x and y (rooms are at most 6 x 5 m)."""
_STREAM_SCAN = 11


def make_floor(rooms: int, seed: int = 0) -> Tuple[Mesh, list]:
    """``rooms`` rooms on a near-square grid.

    Returns
    -------
    mesh : Mesh, the whole floor (metres)
    parts : list of ``(Mesh, viewpoints (K, 3))`` per room, in the floor's coordinates
    """
    columns = math.ceil(math.sqrt(rooms))
    parts = []
    for number in range(rooms):
        layout = room_layout(seed * 1000 + number)
        vertices, faces = build_room(layout)
        offset = np.array([(number % columns) * PITCH[0], (number // columns) * PITCH[1], 0.0])
        parts.append((Mesh(np.asarray(vertices) + offset, np.asarray(faces)),
                      np.asarray(layout.viewpoints) + offset))
    offsets = np.cumsum([0] + [len(mesh.vertices) for mesh, _ in parts])
    mesh = Mesh(np.concatenate([mesh.vertices for mesh, _ in parts]),
                np.concatenate([mesh.faces + o for (mesh, _), o in zip(parts, offsets)]))
    return mesh, parts


def scan_floor(parts: list, points: int, seed: int = 0) -> Tuple[np.ndarray, np.ndarray]:
    """``points`` points in all, the same number per room, each room scanned from its own
    positions. Returns points (N, 3) and the normals of the faces they lie on (N, 3)."""
    per_room = points // len(parts)
    clouds, normals = [], []
    for number, (mesh, viewpoints) in enumerate(parts):
        rng = np.random.default_rng([seed, number, _STREAM_SCAN])
        # the scanner's density and depth tolerance in metres (virtual_scan's defaults are for
        # a room in the unit frame: 0.16 and 0.002 of about 5 m)
        room_points, room_normals = virtual_scan(mesh, per_room, rng, viewpoints=viewpoints,
                                                 near=0.8, slack=0.01)
        clouds.append(room_points)
        normals.append(room_normals)
    return np.concatenate(clouds), np.concatenate(normals)
