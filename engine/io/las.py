"""LAS and LAZ through laspy (lazrs decompresses LAZ). The header, VLRs and LAZ chunk table
are checked against the file size first: a corrupt LAZ can make lazrs abort the process."""

import os
import struct

import numpy as np

from ..geometry import Mesh
from .common import BadFile, byte_count, scaled_colors


def read_las(path: str) -> Mesh:
    _check_las_header(path)  # before laspy: a bad LAZ can make lazrs abort the process
    import laspy  # only LAS/LAZ users need it

    try:
        las = laspy.read(path)
    except laspy.errors.LaspyException as error:
        if "backend" in str(error).lower():
            raise BadFile("cannot decompress LAZ; install the 'lazrs' package "
                           "(pip install 'laspy[lazrs]')") from None
        raise BadFile(f"not a readable LAS/LAZ file ({error})") from None
    except MemoryError:
        raise BadFile("not a readable LAS/LAZ file (its point count does not fit in "
                       "memory)") from None
    except Exception as error:  # lazrs.LazrsError and the like: a corrupt compressed body
        raise BadFile(f"the LAS/LAZ point data is corrupt or truncated "
                       f"({type(error).__name__}: {str(error)[:120]})") from None
    # las.x etc. apply the file's scale and offset.
    vertices = np.stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)], axis=1)
    colors = None
    if "red" in las.point_format.dimension_names:
        rgb = np.stack([np.asarray(las.red), np.asarray(las.green), np.asarray(las.blue)], 1)
        colors = scaled_colors(rgb, 65535)
    return Mesh(vertices.astype(np.float64), np.zeros((0, 3), np.int64), None, colors)


_LASZIP_USER = b"laszip encoded"
_LASZIP_RECORD = 22204


def _check_las_header(path: str) -> None:
    """Check a LAS/LAZ header against the file's size before any point is decompressed.

    The header's sizes and offsets must lie inside the file, the VLRs must end before the
    point data, an uncompressed body must hold every point it claims, and a LAZ file's chunk
    table must lie inside the file and list no more chunks than its point count allows. A
    corrupt or truncated LAZ passing these is still caught when lazrs decodes it; these
    checks refuse the files that would make lazrs allocate absurd amounts (and abort).
    """
    size = os.path.getsize(path)
    with open(path, "rb") as file:
        header = file.read(375)
        if len(header) < 4 or header[:4] != b"LASF":
            raise BadFile("not a LAS/LAZ file (it does not start with 'LASF')")
        if len(header) < 227:
            raise BadFile(f"the LAS header is truncated: the file has {size} bytes, a header "
                           f"needs at least 227")
        minor = header[25]
        header_size, point_offset, vlr_count = struct.unpack_from("<HII", header, 94)
        format_id, record_length, legacy_count = struct.unpack_from("<BHI", header, 104)
        count = legacy_count
        if minor >= 4 and header_size >= 375 and len(header) >= 255:
            count = struct.unpack_from("<Q", header, 247)[0] or legacy_count
        if not 227 <= header_size <= point_offset <= size:
            raise BadFile(f"the LAS header is corrupt: header size {header_size} and point "
                           f"data offset {point_offset} do not fit a file of {size:,} bytes")
        if record_length == 0:
            raise BadFile("the LAS header is corrupt: a point record length of 0")
        chunk_size = None
        at = header_size
        for _ in range(vlr_count):
            if at + 54 > point_offset:
                raise BadFile(f"the LAS header lists {vlr_count} VLRs, but they run past "
                               f"the start of the point data at byte {point_offset}")
            file.seek(at)
            vlr = file.read(54)
            length = struct.unpack_from("<H", vlr, 20)[0]
            if vlr[2:18].rstrip(b"\0") == _LASZIP_USER and struct.unpack_from(
                    "<H", vlr, 18)[0] == _LASZIP_RECORD and length >= 16:
                chunk_size = struct.unpack_from("<I", file.read(16), 12)[0]
            at += 54 + length
        if at > point_offset:
            raise BadFile(f"the LAS VLRs run past the start of the point data at byte "
                           f"{point_offset}")
        compressed = bool(format_id & 0xC0)
        body = size - point_offset
        if not compressed:
            if count * record_length > body:
                raise BadFile(f"the file claims {count:,} points of {record_length} bytes "
                               f"({count * record_length:,} bytes) but holds {body:,} bytes "
                               f"of point data: it is truncated or corrupt")
            return
        if chunk_size is None:
            raise BadFile("a compressed LAZ file without its 'laszip encoded' VLR")
        if count and body < 8 + record_length:
            raise BadFile(f"the LAZ point data is truncated ({byte_count(body)} for "
                           f"{count:,} points)")
        if count == 0:
            return
        file.seek(point_offset)
        table_offset = struct.unpack("<q", file.read(8))[0]
        if table_offset == -1:
            return  # written without a chunk table (streamed); lazrs reads chunk by chunk
        if not point_offset + 8 <= table_offset <= size - 8:
            raise BadFile(f"the LAZ chunk table offset {table_offset:,} lies outside the "
                           f"file ({size:,} bytes): it is truncated or corrupt")
        file.seek(table_offset)
        table_version, chunks = struct.unpack("<II", file.read(8))
        most = count if chunk_size in (0, 0xFFFFFFFF) else -(-count // chunk_size)
        if table_version != 0 or not 1 <= chunks <= min(most, table_offset - point_offset):
            raise BadFile(f"the LAZ chunk table is corrupt (version {table_version}, "
                           f"{chunks:,} chunks for {count:,} points): the file is truncated "
                           f"or has been altered")
