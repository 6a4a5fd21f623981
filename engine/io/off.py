"""OFF with its C (colour), N (normal) and ST (texture) variants; written as [C][N]OFF.

Our own reader and writer rather than trimesh's: trimesh reads and writes only positions and
faces, so COFF colours and NOFF normals would be lost.
"""

import re
from typing import List

import numpy as np

from ..geometry import Mesh
from .common import BadFile, fan, fan_lists, number_table, text_colors, text_lines, write_rows


_OFF_KEYWORD = re.compile(rb"^(ST)?(C)?(N)?(4)?(n)?OFF$")


def read_off(path: str) -> Mesh:
    with open(path, "rb") as file:
        data = file.read()
    lines = text_lines(data)
    if not lines:
        raise BadFile("the file is empty")
    words = lines[0].split()
    keyword = _OFF_KEYWORD.match(words[0])
    if keyword is None:
        raise BadFile("not an OFF file (the first line is not 'OFF', 'COFF', 'NOFF', ...)")
    has_st, has_color, has_normal, four_d, n_dim = keyword.groups()
    if four_d or n_dim:
        raise BadFile("4-D and n-D OFF files are not supported; use 3-D vertices")
    counts, body = words[1:], lines[1:]
    if not counts:
        if not body:
            raise BadFile("the file ends before the vertex and face counts")
        counts, body = body[0].split(), body[1:]
    try:
        vertex_count, face_count = int(counts[0]), int(counts[1])
    except (ValueError, IndexError):
        raise BadFile("the line after 'OFF' must give the vertex and face counts") from None
    if vertex_count < 0 or face_count < 0:
        raise BadFile(f"the header gives {vertex_count} vertices and {face_count} faces; "
                       f"counts cannot be negative")
    if len(body) < vertex_count:
        raise BadFile(f"the file ends after {len(body)} of {vertex_count} vertices")
    if len(body) < vertex_count + face_count:
        raise BadFile(f"the file ends after {len(body) - vertex_count} of {face_count} faces")
    if len(body) > vertex_count + face_count:
        extra = len(body) - vertex_count - face_count
        raise BadFile(f"the header gives {vertex_count} vertices and {face_count} faces, but "
                       f"the file has {extra} more line{'s' if extra > 1 else ''}: the counts "
                       f"in the header are probably wrong")
    table = number_table(body[:vertex_count], "a vertex")
    if vertex_count and table.shape[1] < 3:
        raise BadFile("a vertex has fewer than 3 coordinates")
    vertices, at = table[:, :3], 3
    normals = None
    if has_normal and table.shape[1] >= at + 3:
        normals, at = table[:, at:at + 3], at + 3
    colors = None
    channels = table.shape[1] - at - (2 if has_st else 0)
    if has_color and channels in (3, 4):
        colors = text_colors(table[:, at:at + channels])
    return Mesh(vertices, _off_faces(body[vertex_count:vertex_count + face_count]),
                normals, colors)


def _off_faces(rows: List[bytes]) -> np.ndarray:
    """OFF face lines ``n i1 .. in [colour]`` -> fan-triangulated (F, 3) int64."""
    if not rows:
        return np.zeros((0, 3), np.int64)
    table = number_table(rows, "a face")
    sizes = table[:, 0]
    if len(table) and table.shape[1] > sizes[0] and np.all(sizes == sizes[0]):
        corners = table[:, :1 + int(sizes[0])]
        if np.all(corners == np.round(corners)):  # else the loop names the bad line
            return fan(corners[:, 1:])
    polygons = []
    for number, row in enumerate(rows, 1):
        values = row.split()
        try:
            size = int(values[0])
            corners = [int(v) for v in values[1:size + 1]]
        except ValueError:
            raise BadFile(f"face line {number} ({row[:40].decode('utf-8', 'replace')!r}) is "
                           f"not 'n i1 .. in' with whole numbers; if it is a vertex, the "
                           f"vertex count in the header is too small") from None
        if size < 0:
            raise BadFile(f"face line {number} has a negative vertex count {size}")
        if len(values) < size + 1:
            raise BadFile(f"a face lists {size} vertices but gives only {len(values) - 1}")
        polygons.append(corners)
    return fan_lists(polygons)


def write_off(file, vertices, faces, normals, colors) -> None:
    keyword = ("C" if colors is not None else "") + ("N" if normals is not None else "") + "OFF"
    file.write(f"{keyword}\n{len(vertices)} {len(faces)} 0\n".encode("ascii"))
    columns, row_format = [vertices], "%.17g %.17g %.17g"
    if normals is not None:
        columns.append(normals)
        row_format += " %.9g %.9g %.9g"
    if colors is not None:
        columns.append(colors)
        row_format += " %.6g" * colors.shape[1]
    write_rows(file, row_format + "\n", np.concatenate(columns, axis=1))
    write_rows(file, "3 %d %d %d\n", faces)
