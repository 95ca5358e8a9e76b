"""Calibration boards: the board config (TOML) and corner detection in one image.

A board config has a ``[board]`` table::

    [board]
    type = "charuco"            # or "checkerboard"
    squares = [8, 11]           # squares along x (columns) and y (rows)
    square_mm = 24.0            # side of one square
    marker_mm = 18.75           # ChArUco only: side of one ArUco marker
    dictionary = "4X4_1000"     # ChArUco only: an OpenCV ArUco dictionary
    legacy = false              # ChArUco only: OpenCV < 4.6 pattern (even row counts)

or, for an ArUco grid (OpenCV's ``GridBoard``: markers 0, 1, ... row by row)::

    [board]
    type = "aruco"
    markers = [5, 7]            # markers along x (columns) and y (rows)
    marker_mm = 30.0            # side of one marker
    separation_mm = 6.0         # gap between neighbouring markers
    dictionary = "4X4_50"

The corners of an ArUco grid are the four corners of every marker (marker ``k``: corners
``4k`` to ``4k + 3``, clockwise from its top left).

Anipose's board files (``board_x``, ``board_y``, ``square_length``, ``marker_length``,
``marker_bits``, ``dict_size``) and the ``[calibration]`` table of an Anipose config are read
too. Corner ``i`` of a board is ``object_points[i]``, in mm, on the board's z = 0 plane.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from kinematics.fileio import parse_toml
from videotrack.errors import VideoTrackError

__all__ = ["Board", "load_board"]

TYPES = ("checkerboard", "charuco", "aruco")
#: The keys of each board type besides ``type`` (a checkerboard ignores the ChArUco ones, as
#: Anipose's configs give them for both).
_SQUARE_KEYS = ("squares", "square_mm", "marker_mm", "dictionary", "legacy")
_KEYS = {"checkerboard": _SQUARE_KEYS, "charuco": _SQUARE_KEYS,
         "aruco": ("markers", "marker_mm", "separation_mm", "dictionary")}
#: Fewest ChArUco corners that make a usable (non-degenerate, rarely wrong) partial view.
MIN_CHARUCO_CORNERS = 6
#: Fewest markers of an ArUco grid that make a usable view (one marker's pose is ambiguous).
MIN_GRID_MARKERS = 3
#: Of the grid markers found in a view, at least this fraction must fit the configured layout;
#: fewer means the config does not describe the printed board.
_GRID_AGREE = 0.75
#: Images wider or taller than this are searched for a checkerboard at reduced size first.
_SEARCH_SIZE = 1000


@dataclass(frozen=True)
class Board:
    """A checkerboard, ChArUco board or ArUco grid; see the module docstring for the fields.

    For an ArUco grid, ``squares`` counts the markers and ``square_mm`` is the grid's pitch
    (marker side + separation), the cell a marker sits in as on a ChArUco board.
    """

    type: str
    squares: tuple[int, int]
    square_mm: float
    marker_mm: float | None = None
    dictionary: str | None = None
    legacy: bool = False
    _cv: object = field(default=None, repr=False, compare=False)

    def __post_init__(self):
        if self.type == "charuco":
            try:
                board = cv2.aruco.CharucoBoard(self.squares, self.square_mm, self.marker_mm,
                                               _dictionary(self.dictionary))
            except cv2.error:
                raise VideoTrackError(
                    f"dictionary {self.dictionary} has too few markers for "
                    f"{self.squares[0]}x{self.squares[1]} squares", field="board.dictionary"
                ) from None
            board.setLegacyPattern(self.legacy)
            object.__setattr__(self, "_cv", board)
        elif self.type == "aruco":
            board = cv2.aruco.GridBoard(self.squares, self.marker_mm, self.separation_mm,
                                        _dictionary(self.dictionary))
            object.__setattr__(self, "_cv", board)

    @property
    def separation_mm(self) -> float:
        """ArUco grid: the gap between neighbouring markers."""
        return self.square_mm - self.marker_mm

    @property
    def inner(self) -> tuple[int, int]:
        """Inner corners along x and y (the checkerboard ``patternSize`` of OpenCV)."""
        return self.squares[0] - 1, self.squares[1] - 1

    @property
    def object_points(self) -> np.ndarray:
        """Corner positions (n, 3) in mm, row by row (x fastest), z = 0; y points down the
        printed board, so z points into it."""
        if self.type == "charuco":
            return np.asarray(self._cv.getChessboardCorners(), dtype=np.float64).reshape(-1, 3)
        if self.type == "aruco":
            return np.asarray(self._cv.getObjPoints(), dtype=np.float64).reshape(-1, 3)
        nx, ny = self.inner
        yy, xx = np.mgrid[0:ny, 0:nx]
        pts = np.stack([xx.ravel(), yy.ravel(), np.zeros(nx * ny)], -1) * self.square_mm
        return pts

    @property
    def n_corners(self) -> int:
        if self.type == "aruco":
            return 4 * self.squares[0] * self.squares[1]
        return self.inner[0] * self.inner[1]

    def edges(self) -> tuple[np.ndarray, float, str]:
        """Pairs of corner indices (m, 2) one known length (mm) apart and what that length
        is: neighbouring corners of the squares, or the sides of the grid's markers."""
        if self.type == "aruco":
            k = np.arange(self.n_corners).reshape(-1, 4)
            return (np.stack([k, np.roll(k, -1, axis=1)], -1).reshape(-1, 2), self.marker_mm,
                    "marker")
        nx, ny = self.inner
        k = np.arange(nx * ny).reshape(ny, nx)
        pairs = [np.stack([k[:, :-1], k[:, 1:]], -1), np.stack([k[:-1], k[1:]], -1)]
        return np.concatenate([p.reshape(-1, 2) for p in pairs]), self.square_mm, "square"

    def describe(self) -> str:
        nx, ny = self.squares
        if self.type == "aruco":
            return (f"aruco grid {nx}x{ny} markers of {self.marker_mm:g} mm, "
                    f"{self.separation_mm:g} mm apart, dictionary {self.dictionary}")
        extra = (f", {self.marker_mm:g} mm markers, dictionary {self.dictionary}"
                 if self.type == "charuco" else "")
        return f"{self.type} {nx}x{ny} squares of {self.square_mm:g} mm{extra}"

    def spec(self) -> dict:
        """What identifies the board (for caches and reports)."""
        return {"type": self.type, "squares": list(self.squares), "square_mm": self.square_mm,
                "marker_mm": self.marker_mm, "dictionary": self.dictionary,
                "legacy": self.legacy}

    def detect(self, image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Corners of the board in a grey image: (ids (k,), pixels (k, 2)); k = 0 if absent."""
        if image.ndim == 3:
            image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        if self.type == "charuco":
            return self._detect_charuco(image)
        if self.type == "aruco":
            return self._detect_grid(image)
        return self._detect_checkerboard(image)

    def _detect_charuco(self, grey):
        detector = cv2.aruco.CharucoDetector(self._cv)
        corners, ids, _, _ = detector.detectBoard(grey)
        if ids is None or len(ids) < MIN_CHARUCO_CORNERS:
            return np.zeros(0, int), np.zeros((0, 2))
        return ids.ravel().astype(int), corners.reshape(-1, 2).astype(np.float64)

    def _detect_grid(self, grey):
        none = np.zeros(0, int), np.zeros((0, 2))
        dictionary = self._cv.getDictionary()
        found, ids, _ = cv2.aruco.ArucoDetector(dictionary).detectMarkers(grey)
        if ids is None:
            return none
        ids = ids.ravel()
        # markers of this board, each found once (a duplicate id is another board: ambiguous)
        unique, counts = np.unique(ids, return_counts=True)
        keep = np.isin(ids, unique[counts == 1]) & (ids < len(self._cv.getIds()))
        quads = np.array(found, np.float64).reshape(-1, 4, 2)[keep]
        ids = ids[keep]
        if len(ids) < MIN_GRID_MARKERS:
            return none
        cell = np.median(np.linalg.norm(quads - np.roll(quads, 1, axis=1), axis=-1)) / (
            dictionary.markerSize + 2)
        quads = _refine_quads(grey, quads, cell)
        # object points as Board.matchImagePoints pairs them, keeping the corner ids:
        # GridBoard markers are 0, 1, ... in the order of its object points
        good = np.isfinite(quads).all(axis=(1, 2))
        obj = self.object_points.reshape(-1, 4, 3)[ids[good]]
        good[good] = _fits_layout(obj, quads[good], self.square_mm)
        if good.sum() < max(MIN_GRID_MARKERS, _GRID_AGREE * len(good)):
            return none
        return (4 * ids[good, None] + np.arange(4)).ravel(), quads[good].reshape(-1, 2)

    def _detect_checkerboard(self, grey):
        flags = (cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
                 | cv2.CALIB_CB_FAST_CHECK)
        scale = min(1.0, _SEARCH_SIZE / max(grey.shape))
        small = grey if scale == 1.0 else cv2.resize(grey, None, fx=scale, fy=scale,
                                                     interpolation=cv2.INTER_AREA)
        found, corners = cv2.findChessboardCorners(small, self.inner, flags)
        if not found:
            return np.zeros(0, int), np.zeros((0, 2))
        corners = (corners.reshape(-1, 2) + 0.5) / scale - 0.5  # pixel centres at integers
        nx = self.inner[0]
        spacing = np.min(np.linalg.norm(corners[1:nx] - corners[:nx - 1], axis=1))
        half = int(np.clip(spacing * 0.4, 2, 11))  # window inside one square
        criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-3)
        corners = cv2.cornerSubPix(grey, corners.astype(np.float32).reshape(-1, 1, 2),
                                   (half, half), (-1, -1), criteria).reshape(-1, 2)
        # A checkerboard is symmetric under a 180° turn; start at the corner nearer the image's
        # top-left so cameras looking from the same side agree.
        if corners[0].sum() > corners[-1].sum():
            corners = corners[::-1]
        return np.arange(len(corners)), corners.astype(np.float64)


def _refine_quads(grey: np.ndarray, quads: np.ndarray, cell: float) -> np.ndarray:
    """Marker corners (k, 4, 2; clockwise) refined as the intersections of straight lines
    fitted to the marker's four outer edges; NaN where an edge is not found or the fit moved
    a corner by more than a cell (an edge lost in clutter).

    Why not OpenCV's refinements: corner methods (SUBPIX, CONTOUR) put the corner of a blurred
    black square 0.3 to 0.7 px inside it, and APRILTAG counts pixels from their corner, not
    their centre. An edge, unlike a corner, stays in place under blur.
    """
    from scipy.ndimage import map_coordinates

    d = np.roll(quads, -1, axis=1) - quads  # side j: from corner j to corner j + 1
    u = d / np.linalg.norm(d, axis=-1, keepdims=True)
    n = np.stack([u[..., 1], -u[..., 0]], -1)  # outward normal (corners go clockwise)
    t = np.linspace(0.15, 0.85, 15)  # along a side, clear of the rounded corners
    # across it: half a cell inwards (the marker's inner cells begin one cell in), one out
    s = np.arange(-np.clip(0.5 * cell, 1.5, 10), np.clip(cell, 2, 10) + 1e-9, 0.25)
    pts = (quads[:, :, None, None] + t[:, None, None] * d[:, :, None, None]
           + s[:, None] * n[:, :, None, None])  # (k, 4, t, s, 2)
    profile = map_coordinates(grey.astype(np.float32), [pts[..., 1], pts[..., 0]], order=1,
                              mode="nearest")
    rise = np.clip(np.diff(profile, axis=-1), 0, None)  # black inside, white outside
    w = rise.sum(-1)
    offset = (rise * (s[1:] + s[:-1]) / 2).sum(-1) / np.where(w > 0, w, np.nan)
    # the edge's offset along the normal, a + b t, by weighted least squares per side
    w = np.where(np.isfinite(offset), w, 0)
    offset = np.nan_to_num(offset)
    sw, st, stt = w.sum(-1), (w * t).sum(-1), (w * t * t).sum(-1)
    so, sto = (w * offset).sum(-1), (w * t * offset).sum(-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        b = (sw * sto - st * so) / (sw * stt - st**2)
        a = (so - b * st) / sw
    start = quads + a[..., None] * n  # the fitted line of side j and its direction
    direction = d + b[..., None] * n
    # corner j is where side j - 1 meets side j
    p, v = np.roll(start, 1, axis=1), np.roll(direction, 1, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = _cross(start - p, direction) / _cross(v, direction)
    out = p + lam[..., None] * v
    with np.errstate(invalid="ignore"):
        out[~(np.linalg.norm(out - quads, axis=-1).max(axis=-1) < cell)] = np.nan
    return out


def _cross(x, y):
    return x[..., 0] * y[..., 1] - x[..., 1] * y[..., 0]


def _fits_layout(obj: np.ndarray, img: np.ndarray, pitch: float) -> np.ndarray:
    """Markers (bool per marker) that sit where the board's layout puts them: each marker's
    own homography (its 4 corners) must place at least half of its found grid neighbours
    within a quarter of its side. Local, so lens distortion does not matter; a wrong marker
    count moves neighbours by a whole grid cell, and a marker found alone is unconfirmed."""
    centre = obj[:, :, :2].mean(axis=1)
    near = np.abs(centre[:, None] - centre[None]).max(axis=-1) < 1.5 * pitch
    np.fill_diagonal(near, False)
    agree = np.zeros_like(near)
    for i in np.flatnonzero(near.any(axis=1)):
        H = cv2.getPerspectiveTransform(obj[i, :, :2].astype(np.float32),
                                        img[i].astype(np.float32))
        j = np.flatnonzero(near[i])
        pred = cv2.perspectiveTransform(obj[j, :, :2].reshape(-1, 1, 2), H).reshape(-1, 4, 2)
        side = np.linalg.norm(img[i] - np.roll(img[i], 1, axis=0), axis=-1).mean()
        agree[i, j] = np.linalg.norm(pred - img[j], axis=-1).max(axis=-1) < 0.25 * side
    n = near.sum(axis=1)
    return (n > 0) & (2 * agree.sum(axis=1) >= n)


def _dictionary(name: str):
    key = name.upper()
    key = key if key.startswith("DICT_") else f"DICT_{key}"
    if not hasattr(cv2.aruco, key):
        raise VideoTrackError(f"unknown ArUco dictionary {name!r}; e.g. 4X4_50, 5X5_100, "
                              "6X6_250, ARUCO_ORIGINAL", field="board.dictionary")
    return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, key))


def _from_anipose(doc: dict) -> dict:
    """[board] keys from Anipose's board file or the [calibration] table of its config."""
    if "board_x" in doc:  # sleap-anipose board.toml
        return {"type": "charuco" if "marker_length" in doc else "checkerboard",
                "squares": [doc["board_x"], doc["board_y"]],
                "square_mm": doc.get("square_length"), "marker_mm": doc.get("marker_length"),
                "dictionary": f"{doc.get('marker_bits', 4)}X{doc.get('marker_bits', 4)}_"
                              f"{doc.get('dict_size', 50)}"}
    cal = doc["calibration"]
    bits = cal.get("board_marker_bits", 4)
    return {"type": cal.get("board_type", "charuco"), "squares": cal.get("board_size"),
            "square_mm": cal.get("board_square_side_length"),
            "marker_mm": cal.get("board_marker_length"),
            "dictionary": f"{bits}X{bits}_{cal.get('board_marker_dict_number', 50)}"}


def _number(table, key, *, required=True):
    value = table.get(key)
    if value is None and not required:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float) or not value > 0:
        raise VideoTrackError(f"expected a positive number (mm), got {value!r}",
                              field=f"board.{key}")
    return float(value)


