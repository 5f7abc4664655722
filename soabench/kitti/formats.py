"""KITTI tracking file formats (docs/method.md §5.9; KITTI tracking devkit readme; AB3DMOT data format).

Parsing only: every function reads one text file and returns arrays, or raises :class:`SoabenchError` naming the file
and the 1-based line of the first bad row. Nothing read is evaluated; numbers go through ``float``/``int`` only, and
must be finite; integers fit a C int, frames lie in [0, :data:`MAX_FRAME`], object types are the devkit's
(:data:`KITTI_TYPES`, case matters), box sizes are >= 0, and a label file holds at least one row.

* ``label_02/XXXX.txt`` (ground truth), 17 space-separated columns per object: frame, track id, type, truncated,
  occluded, alpha, 2-D box (left, top, right, bottom), dimensions h w l (m), location x y z (bottom centre, rectified
  camera coordinates, m), rotation_y (rad). ``DontCare`` rows are dropped here.
* detections in the KITTI tracking *result* format: the 17 label columns plus a score (18 columns), or in the
  AB3DMOT comma-separated format: frame, type id (1 Pedestrian, 2 Car, 3 Cyclist), 2-D box (4), score, h, w, l,
  x, y, z, rotation_y, alpha (15 columns). The format is detected from the first row of each file.
* ``calib/XXXX.txt``: ``KEY[:] v1 v2 ...`` lines; R0_rect (alias R_rect, 9 values), Tr_velo_to_cam (alias Tr_velo_cam,
  12 values), Tr_imu_to_velo (alias Tr_imu_velo, 12 values), P2 (12 values). Missing keys take the nominal KITTI
  values of :data:`NOMINAL`.
* ``oxts/XXXX.txt``: one GPS/IMU packet per frame, 30 columns (lat, lon, alt, roll, pitch, yaw, ...). Poses follow the
  devkit's Mercator convention (:func:`poses_from_oxts`).
* semantics (soabench's own, ``semantics/XXXX.txt``): ``frame class x1 y1 x2 y2 ... xn yn`` (n >= 3), one bird's-eye
  polygon per line in the ego (Velodyne) frame, metres: x forward, y left.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from soabench.errors import SoabenchError

EARTH_RADIUS = 6378137.0  #: equatorial earth radius of the devkit's Mercator projection (m)
NOMINAL_IMAGE_WIDTH = 1242  #: width (px) of the KITTI tracking colour images
AB3DMOT_TYPES = {1: "Pedestrian", 2: "Car", 3: "Cyclist"}  #: AB3DMOT type ids
AB3DMOT_IDS = {name: i for i, name in AB3DMOT_TYPES.items()}
LABEL_COLUMNS = 17
RESULT_COLUMNS = 18
AB3DMOT_COLUMNS = 15
OXTS_MIN_COLUMNS = 6
#: the object types of the KITTI tracking devkit (case matters: "pedestrian" is none of them)
KITTI_TYPES = ("Car", "Van", "Truck", "Pedestrian", "Person_sitting", "Cyclist", "Tram", "Misc", "DontCare")
MAX_INT = 2**31 - 1  #: largest |track id| and other integer column (a C int, as the devkit stores them)
MAX_FRAME = 1_000_000  #: largest frame index (a day of frames at 10 Hz is 864 000)
#: largest |coordinate| of a semantic polygon (m, ego frame): twice the largest sensor.r_max, so that every file
#: ``soabench export kitti`` writes (polygons within r_max of the ego) reads back
MAX_SEMANTICS_COORDINATE = 20_000.0


class ReadError(SoabenchError):
    """A file of one sequence could not be read or parsed (the sequence may be skipped with ``--skip-bad``)."""


class UnreadableError(ReadError):
    """A file exists but cannot be read as text (permissions, binary content): always a reported skip."""


@dataclass
class Objects:
    """Rows of a label or detection file, column arrays of length N (camera coordinates, metres, radians)."""

    frame: np.ndarray  #: (N,) int
    track_id: np.ndarray  #: (N,) int (-1 when the format has none)
    type: np.ndarray  #: (N,) str
    occluded: np.ndarray  #: (N,) int (0 fully visible, 1 partly, 2 largely occluded, 3 unknown; -1 if absent)
    hwl: np.ndarray  #: (N, 3) box height, width, length
    xyz: np.ndarray  #: (N, 3) bottom centre in rectified camera coordinates
    ry: np.ndarray  #: (N,) rotation around the camera y axis
    score: np.ndarray  #: (N,) detection score (inf for labels)
    line: np.ndarray  #: (N,) 1-based line number in ``path``
    path: str = ""
    #: (N,) float KITTI ``truncated`` (tracking: 0 not, 1 partly, 2 fully truncated; -1 if the format has none);
    #: None: not read
    truncated: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.frame)

    def select(self, mask: np.ndarray) -> Objects:
        m = np.asarray(mask, dtype=bool)
        return Objects(
            self.frame[m], self.track_id[m], self.type[m], self.occluded[m], self.hwl[m], self.xyz[m], self.ry[m],
            self.score[m], self.line[m], self.path, None if self.truncated is None else self.truncated[m],
        )  # fmt: skip

    @classmethod
    def empty(cls, path: str = "") -> Objects:
        z = np.zeros(0)
        return cls(
            np.zeros(0, int), np.zeros(0, int), np.zeros(0, "<U16"), np.zeros(0, int), np.zeros((0, 3)),
            np.zeros((0, 3)), z, z.copy(), np.zeros(0, int), path, z.copy(),
        )  # fmt: skip


def read_lines(path: Path) -> list[tuple[int, str]]:
    """Non-empty lines of a text file with their 1-based numbers; :class:`UnreadableError` if it cannot be read."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise UnreadableError(f"{path}: cannot be read as text ({exc.__class__.__name__}: {exc})") from None
    return [(i, s.strip()) for i, s in enumerate(text.splitlines(), start=1) if s.strip()]


