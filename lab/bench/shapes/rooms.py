"""Indoor-scene-like rooms: the ScanNet stand-in.

A room is a floor (top face only), two or three walls (single sheets facing inward) and 3-7 pieces
of furniture: tables with thin tops on legs, open-bottom cabinets (five single sheets), shelves of
thin boards, chairs. The layout (sizes, placements, scanner positions) is drawn first, so the
dataset can place the virtual scanner without rebuilding the mesh. Units are metres (z up); the
room's bounding box is exactly [0, Lx] x [0, Ly] x [0, H].
"""

from dataclasses import dataclass, field
from typing import List, Tuple

import numpy as np

from . import primitives as P

CELL = 0.08  # metres: triangle size of floor, walls and furniture sheets
ITEM_KINDS = ("table", "cabinet", "shelf", "chair")


@dataclass
class Item:
    """One piece of furniture: ``size`` (sx, sy, sz) metres about its floor centre ``(x, y)``."""

    kind: str
    x: float
    y: float
    yaw: float
    size: Tuple[float, float, float]
    seed: int


@dataclass
class RoomLayout:
    """Everything random about a room, in metres.

    size: (Lx, Ly, H); walls: names among "y0", "x0", "y1", "x1" (the plane each lies in);
    items: the furniture; viewpoints: (K, 3) scanner positions inside the room.
    """

    size: Tuple[float, float, float]
    walls: Tuple[str, ...]
    items: List[Item] = field(default_factory=list)
    viewpoints: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))


def _item_size(kind: str, rng: np.random.Generator) -> Tuple[float, float, float]:
    if kind == "table":
        return rng.uniform(0.8, 1.8), rng.uniform(0.6, 1.0), rng.uniform(0.7, 0.78)
    if kind == "cabinet":
        return rng.uniform(0.5, 1.2), rng.uniform(0.4, 0.6), rng.uniform(0.7, 1.2)
    if kind == "shelf":
        return rng.uniform(0.6, 1.2), rng.uniform(0.25, 0.4), rng.uniform(1.2, 2.0)
    return rng.uniform(0.4, 0.5), rng.uniform(0.4, 0.5), rng.uniform(0.8, 0.95)


def room_layout(seed: int) -> RoomLayout:
    """Draw a room's size, walls, furniture placement and 2-4 scanner positions from ``seed``."""
    rng = np.random.default_rng(seed)
    lx, ly, height = rng.uniform(3.5, 6.0), rng.uniform(3.0, 5.0), rng.uniform(2.4, 2.8)
    walls = ("y0", "x0") + (("y1", "x1")[rng.integers(2)],) * int(rng.random() < 0.5)
    layout = RoomLayout((lx, ly, height), walls)
    circles: List[Tuple[float, float, float]] = []
    for _ in range(rng.integers(3, 8)):
        kind = ITEM_KINDS[rng.choice(4, p=[0.3, 0.3, 0.2, 0.2])]
        size = _item_size(kind, rng)
        radius = 0.5 * np.hypot(size[0], size[1])
        for _try in range(50):
            if kind in ("cabinet", "shelf") and rng.random() < 0.6:
                yaw, x, y = 0.0, rng.uniform(radius, lx - radius), size[1] / 2 + 0.03
            else:
                yaw = rng.uniform(0, np.pi)
                x = rng.uniform(radius + 0.05, lx - radius - 0.05)
                y = rng.uniform(radius + 0.05, ly - radius - 0.05)
            if all(np.hypot(x - cx, y - cy) > radius + cr + 0.1 for cx, cy, cr in circles):
                circles.append((x, y, radius))
                layout.items.append(Item(kind, x, y, yaw, size, int(rng.integers(2 ** 31))))
                break
    views = []
    for _ in range(rng.integers(2, 5)):
        # the freest of 64 random spots: farthest outside every furniture circle
        spots = rng.uniform((0.3, 0.3), (lx - 0.3, ly - 0.3), (64, 2))
        clearance = np.full(64, np.inf)
        for cx, cy, cr in circles:
            clearance = np.minimum(clearance, np.hypot(spots[:, 0] - cx, spots[:, 1] - cy) - cr)
        free = np.flatnonzero(clearance > 0.25)
        x, y = spots[free[0]] if len(free) else spots[np.argmax(clearance)]
        views.append((x, y, rng.uniform(1.2, 1.7)))
    layout.viewpoints = np.array(views)
    return layout