def _counts(table, key, least, what):
    value = table.get(key)
    if (not isinstance(value, list) or len(value) != 2
            or not all(isinstance(n, int) and not isinstance(n, bool) and n >= least
                       for n in value)):
        raise VideoTrackError(f"expected two whole numbers >= {least} ({what} along x and y), "
                              f"got {value!r}", field=f"board.{key}")
    return value[0], value[1]


def _dictionary_name(table, needed: int, what: str) -> str:
    """The dictionary of a board with ``needed`` markers; errors name the field."""
    name = table.get("dictionary")
    if not isinstance(name, str):
        raise VideoTrackError(f"type {table['type']!r} needs a dictionary name such as "
                              "'4X4_50'", field="board.dictionary")
    available = _dictionary(name).bytesList.shape[0]
    if needed > available:
        raise VideoTrackError(f"dictionary {name} has {available} markers, too few for {what}",
                              field="board.dictionary")
    return name


def _grid_from_table(table: dict) -> Board:
    nx, ny = _counts(table, "markers", 2, "markers")
    marker = _number(table, "marker_mm")
    separation = _number(table, "separation_mm")
    dictionary = _dictionary_name(table, nx * ny, f"{nx}x{ny} markers")
    return Board("aruco", (nx, ny), marker + separation, marker, dictionary)