def _num(path: Path, line: int, token: str, what: str, kind: type = float) -> float:
    try:
        value = kind(token)
    except ValueError:
        noun = "an integer" if kind is int else "a number"
        raise ReadError(f"{path}:{line}: {what} {token!r} is not {noun}") from None
    if kind is float and not math.isfinite(value):
        raise ReadError(f"{path}:{line}: {what} {token!r} is not a finite number")
    if kind is int and abs(value) > MAX_INT:
        raise ReadError(f"{path}:{line}: {what} {token!r} is out of range; allowed: |{what}| <= {MAX_INT}")
    return value


def _frame(path: Path, line: int, token: str) -> int:
    f = int(_num(path, line, token, "frame", int))
    if f < 0:
        raise ReadError(f"{path}:{line}: frame {f} is negative")
    if f > MAX_FRAME:
        raise ReadError(f"{path}:{line}: frame {f} is out of range; allowed: 0 to {MAX_FRAME}")
    return f


def _type(path: Path, line: int, token: str) -> str:
    """A KITTI object type (:data:`KITTI_TYPES`; case matters)."""
    if token not in KITTI_TYPES:
        raise ReadError(f"{path}:{line}: type {token!r} is not a KITTI type; allowed: {', '.join(KITTI_TYPES)}")
    return token


def _size(path: Path, line: int, token: str) -> float:
    """A box dimension (h, w or l): a finite number >= 0 (m)."""
    v = _num(path, line, token, "dimension")
    if v < 0:
        raise ReadError(f"{path}:{line}: box dimension {token!r} is negative; h, w, l are sizes in metres (>= 0)")
    return v


def detect_format(path: Path, lines: list[tuple[int, str]]) -> str:
    """ "ab3dmot" (comma-separated, 15 columns) or "result" (space-separated, 18 columns), from the first row."""
    if not lines:
        return "result"
    line, text = lines[0]
    if "," in text:
        n = len(text.split(","))
        if n != AB3DMOT_COLUMNS:
            raise ReadError(
                f"{path}:{line}: {n} comma-separated columns; the AB3DMOT format has {AB3DMOT_COLUMNS} "
                "(frame, type id, 2-D box, score, h, w, l, x, y, z, rotation_y, alpha)"
            )
        return "ab3dmot"
    n = len(text.split())
    if n != RESULT_COLUMNS:
        raise ReadError(
            f"{path}:{line}: {n} columns; detections need {RESULT_COLUMNS} space-separated columns (KITTI tracking "
            f"result: the label columns plus a score) or {AB3DMOT_COLUMNS} comma-separated ones (AB3DMOT)"
        )
    return "result"


