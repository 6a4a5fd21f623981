"""What every reader shares: the error a reader raises, the final checks of its result, and
vectorised helpers for text numbers, polygons and colours."""

import re
from typing import List, Optional

import numpy as np

from ..geometry import Mesh


class BadFile(Exception):
    """A problem inside a file; :func:`engine.io.read_mesh` prefixes the file name and raises
    InputError."""


def checked(mesh: Mesh) -> Mesh:
    """Common checks and dtypes for every reader's result."""
    vertices = np.ascontiguousarray(mesh.vertices, dtype=np.float64).reshape(-1, 3)
    if len(vertices) == 0:
        raise BadFile("the file contains no points")
    faces = np.ascontiguousarray(mesh.faces, dtype=np.int64).reshape(-1, 3)
    if faces.size and (faces.min() < 0 or faces.max() >= len(vertices)):
        bad = faces[(faces < 0) | (faces >= len(vertices))][0]
        raise BadFile(f"a face refers to vertex {bad}, but there are only {len(vertices)} "
                      f"vertices (numbered from 0)")
    normals = mesh.normals
    if normals is not None:
        normals = np.ascontiguousarray(normals, dtype=np.float64).reshape(-1, 3)
    colors = mesh.colors
    if colors is not None:
        colors = np.clip(np.asarray(colors, dtype=np.float32), 0.0, 1.0)
        colors = np.ascontiguousarray(colors.reshape(len(colors), -1))
    return Mesh(vertices, faces, normals, colors)


def fan(polygons: np.ndarray) -> np.ndarray:
    """Fan-triangulate polygons that all have the same vertex count.

    polygons : (P, n) int -> (P * (n - 2), 3) int64; empty for n < 3 (points and edges).
    """
    polygons = np.asarray(polygons, dtype=np.int64)
    count = polygons.shape[1]
    if count < 3:
        return np.zeros((0, 3), np.int64)
    fans = [np.stack([polygons[:, 0], polygons[:, i], polygons[:, i + 1]], axis=1)
            for i in range(1, count - 1)]
    # Keep each polygon's triangles together, in order.
    return np.stack(fans, axis=1).reshape(-1, 3)


def fan_lists(polygons: List[List[int]]) -> np.ndarray:
    """Fan-triangulate polygons of mixed sizes (given as Python lists) -> (T, 3) int64."""
    triangles = [(p[0], p[i], p[i + 1]) for p in polygons for i in range(1, len(p) - 1)]
    return np.array(triangles, dtype=np.int64).reshape(-1, 3)


def scaled_colors(values: np.ndarray, integer_max: Optional[int]) -> np.ndarray:
    """Colour channels -> float32 in [0, 1]; integer storage is divided by its full scale."""
    values = np.asarray(values, dtype=np.float64)
    if integer_max:
        values = values / integer_max
    return np.clip(values, 0.0, 1.0).astype(np.float32)


def text_colors(values: np.ndarray) -> np.ndarray:
    """Colours written as text: 0..255 when any channel exceeds 1, otherwise floats in [0, 1]."""
    return scaled_colors(values, 255 if values.size and values.max() > 1.0 else None)


def numbers(tokens: List[bytes], what: str) -> np.ndarray:
    """Convert text tokens to float64 in one call; name the first bad token on failure."""
    try:
        return np.array(tokens, dtype=np.float64)
    except ValueError:
        for token in tokens:
            try:
                float(token)
            except ValueError:
                text = token.decode("utf-8", "replace")[:40]
                raise BadFile(f"{what}: {text!r} is not a number") from None
        raise


def number_table(rows: List[bytes], what: str) -> np.ndarray:
    """Rows of whitespace-separated numbers -> (R, C) float64 (C = the shortest row's length).

    One token split and one conversion when every row has the same length; rows of mixed
    length (e.g. OBJ vertices with and without colour) are cut to the shortest.
    """
    if not rows:
        return np.zeros((0, 0))
    width = len(rows[0].split())
    tokens = b" ".join(rows).split()
    if len(tokens) == width * len(rows):
        return numbers(tokens, what).reshape(len(rows), width)
    split = [row.split() for row in rows]
    width = min(len(row) for row in split)
    return numbers([t for row in split for t in row[:width]], what).reshape(len(rows), width)


def strip_comments(data: bytes) -> bytes:
    """Text with ``#`` comments removed (to the end of each line)."""
    return re.sub(rb"#[^\r\n]*", b"", data) if b"#" in data else data


def text_lines(data: bytes) -> List[bytes]:
    """Non-empty, stripped lines with ``#`` comments removed."""
    return [line for line in (raw.strip() for raw in strip_comments(data).splitlines()) if line]


def write_rows(file, row_format: str, rows: np.ndarray) -> None:
    """Write each row of ``rows`` with the %-format ``row_format`` (ASCII)."""
    file.write("".join(row_format % tuple(row) for row in rows.tolist()).encode("ascii"))


def byte_count(count: int) -> str:
    """A byte count for people: '912 bytes', '3.1 MiB', '2.18 TiB'."""
    if count < 1024:
        return f"{count} bytes"
    for unit in ("KiB", "MiB", "GiB", "TiB", "PiB"):
        count /= 1024.0
        if count < 1024 or unit == "PiB":
            return f"{count:.3g} {unit}"
