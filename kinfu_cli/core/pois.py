"""Points of interest (POIs) and the pois.json file that the NBV planner and the fusion's POI clearing read.

pois.json::

    {"pois": [{"id": 0, "position": [x, y, z], "time": s, "saliency": float, "radius": 0.2,
               "gaussian": {"mean": [x, y, z, t], "covariance": 4x4, "weight": w} | null}],
     "algorithm": "gmm-as" | "zvc", "parameters": {...}, "frame": str, "source": str}

Positions in metres in `frame`; time in seconds on the trajectory's clock; `radius` is the region of
interest S(POI) around the position (0.2 m in the paper). ZVC POIs have `"gaussian": null`; GMM-AS
Gaussians are in (x, y, z, t) with t in seconds. Optional extra keys per POI: "stamp_ns" (absolute
time, when the trajectory came from a recording), "recording_time_s" (seconds from the recording's start, when
the stamp is on its clock), "component"/"threshold" (GMM-AS), "segment" (ZVC), "task"
(index into "tasks"). `kinfu poi` also writes "tasks" (the hand stream cut into tasks: index, t_start, t_end,
samples, n_pois, ...), "tasks_dropped" and "task_split" (see attention/tasks.py and attention/detect.py).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from kinfu_cli.core.atomic import write_json
from kinfu_cli.core.errors import ConfigError, TrajectoryError
from kinfu_cli.core.volume_file import MAX_COORDINATE_M

DEFAULT_RADIUS = 0.2
MAX_RADIUS_M = 100.0  # the largest S(POI) radius `kinfu poi` writes (its --radius range)
ALGORITHMS = ("gmm-as", "zvc")


class PoiFileError(TrajectoryError):
    """A pois.json file is missing or malformed."""


@dataclass
class Gaussian4:
    """One component of the GMM on (x, y, z, t): mean (4,), covariance (4, 4), mixture weight."""

    mean: np.ndarray
    covariance: np.ndarray
    weight: float

    def to_dict(self) -> dict:
        return {"mean": [float(v) for v in self.mean],
                "covariance": [[float(v) for v in row] for row in self.covariance],
                "weight": float(self.weight)}


@dataclass
class Poi:
    """A point of interest: where the person acted. `position` (3,) metres, `time` seconds."""

    id: int
    position: np.ndarray
    time: float
    saliency: float
    radius: float = DEFAULT_RADIUS
    gaussian: Gaussian4 | None = None
    extra: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.position = np.asarray(self.position, dtype=np.float64).reshape(3)

    def to_dict(self) -> dict:
        d = {"id": int(self.id), "position": [float(v) for v in self.position], "time": float(self.time),
             "saliency": float(self.saliency), "radius": float(self.radius),
             "gaussian": self.gaussian.to_dict() if self.gaussian is not None else None}
        d.update(self.extra)
        return d


def pois_document(pois: list[Poi], algorithm: str, parameters: dict, frame: str = "", source: str = "") -> dict:
    """The pois.json object for `pois` (see the module docstring)."""
    if algorithm not in ALGORITHMS:
        raise ConfigError(f"expected one of {', '.join(ALGORITHMS)}, got {algorithm!r}", parameter="algorithm")
    return {"pois": [p.to_dict() for p in pois], "algorithm": algorithm,
            "parameters": dict(parameters), "frame": frame, "source": source}


def write_pois(path: str | os.PathLike, pois: list[Poi], algorithm: str, parameters: dict,
               frame: str = "", source: str = "") -> Path:
    """Write pois.json atomically; returns the path."""
    return write_json(path, pois_document(pois, algorithm, parameters, frame, source))


def read_pois_document(path: str | os.PathLike) -> dict:
    """Load and check a pois.json file; returns the JSON object with validated "pois" entries."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text())
    except FileNotFoundError:
        raise PoiFileError(f"{path}: no such POI file (expected pois.json from `kinfu poi`)") from None
    except IsADirectoryError:
        raise PoiFileError(f"{path}: is a folder, expected a pois.json file") from None
    except ValueError as exc:  # JSONDecodeError, UnicodeDecodeError, an integer of > 4300 digits
        raise PoiFileError(f"{path}: not valid JSON ({exc}), expected a pois.json file from `kinfu poi`") from None
    except RecursionError:
        raise PoiFileError(f"{path}: JSON nested too deeply to read, expected a pois.json file from "
                           f"`kinfu poi`") from None
    if not isinstance(doc, dict) or "pois" not in doc:
        raise PoiFileError(f"{path}: no \"pois\" key, expected {{\"pois\": [{{\"position\": [x, y, z], ...}}]}}")
    if not isinstance(doc["pois"], list):
        raise PoiFileError(f"{path}: \"pois\" is not a list")
    return doc