def board_from_table(table: dict) -> Board:
    """Validate a ``[board]`` table; errors name the field."""
    kind = table.get("type")
    if kind not in TYPES:
        raise VideoTrackError(f"expected one of {', '.join(TYPES)}, got {kind!r}",
                              field="board.type")
    unknown = set(table) - {"type", *_KEYS[kind]}
    if unknown:
        raise VideoTrackError(f"unknown key(s) {', '.join(sorted(unknown))} for type "
                              f"{kind!r}; expected type, {', '.join(_KEYS[kind])}",
                              field="board")
    if kind == "aruco":
        return _grid_from_table(table)
    squares = _counts(table, "squares", 3, "squares")
    if kind == "checkerboard" and squares[0] == squares[1]:
        raise VideoTrackError("a square checkerboard looks the same turned by 90°, so its "
                              "corners cannot be matched between views; use one with "
                              "different counts (e.g. [10, 7]) or a ChArUco board",
                              field="board.squares")
    square = _number(table, "square_mm")
    marker = dictionary = None
    if kind == "charuco":
        marker = _number(table, "marker_mm")
        if marker >= square:
            raise VideoTrackError(f"the marker ({marker:g} mm) must be smaller than the square "
                                  f"({square:g} mm)", field="board.marker_mm")
        dictionary = _dictionary_name(table, squares[0] * squares[1] // 2,
                                      f"{squares[0]}x{squares[1]} squares")
    legacy = table.get("legacy", False)
    if not isinstance(legacy, bool):
        raise VideoTrackError(f"expected true or false, got {legacy!r}", field="board.legacy")
    return Board(kind, squares, square, marker, dictionary, legacy)


def load_board(path) -> Board:
    """Read a board config (see the module docstring); errors name the file and field."""
    path = Path(path)
    try:
        doc = parse_toml(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as err:
        raise VideoTrackError(f"cannot read the board config: {err}", file=path) from None
    except tomllib.TOMLDecodeError as err:
        raise VideoTrackError(f"not valid TOML: {err}", file=path) from None
    try:
        if isinstance(doc.get("board"), dict):
            return board_from_table(doc["board"])
        if "board_x" in doc or isinstance(doc.get("calibration"), dict):
            return board_from_table({k: v for k, v in _from_anipose(doc).items()
                                     if v is not None})
        raise VideoTrackError("no [board] table (type, squares, square_mm ...)",
                              field="board")
    except VideoTrackError as err:
        raise err.located(file=path) from None