def parse_objects(path: Path, kind: str) -> tuple[Objects, str]:
    """Rows of a label file (``kind="label"``) or a detection file (``kind="detections"``, format auto-detected).

    Returns ``(objects, format)`` with format "label", "result" or "ab3dmot". DontCare rows are dropped.
    """
    path = Path(path)
    lines = read_lines(path)
    if kind == "label" and not lines:
        raise ReadError(
            f"sequence {path.stem} is empty: the label file {str(path)!r} holds no rows (one row per labelled object "
            "and frame)"
        )
    fmt = "label" if kind == "label" else detect_format(path, lines)
    cols: dict[str, list] = {
        k: [] for k in ("frame", "tid", "type", "occ", "trunc", "hwl", "xyz", "ry", "score", "line")
    }
    for line, text in lines:
        if fmt == "ab3dmot":
            tok = [t.strip() for t in text.split(",")]
            if len(tok) != AB3DMOT_COLUMNS:
                raise ReadError(f"{path}:{line}: {len(tok)} comma-separated columns; expected {AB3DMOT_COLUMNS}")
            type_id = int(_num(path, line, tok[1], "type id", int))
            if type_id not in AB3DMOT_TYPES:
                raise ReadError(f"{path}:{line}: type id {type_id} is not one of 1 (Pedestrian), 2 (Car), 3 (Cyclist)")
            row = dict(
                frame=_frame(path, line, tok[0]), tid=-1, type=AB3DMOT_TYPES[type_id], occ=-1, trunc=-1.0,
                score=_num(path, line, tok[6], "score"), hwl=tok[7:10], xyz=tok[10:13], ry=tok[13],
            )  # fmt: skip
        else:
            tok = text.split()
            want = LABEL_COLUMNS if fmt == "label" else RESULT_COLUMNS
            if len(tok) != want:
                raise ReadError(f"{path}:{line}: {len(tok)} columns; expected {want}")
            if _type(path, line, tok[2]) == "DontCare":
                continue
            row = dict(
                frame=_frame(path, line, tok[0]), tid=int(_num(path, line, tok[1], "track id", int)), type=tok[2],
                occ=int(_num(path, line, tok[4], "occluded", int)), hwl=tok[10:13], xyz=tok[13:16], ry=tok[16],
                trunc=_num(path, line, tok[3], "truncated"),
                score=math.inf if fmt == "label" else _num(path, line, tok[17], "score"),
            )  # fmt: skip
        cols["frame"].append(row["frame"])
        cols["tid"].append(row["tid"])
        cols["type"].append(row["type"])
        cols["occ"].append(row["occ"])
        cols["trunc"].append(row["trunc"])
        cols["hwl"].append([_size(path, line, t) for t in row["hwl"]])
        cols["xyz"].append([_num(path, line, t, "location") for t in row["xyz"]])
        cols["ry"].append(_num(path, line, row["ry"], "rotation_y"))
        cols["score"].append(row["score"])
        cols["line"].append(line)
    if not cols["frame"]:
        return Objects.empty(str(path)), fmt
    return (
        Objects(
            frame=np.asarray(cols["frame"], dtype=int),
            track_id=np.asarray(cols["tid"], dtype=int),
            type=np.asarray(cols["type"], dtype=str),
            occluded=np.asarray(cols["occ"], dtype=int),
            hwl=np.asarray(cols["hwl"], dtype=float),
            xyz=np.asarray(cols["xyz"], dtype=float),
            ry=np.asarray(cols["ry"], dtype=float),
            score=np.asarray(cols["score"], dtype=float),
            line=np.asarray(cols["line"], dtype=int),
            path=str(path),
            truncated=np.asarray(cols["trunc"], dtype=float),
        ),
        fmt,
    )


# ---------------------------------------------------------------------------------------------------------------------
# calibration


