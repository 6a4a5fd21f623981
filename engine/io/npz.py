"""NumPy files: an (N, 3|6) NPY array, or an NPZ archive of ``points``/``vertices``,
``normals``, ``colors`` and ``faces``. Every NPY header is checked against the bytes that
follow it before anything is allocated, so a corrupt header gives one message."""

import os
import zipfile
import zlib
from typing import List, Tuple

import numpy as np

from ..errors import InputError
from ..geometry import Mesh
from .clouds import split_columns
from .common import BadFile, byte_count, fan, scaled_colors


def read_npy(path: str) -> Mesh:
    with open(path, "rb") as file:
        array = _npy_array(file, os.fstat(file.fileno()).st_size, "the file")
    if array.dtype.kind not in "iuf":
        raise BadFile("the NPY file must hold a numeric (N, 3) or (N, 6) array")
    if array.ndim != 2 or array.shape[1] not in (3, 6):
        raise BadFile(f"the array has shape {array.shape}; expected (N, 3) points or "
                       f"(N, 6) points with normals or colours")
    return split_columns(array.astype(np.float64))


def _npy_array(stream, size: int, what: str) -> np.ndarray:
    """One NPY array from ``stream`` holding ``size`` bytes; the header is checked first.

    The header's shape and dtype must describe exactly the bytes that follow, so a corrupt
    header (bad syntax, an absurd shape such as a claimed 2 TiB array, object arrays) is
    refused in one message before anything is allocated.
    """
    from numpy.lib import format as npy_format

    try:
        version = npy_format.read_magic(stream)
        if version == (1, 0):
            shape, fortran, dtype = npy_format.read_array_header_1_0(stream)
        elif version == (2, 0):
            shape, fortran, dtype = npy_format.read_array_header_2_0(stream)
        else:
            shape, fortran, dtype = npy_format._read_array_header(stream, version)
    except Exception as error:  # the header parser raises ValueError, SyntaxError, TokenError...
        detail = str(error.args[0] if error.args else "") or type(error).__name__
        raise BadFile(f"{what} has a corrupt NPY header "
                       f"({detail.splitlines()[0][:120]})") from None
    dtype = np.dtype(dtype)
    if dtype.hasobject or dtype.itemsize == 0:
        raise BadFile(f"{what} holds {dtype} values; expected numbers")
    if any(not isinstance(n, int) or n < 0 for n in shape):
        raise BadFile(f"{what} claims the impossible shape {shape}")
    needed = dtype.itemsize * int(np.prod(shape, dtype=object))
    available = size - stream.tell()
    if needed > available:
        raise BadFile(f"{what} claims a {shape} array of {dtype} ({byte_count(needed)}), but "
                       f"only {byte_count(available)} follow its header: the file is truncated "
                       f"or its header is corrupt")
    data = stream.read(needed)
    if len(data) != needed:
        raise BadFile(f"{what} ends after {byte_count(len(data))} of {byte_count(needed)}")
    return np.frombuffer(data, dtype).reshape(shape, order="F" if fortran else "C")


_NPZ_KEYS = ("points", "vertices", "normals", "colors", "faces")


def read_npz_arrays(path, keys) -> Tuple[dict, List[str]]:
    """The arrays ``keys`` of an NPZ archive, each header checked before anything is read.

    Returns ``(arrays, names)``: the arrays found among ``keys`` and the names of every array
    in the archive. Members not in ``keys`` are never read, however big they claim to be.

    Raises
    ------
    InputError
        The file is missing, not an NPZ archive, truncated, or has a corrupt member, with one
        message naming the file.
    """
    path = os.fspath(path)
    name = os.path.basename(path) or path
    try:
        return _npz_members(path, keys)
    except BadFile as error:
        raise InputError(f"{name}: {error}") from None
    except OSError as error:
        raise InputError(f"{name}: cannot be read ({error.strerror or error})") from None


def _npz_members(path: str, keys) -> Tuple[dict, List[str]]:
    try:
        with zipfile.ZipFile(path) as archive:
            members = {info.filename[:-4]: info for info in archive.infolist()
                       if info.filename.endswith(".npy")}
            arrays = {}
            for key in keys:  # only what is asked for: a huge extra member is never read
                info = members.get(key)
                if info is None:
                    continue
                if info.file_size > 1100 * info.compress_size + (1 << 20):  # deflate gives < 1032:1
                    raise BadFile(f"'{key}' claims {byte_count(info.file_size)} uncompressed from "
                                   f"{byte_count(info.compress_size)}: the archive is corrupt")
                with archive.open(info) as stream:
                    arrays[key] = _npy_array(stream, info.file_size, f"'{key}'")
    except zipfile.BadZipFile as error:
        with open(path, "rb") as file:
            single = file.read(6) == b"\x93NUMPY"
        if single:
            raise BadFile("not an NPZ archive (it holds a single NPY array)") from None
        raise BadFile(f"not a readable NPZ archive ({error})") from None
    except (zlib.error, EOFError, NotImplementedError, RuntimeError) as error:
        raise BadFile(f"not a readable NPZ archive ({error})") from None
    return arrays, sorted(members)


def read_npz(path: str) -> Mesh:
    arrays, members = _npz_members(path, _NPZ_KEYS)
    key = "points" if "points" in arrays else "vertices" if "vertices" in arrays else None
    if key is None:
        raise BadFile(f"has no 'points' or 'vertices' array (it has: "
                       f"{', '.join(sorted(members)) or 'nothing'})")
    vertices = _npz_array(arrays, key, (3,))
    normals = _npz_array(arrays, "normals", (3,)) if "normals" in arrays else None
    colors = None
    if "colors" in arrays:
        raw = _npz_array(arrays, "colors", (3, 4))
        colors = scaled_colors(raw, np.iinfo(raw.dtype).max if raw.dtype.kind in "iu" else None)
    faces = np.zeros((0, 3), np.int64)
    if "faces" in arrays:
        raw = arrays["faces"]
        if raw.ndim != 2 or raw.dtype.kind not in "iu":
            raise BadFile(f"'faces' must be an (F, 3) integer array, not {raw.dtype} "
                           f"with shape {raw.shape}")
        faces = fan(raw)
    for name, values in (("normals", normals), ("colors", colors)):
        if values is not None and len(values) != len(vertices):
            raise BadFile(f"'{name}' has {len(values)} rows but '{key}' has {len(vertices)}")
    return Mesh(vertices, faces, normals, colors)


def _npz_array(arrays: dict, key: str, widths: Tuple[int, ...]) -> np.ndarray:
    array = arrays[key]
    if array.ndim != 2 or array.shape[1] not in widths or array.dtype.kind not in "iuf":
        raise BadFile(f"'{key}' must be a numeric (N, {' or '.join(map(str, widths))}) "
                       f"array, not {array.dtype} with shape {array.shape}")
    return array