def _table(size, rng) -> list:
    sx, sy, sz = size
    top = rng.uniform(0.025, 0.045)
    leg = rng.uniform(0.04, 0.07) / 2
    inset = rng.uniform(0.03, 0.1)
    parts = [P.box((0, 0, sz - top / 2), (sx / 2, sy / 2, top / 2), CELL)]
    for px in (-1, 1):
        for py in (-1, 1):
            c = (px * (sx / 2 - inset - leg), py * (sy / 2 - inset - leg), (sz - top) / 2)
            parts.append(P.box(c, (leg, leg, (sz - top) / 2), CELL))
    return parts


def _cabinet(size, rng) -> list:
    sx, sy, sz = size
    parts = [P.box((0, 0, sz / 2), (sx / 2, sy / 2, sz / 2), CELL, skip=("-z",))]
    if rng.random() < 0.5:  # a second open box stacked on top (a hutch)
        h2 = rng.uniform(0.3, 0.6)
        parts.append(P.box((0, -sy * 0.2, sz + h2 / 2 + 0.002), (sx / 2 * 0.9, sy * 0.3, h2 / 2),
                           CELL, skip=("-z",)))
    return parts


def _shelf(size, rng) -> list:
    sx, sy, sz = size
    board = rng.uniform(0.015, 0.03) / 2
    parts = [P.box((side * (sx / 2 - board), 0, sz / 2), (board, sy / 2, sz / 2), CELL)
             for side in (-1, 1)]
    for z in np.linspace(0.08, sz - board, rng.integers(3, 7)):
        parts.append(P.box((0, 0, z), (sx / 2 - 2 * board - 0.002, sy / 2, board), CELL))
    if rng.random() < 0.6:
        parts.append(P.box((0, -sy / 2 + board, sz / 2),
                           (sx / 2 - 2 * board - 0.002, board, sz / 2 - 0.01), CELL))
    return parts


def _chair(size, rng) -> list:
    sx, sy, sz = size
    seat_z, seat_t = rng.uniform(0.42, 0.48), rng.uniform(0.03, 0.05)
    leg = 0.015
    parts = [P.box((0, 0, seat_z - seat_t / 2), (sx / 2, sy / 2, seat_t / 2), CELL)]
    for px in (-1, 1):
        for py in (-1, 1):
            c = (px * (sx / 2 - leg - 0.01), py * (sy / 2 - leg - 0.01), (seat_z - seat_t) / 2)
            parts.append(P.box(c, (leg, leg, (seat_z - seat_t) / 2), CELL))
    back = sz - seat_z
    parts.append(P.box((0, -sy / 2 + 0.02, seat_z + back / 2), (sx / 2, 0.015, back / 2), CELL))
    return parts


_BUILDERS = {"table": _table, "cabinet": _cabinet, "shelf": _shelf, "chair": _chair}


def _walls(layout: RoomLayout) -> list:
    lx, ly, h = layout.size
    sheets = {  # origin, edge u, edge v with u x v pointing into the room
        "y0": ((0, 0, 0), (0, 0, h), (lx, 0, 0)),
        "x0": ((0, 0, 0), (0, ly, 0), (0, 0, h)),
        "y1": ((0, ly, 0), (lx, 0, 0), (0, 0, h)),
        "x1": ((lx, 0, 0), (0, 0, h), (0, ly, 0)),
    }
    return [P.plane(*sheets[name], CELL) for name in layout.walls]


def build_room(layout: RoomLayout) -> P.Part:
    """Mesh a layout: vertices (V, 3) float64 metres, faces (F, 3) int64."""
    lx, ly, _ = layout.size
    parts = [P.plane((0, 0, 0), (lx, 0, 0), (0, ly, 0), CELL)] + _walls(layout)
    for item in layout.items:
        rng = np.random.default_rng(item.seed)
        for part in _BUILDERS[item.kind](item.size, rng):
            parts.append(P.transform(part, P.rotation_z(item.yaw), (item.x, item.y, 0.0)))
    return P.concat(parts)


def make_room(seed: int) -> P.Part:
    """One room in metres: ``build_room(room_layout(seed))``."""
    return build_room(room_layout(seed))