def _rigid(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return T


@dataclass
class Calib:
    """Sensor calibration of one sequence as 4x4 homogeneous transforms.

    ``X_rect = R0_rect @ Tr_velo_cam @ X_velo`` (rectified camera from Velodyne) and ``X_velo = Tr_imu_velo @ X_imu``.
    ``nominal`` lists the keys that took the nominal value (file absent or key missing).
    """

    R0_rect: np.ndarray  #: (4, 4)
    Tr_velo_cam: np.ndarray  #: (4, 4)
    Tr_imu_velo: np.ndarray  #: (4, 4)
    P2: np.ndarray  #: (3, 4) projection of the left colour camera
    nominal: list[str] = field(default_factory=list)

    @property
    def velo_to_rect(self) -> np.ndarray:
        return self.R0_rect @ self.Tr_velo_cam

    def rect_to_velo(self, X: np.ndarray) -> np.ndarray:
        """(N, 3) rectified-camera points -> Velodyne frame (x forward, y left, z up)."""
        X = np.asarray(X, dtype=float).reshape(-1, 3)
        return np.linalg.solve(self.velo_to_rect, np.column_stack([X, np.ones(len(X))]).T).T[:, :3]

    def velo_to_rect_pts(self, X: np.ndarray) -> np.ndarray:
        """(N, 3) Velodyne points -> rectified camera frame."""
        X = np.asarray(X, dtype=float).reshape(-1, 3)
        return (self.velo_to_rect @ np.column_stack([X, np.ones(len(X))]).T).T[:, :3]

    def fov_deg(self, image_width: float = NOMINAL_IMAGE_WIDTH) -> float:
        """Horizontal field of view of camera 2 (deg): 2 atan(width / (2 f_x))."""
        return math.degrees(2.0 * math.atan(0.5 * image_width / float(self.P2[0, 0])))


NOMINAL = {
    "R0_rect": np.eye(3).ravel(),
    # camera axes (x right, y down, z forward) from Velodyne axes (x forward, y left, z up); the cameras sit 0.27 m
    # ahead of and 0.08 m below the Velodyne (KITTI sensor setup)
    "Tr_velo_to_cam": np.array([0.0, -1.0, 0.0, 0.0, 0.0, 0.0, -1.0, -0.08, 1.0, 0.0, 0.0, -0.27]),
    # the GPS/IMU sits 0.81 m behind, 0.32 m right of and 0.80 m below the Velodyne
    "Tr_imu_to_velo": np.array([1.0, 0.0, 0.0, -0.81, 0.0, 1.0, 0.0, 0.32, 0.0, 0.0, 1.0, -0.80]),
    "P2": np.array([721.5377, 0.0, 609.5593, 44.85728, 0.0, 721.5377, 172.854, 0.2163791, 0.0, 0.0, 1.0, 0.002745884]),
}
_ALIASES = {
    "R0_rect": "R0_rect", "R_rect": "R0_rect", "Tr_velo_to_cam": "Tr_velo_to_cam", "Tr_velo_cam": "Tr_velo_to_cam",
    "Tr_imu_to_velo": "Tr_imu_to_velo", "Tr_imu_velo": "Tr_imu_to_velo", "P2": "P2",
}  # fmt: skip
_SIZES = {"R0_rect": 9, "Tr_velo_to_cam": 12, "Tr_imu_to_velo": 12, "P2": 12}


def calib_from_values(values: dict[str, np.ndarray], nominal: list[str]) -> Calib:
    v = {**NOMINAL, **values}
    Tr = v["Tr_velo_to_cam"].reshape(3, 4)
    Ti = v["Tr_imu_to_velo"].reshape(3, 4)
    return Calib(
        R0_rect=_rigid(v["R0_rect"].reshape(3, 3), np.zeros(3)),
        Tr_velo_cam=_rigid(Tr[:, :3], Tr[:, 3]),
        Tr_imu_velo=_rigid(Ti[:, :3], Ti[:, 3]),
        P2=v["P2"].reshape(3, 4),
        nominal=nominal,
    )


def nominal_calib() -> Calib:
    """The nominal KITTI calibration (used when ``calib/XXXX.txt`` is absent)."""
    return calib_from_values({}, sorted(_SIZES))


def parse_calib(path: Path) -> Calib:
    """A tracking (or object) calibration file; keys it lacks take their nominal value."""
    path = Path(path)
    values: dict[str, np.ndarray] = {}
    for line, text in read_lines(path):
        key, *rest = text.replace(":", " ", 1).split()
        name = _ALIASES.get(key)
        if name is None:
            continue  # P0, P1, P3 and other keys are not needed
        if len(rest) != _SIZES[name]:
            raise ReadError(f"{path}:{line}: {key} has {len(rest)} values; expected {_SIZES[name]}")
        values[name] = np.array([_num(path, line, t, key) for t in rest])
    if "P2" in values and not values["P2"][0] > 0:
        raise ReadError(f"{path}: P2 has focal length {values['P2'][0]!r}; it must be > 0")
    return calib_from_values(values, sorted(set(_SIZES) - set(values)))


# ---------------------------------------------------------------------------------------------------------------------
# oxts -> poses (devkit Mercator convention)


def lat_to_scale(lat: float) -> float:
    """Mercator scale of the devkit: cos(latitude of the first packet)."""
    return math.cos(math.radians(lat))


def latlon_to_mercator(lat: np.ndarray, lon: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """Devkit Mercator: mx = s er lon pi/180, my = s er ln tan((90 + lat) pi/360) (m)."""
    mx = scale * np.asarray(lon, dtype=float) * np.pi * EARTH_RADIUS / 180.0
    my = scale * EARTH_RADIUS * np.log(np.tan((90.0 + np.asarray(lat, dtype=float)) * np.pi / 360.0))
    return mx, my


def mercator_to_latlon(mx: np.ndarray, my: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`latlon_to_mercator`."""
    lon = np.asarray(mx, dtype=float) * 180.0 / (scale * np.pi * EARTH_RADIUS)
    lat = 360.0 / np.pi * np.arctan(np.exp(np.asarray(my, dtype=float) / (scale * EARTH_RADIUS))) - 90.0
    return lat, lon


def rotation_rpy(roll: np.ndarray, pitch: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """(N, 3, 3) R = Rz(yaw) Ry(pitch) Rx(roll) (OXTS convention; yaw 0 = east, counter-clockwise)."""
    r, p, y = (np.asarray(a, dtype=float) for a in (roll, pitch, yaw))
    n = len(r)
    Rx = np.zeros((n, 3, 3))
    Rx[:, 0, 0] = 1
    Rx[:, 1, 1], Rx[:, 1, 2], Rx[:, 2, 1], Rx[:, 2, 2] = np.cos(r), -np.sin(r), np.sin(r), np.cos(r)
    Ry = np.zeros((n, 3, 3))
    Ry[:, 1, 1] = 1
    Ry[:, 0, 0], Ry[:, 0, 2], Ry[:, 2, 0], Ry[:, 2, 2] = np.cos(p), np.sin(p), -np.sin(p), np.cos(p)
    Rz = np.zeros((n, 3, 3))
    Rz[:, 2, 2] = 1
    Rz[:, 0, 0], Rz[:, 0, 1], Rz[:, 1, 0], Rz[:, 1, 1] = np.cos(y), -np.sin(y), np.sin(y), np.cos(y)
    return Rz @ Ry @ Rx


def poses_from_oxts(oxts: np.ndarray) -> np.ndarray:
    """(F, 4, 4) IMU poses in the frame of the first packet (devkit ``convertOxtsToPose``).

    Translation = Mercator (mx, my) with the scale of the first latitude, and the altitude; rotation =
    Rz(yaw) Ry(pitch) Rx(roll); every pose is then premultiplied by the inverse of the first one.
    """
    oxts = np.asarray(oxts, dtype=float)
    scale = lat_to_scale(oxts[0, 0])
    mx, my = latlon_to_mercator(oxts[:, 0], oxts[:, 1], scale)
    T = np.tile(np.eye(4), (len(oxts), 1, 1))
    T[:, :3, :3] = rotation_rpy(oxts[:, 3], oxts[:, 4], oxts[:, 5])
    T[:, :3, 3] = np.column_stack([mx, my, oxts[:, 2]])
    return np.linalg.solve(T[0], T)


def parse_oxts(path: Path) -> np.ndarray:
    """(F, C) packets of an oxts file (C >= 6: lat, lon, alt, roll, pitch, yaw, ...)."""
    path = Path(path)
    rows = []
    width = None
    for line, text in read_lines(path):
        tok = text.split()
        if len(tok) < OXTS_MIN_COLUMNS:
            raise ReadError(
                f"{path}:{line}: {len(tok)} columns; an oxts packet has 30 (at least lat lon alt roll pitch yaw)"
            )
        if width is not None and len(tok) != width:
            raise ReadError(f"{path}:{line}: {len(tok)} columns; the first packet had {width}")
        width = len(tok)
        rows.append([_num(path, line, t, "oxts value") for t in tok[:OXTS_MIN_COLUMNS]])
    if rows and not -90.0 < rows[0][0] < 90.0:
        raise ReadError(f"{path}:1: latitude {rows[0][0]!r} is outside (-90, 90) degrees")
    return np.asarray(rows, dtype=float).reshape(-1, OXTS_MIN_COLUMNS)


# ---------------------------------------------------------------------------------------------------------------------
# semantics


def parse_semantics(path: Path) -> dict[int, list[tuple[str, np.ndarray]]]:
    """Per-frame bird's-eye polygons: ``{frame: [(class, (n, 2) ego-frame vertices), ...]}``."""
    path = Path(path)
    out: dict[int, list[tuple[str, np.ndarray]]] = {}
    for line, text in read_lines(path):
        tok = text.split()
        if len(tok) < 8 or len(tok) % 2:
            raise ReadError(
                f"{path}:{line}: {len(tok)} columns; a polygon row is 'frame class x1 y1 ... xn yn' with n >= 3"
            )
        frame = _frame(path, line, tok[0])
        xy = np.array([_num(path, line, t, "coordinate") for t in tok[2:]]).reshape(-1, 2)
        far = np.abs(xy) > MAX_SEMANTICS_COORDINATE
        if far.any():
            raise ReadError(
                f"{path}:{line}: coordinate {float(xy[far][0])!r} is out of range; semantic polygons lie around the "
                f"ego: |x|, |y| <= {MAX_SEMANTICS_COORDINATE:g} m"
            )
        out.setdefault(frame, []).append((tok[1], xy))
    return out
