"""Point clouds as text columns (XYZ, PTS, TXT): x y z, then optional intensity, normals and
colours. trimesh has no reader for these."""

from typing import Optional

import numpy as np

from ..geometry import Mesh
from .common import BadFile, numbers, scaled_colors


def read_columns(path: str) -> Mesh:
    """Text columns: x y z, then optional intensity, normals and colours (see _split_columns).

    Separators are whitespace, commas or semicolons; ``#`` and ``//`` start comments; a line
    holding one whole number (a PTS point count) is skipped; a first line with no numbers
    (column names) is skipped.
    """
    with open(path, "rb") as file:
        data = file.read()
    rows = []
    for line in data.replace(b",", b" ").replace(b";", b" ").splitlines():
        line = line.split(b"#", 1)[0].split(b"//", 1)[0].strip()
        if line and not line.isdigit():
            rows.append(line)
    if rows and not any(_is_number(word) for word in rows[0].split()):
        rows = rows[1:]
    if not rows:
        raise BadFile("the file contains no points")
    width = len(rows[0].split())
    tokens = b" ".join(rows).split()
    if len(tokens) != width * len(rows):
        bad = next(i for i, row in enumerate(rows) if len(row.split()) != width)
        raise BadFile(f"data line {bad + 1} has {len(rows[bad].split())} values, but the "
                       f"first data line has {width}; every line needs the same columns")
    table = numbers(tokens, "the point data").reshape(len(rows), width)
    return split_columns(table)


def _is_number(word: bytes) -> bool:
    try:
        float(word)
        return True
    except ValueError:
        return False


def split_columns(table: np.ndarray) -> Mesh:
    """Columns of numbers -> points with optional normals and colours.

    3: x y z; 4: x y z intensity; 6: x y z + triple; 7: x y z intensity + triple (PTS);
    9: x y z + triple + triple; 10: x y z intensity + two triples; other widths >= 3: x y z
    and the rest ignored. Intensity is ignored; each triple is classified by
    :func:`_triple_kind`.
    """
    if table.ndim != 2 or table.shape[1] < 3:
        raise BadFile(f"needs at least 3 columns (x y z), found "
                       f"{table.shape[1] if table.ndim == 2 else table.ndim}")
    starts = {6: [3], 7: [4], 9: [3, 6], 10: [4, 7]}.get(table.shape[1], [])
    normals = colors = None
    for start in starts:
        triple = table[:, start:start + 3]
        kind = _triple_kind(triple)
        if kind == "normals" and normals is None:
            normals = triple
        elif kind == "colors255" and colors is None:
            colors = scaled_colors(triple, 255)
        elif kind == "colors" and colors is None:
            colors = scaled_colors(triple, None)
    return Mesh(table[:, :3], np.zeros((0, 3), np.int64), normals, colors)


def _triple_kind(triple: np.ndarray) -> Optional[str]:
    """Decide whether three columns are normals or colours; the first rule that fits wins.

    1. every value a whole number in 0..255 and some value above 1 -> ``colors255`` (/255);
    2. some value negative, or every row of unit length (within 0.01) -> ``normals``;
    3. every value in [0, 1] -> ``colors``;
    4. otherwise ``None``: the columns are ignored.
    """
    if triple.size == 0 or not np.isfinite(triple).all():
        return None
    low, high = triple.min(), triple.max()
    if low >= 0 and high <= 255 and high > 1 and np.all(triple == np.round(triple)):
        return "colors255"
    if low < 0 or np.all(np.abs(np.linalg.norm(triple, axis=1) - 1.0) < 0.01):
        return "normals"
    if low >= 0 and high <= 1:
        return "colors"
    return None
