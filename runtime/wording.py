"""What the user reads: short progress labels, sentence-case messages, and which of the engine's
notes are worth showing (no bpy here).

The engine's progress messages and notes are written for logs ("network UDF: 49,152 / 84,297
queries", "iso raised from 1.00 to 1.25 voxels"). The sidebar has room for a word and a
percentage, and the Info log should only hold what a user can act on; the rest goes to the system
console.
"""

import re

# First match wins: a word in the engine's progress message -> the stage shown to the user.
_STAGES = (
    ("outlier", "Outliers"),
    ("gaps", "Gap fill"),
    ("preparing", "Preparing"),
    ("band", "Distances"),
    ("udf", "Distances"),
    ("radi", "Distances"),
    ("field", "Distances"),
    ("quer", "Distances"),
    ("marching", "Meshing"),
    ("optimis", "Meshing"),
    ("optimiz", "Meshing"),
    ("splitting", "Meshing"),
    ("meshing", "Meshing"),
    ("cut", "Meshing"),
    ("layer", "Meshing"),
    ("cover", "Meshing"),
    ("clean", "Meshing"),
    ("stitch", "Stitching"),
    ("tile", "Tiles"),  # "4 of 9 tiles done on 2 workers"
    ("mapping", "Finishing"),
    ("done", "Finishing"),
)


def stage_name(message: str, previous: str = "Working") -> str:
    """A one-word stage for an engine progress message ("network UDF: 3 / 8 queries" ->
    "Distances"); ``previous`` (the stage shown before) for messages it does not know."""
    lowered = (message or "").lower()
    for word, stage in _STAGES:
        if word in lowered:
            return stage
    return previous


def progress_text(message: str, fraction: float, stage: str = None) -> str:
    """Short enough for the sidebar: ``"Distances 58 %"`` (``stage`` instead of the one the
    message names, when given)."""
    percent = int(min(max(fraction, 0.0), 1.0) * 100 + 1e-6)
    return f"{stage or stage_name(message)} {percent} %"


def sentence(text: str) -> str:
    """``text`` with a capital first letter and a full stop, as every report is written."""
    text = (text or "").strip()
    if not text:
        return text
    text = text[0].upper() + text[1:]
    if text[-1] not in ".!?)":
        text += "."
    return text


_OUTLIERS = re.compile(r"dropped ([\d,]+) isolated points? \(((?:under )?[\d.]+) %\)")
_KEPT = re.compile(r"kept ([\d,]+) isolated points? \(((?:under )?[\d.]+) %\)")
_SPARSE = re.compile(r"the balls hold only ([\d.]+) points")
_GAPS = re.compile(r"the scan has gaps wider than the ball in places \((\d+) %")


def _plural(count: str, noun: str) -> str:
    """``noun`` or its plural, for a count as the engine wrote it ("1", "1,024")."""
    return noun if count == "1" else noun + "s"


def radius_control(radius_mode: str, custom_range: bool) -> str:
    """The panel control that makes the balls larger in this radius mode."""
    if radius_mode == "fixed":
        return "Radius"
    return "Largest Radius" if custom_range else "Largest Radius (turn on Custom Range)"


def user_notices(messages, radius_mode: str = "fixed", custom_range: bool = False) -> list:
    """The engine notes a user can act on, reworded: what happened and what to do about it.

    Every other note (the mesher's iso-value, cut and piece diagnostics) is for the system
    console only.
    """
    radius = radius_control(radius_mode, custom_range)
    notices = []
    for message in messages:
        match = _OUTLIERS.search(message)
        if match:
            notices.append(f"Dropped {match.group(1)} stray {_plural(match.group(1), 'point')} "
                           f"({match.group(2)} %) before meshing. To use every point, set Advanced > Outliers to Keep.")
            continue
        match = _KEPT.search(message)
        if match:
            notices.append(f"Kept {match.group(1)} stray-looking "
                           f"{_plural(match.group(1), 'point')} ({match.group(2)} %): "
                           f"too few to drop. To remove them, set Advanced > Outliers to Drop.")
            continue
        match = _SPARSE.search(message)
        if match:
            notices.append(f"The points are sparse for this radius (about {match.group(1)} "
                           f"around each spot). If the mesh has holes, raise {radius}.")
            continue
        match = _GAPS.search(message)
        if match:
            notices.append(f"The scan has gaps wider than the ball around {match.group(1)} % of "
                           f"the spots looked at. To bridge the flat ones, turn on Advanced > "
                           f"Fill Gaps.")
    return notices
