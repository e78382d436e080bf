"""Whether a PLY file holds the rows its header declares. open3d reads a file cut short (a copy or a write
interrupted) without a word, keeping the header's vertex count; plyfile notices, but reads list properties (faces)
row by row in Python. This checks the header's counts against the file's size (binary) or line count (ASCII)
without reading the rows."""

from __future__ import annotations

from pathlib import Path

_PLY_SIZES = {"char": 1, "uchar": 1, "int8": 1, "uint8": 1, "short": 2, "ushort": 2, "int16": 2, "uint16": 2,
              "int": 4, "uint": 4, "int32": 4, "uint32": 4, "float": 4, "float32": 4, "double": 8, "float64": 8}


def ply_cut_short(path: Path) -> str | None:
    """Why a PLY file holds fewer rows than its header declares (a copy or write cut short), or None. open3d
    reads such a file without a word, keeping the header's vertex count, so a mesh cut in half scored as a
    reconstruction with half its surface. Binary: the body must hold every row, a list (a face) at least 3
    items; ASCII: a line per row."""
    with open(path, "rb") as f:
        head = f.read(65536)
    end = head.find(b"end_header")
    if not head.startswith(b"ply") or end < 0:
        return None  # not a PLY header we can read: left to the reader
    body = len(head[head.index(b"\n", end) + 1:]) if b"\n" in head[end:] else 0
    lines = head[:end].decode("ascii", "replace").splitlines()
    fmt, need, rows, count = "", 0, 0, 0
    for line in lines:
        t = line.split()
        if t[:1] == ["format"] and len(t) > 1:
            fmt = t[1]
        elif t[:1] == ["element"] and len(t) == 3 and t[2].isdigit():
            count = int(t[2])
            rows += count
        elif t[:1] == ["property"] and len(t) >= 3:
            size = (_PLY_SIZES.get(t[2], 0) + 3 * _PLY_SIZES.get(t[3], 0)) if t[1] == "list" and len(t) >= 5 \
                else _PLY_SIZES.get(t[1], 0)
            need += count * size
    size = path.stat().st_size - (len(head) - body)
    if fmt.startswith("binary") and size < need:
        return f"the header declares {rows} rows in {need} bytes or more, the file holds {size}"
    if fmt == "ascii":
        with open(path, "rb") as f:
            held = sum(1 for _ in f) - len(lines) - 1
        if held < rows:
            return f"the header declares {rows} rows, the file holds {held}"
    return None