def _is_number(v: object) -> bool:
    """A JSON number a float holds: int or float, not a bool (True is an int to Python), a string of digits nor an
    integer of more than 308 digits."""
    return isinstance(v, float) or (isinstance(v, int) and not isinstance(v, bool) and abs(v) < 10 ** 308)


def _numbers(v: object, shape: tuple[int, ...]) -> np.ndarray | None:
    """`v` as a finite float array of `shape` when it is nested lists of JSON numbers, else None."""
    def ok(x, dims):
        if not dims:
            return _is_number(x)
        return isinstance(x, list) and len(x) == dims[0] and all(ok(y, dims[1:]) for y in x)
    if not ok(v, shape):
        return None
    arr = np.asarray(v, dtype=np.float64)
    return arr if np.all(np.isfinite(arr)) else None


def _parse_poi(path: Path, i: int, d: object) -> Poi:
    if not isinstance(d, dict):
        raise PoiFileError(f"{path}: pois[{i}] is not an object")
    pos = d.get("position")
    arr = _numbers(pos, (3,))
    if arr is None or np.any(np.abs(arr) > MAX_COORDINATE_M):
        raise PoiFileError(f"{path}: pois[{i}].position is {_short(pos)}, expected [x, y, z] (three finite numbers "
                           f"within {MAX_COORDINATE_M:g} m)")
    radius = d.get("radius", DEFAULT_RADIUS)
    if not _is_number(radius) or not 0 < radius <= MAX_RADIUS_M:  # also refuses NaN and inf
        raise PoiFileError(f"{path}: pois[{i}].radius is {_short(radius)}, expected a positive number of metres, "
                           f"at most {MAX_RADIUS_M:g}")
    poi_id = d.get("id", i)
    if not _is_number(poi_id) or not float(poi_id).is_integer():  # 2.0 is 2, 1.7 is no id
        raise PoiFileError(f"{path}: pois[{i}].id is {_short(poi_id)}, expected an integer")
    for key in ("time", "saliency"):
        if key in d and not _is_number(d[key]):  # missing: NaN (not known)
            raise PoiFileError(f"{path}: pois[{i}].{key} is {_short(d[key])}, expected a number")
    gaussian = None
    g = d.get("gaussian")
    if g is not None:
        # GMM-AS's component that made the POI, kept for the record (the planners do not read it): a damaged one
        # says the file is, so it is refused rather than passed on
        parts = (_numbers(g.get("mean"), (4,)), _numbers(g.get("covariance"), (4, 4)),
                 _numbers(g.get("weight"), ())) if isinstance(g, dict) else (None,)
        if any(v is None for v in parts) or not 0 <= parts[2] <= 1:
            raise PoiFileError(f"{path}: pois[{i}].gaussian needs mean [4], covariance 4x4 (finite numbers) and a "
                               f"weight in [0, 1], or null")
        gaussian = Gaussian4(parts[0], parts[1], float(parts[2]))
    known = {"id", "position", "time", "saliency", "radius", "gaussian"}
    return Poi(id=int(poi_id), position=arr, time=float(d.get("time", float("nan"))),
               saliency=float(d.get("saliency", float("nan"))), radius=float(radius), gaussian=gaussian,
               extra={k: v for k, v in d.items() if k not in known})


def _short(value: object, limit: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[:limit] + "..."


def read_pois(path: str | os.PathLike) -> list[Poi]:
    """Read the POIs of a pois.json file.

    Raises PoiFileError (a TrajectoryError, so the CLI prints one line and exits 2) when the file is
    missing, not JSON, has no "pois" list, or a POI is malformed: no finite [x, y, z] position, a radius
    that is not a number in (0, MAX_RADIUS_M], an id that is not an integer or repeats another POI's.
    """
    path = Path(path)
    doc = read_pois_document(path)
    pois = [_parse_poi(path, i, d) for i, d in enumerate(doc["pois"])]
    first: dict[int, int] = {}
    for i, p in enumerate(pois):
        if p.id in first:  # views.json and the fusion's clearing name POIs by id: two would be one
            raise PoiFileError(f"{path}: pois[{i}].id {p.id} repeats pois[{first[p.id]}].id, expected unique ids")
        first[p.id] = i
    return pois


def poi_frame_warnings(pois_path, frame: str, option: str = "") -> list[str]:
    """A warning when the POIs of `pois_path` are in another named frame than `frame` (the volume's).

    option: how the caller names the file, put before its path (a command passes its flag); none by default.
    """
    if not pois_path or not frame:
        return []
    theirs = str(read_pois_document(pois_path).get("frame") or "").lstrip("/")
    frame = frame.lstrip("/")
    if theirs and theirs != frame:
        named = f"{option} {pois_path}" if option else str(pois_path)
        return [f"{named}: POIs are in frame {theirs!r}, the volume in {frame!r}; they are used at "
                f"their coordinates as given (is the hand tracker calibrated to {frame!r}?)"]
    return []
