"""Calibration boards: the board config (TOML) and corner detection in one image.

A board config has a ``[board]`` table::

    [board]
    type = "charuco"            # or "checkerboard"
    squares = [8, 11]           # squares along x (columns) and y (rows)
    square_mm = 24.0            # side of one square
    marker_mm = 18.75           # ChArUco only: side of one ArUco marker
    dictionary = "4X4_1000"     # ChArUco only: an OpenCV ArUco dictionary
    legacy = false              # ChArUco only: OpenCV < 4.6 pattern (even row counts)

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

from videotrack.errors import VideoTrackError

__all__ = ["Board", "load_board"]

TYPES = ("checkerboard", "charuco")
_KEYS = ("type", "squares", "square_mm", "marker_mm", "dictionary", "legacy")
#: Fewest ChArUco corners that make a usable (non-degenerate, rarely wrong) partial view.
MIN_CHARUCO_CORNERS = 6
#: Images wider or taller than this are searched for a checkerboard at reduced size first.
_SEARCH_SIZE = 1000


@dataclass(frozen=True)
class Board:
    """A checkerboard or ChArUco board; see the module docstring for the fields."""

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

    @property
    def inner(self) -> tuple[int, int]:
        """Inner corners along x and y (the checkerboard ``patternSize`` of OpenCV)."""
        return self.squares[0] - 1, self.squares[1] - 1

    @property
    def object_points(self) -> np.ndarray:
        """Corner positions (n, 3) in mm, row by row (x fastest), z = 0."""
        if self.type == "charuco":
            return np.asarray(self._cv.getChessboardCorners(), dtype=np.float64).reshape(-1, 3)
        nx, ny = self.inner
        yy, xx = np.mgrid[0:ny, 0:nx]
        pts = np.stack([xx.ravel(), yy.ravel(), np.zeros(nx * ny)], -1) * self.square_mm
        return pts

    @property
    def n_corners(self) -> int:
        return self.inner[0] * self.inner[1]

    def describe(self) -> str:
        nx, ny = self.squares
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
        return self._detect_checkerboard(image)

    def _detect_charuco(self, grey):
        detector = cv2.aruco.CharucoDetector(self._cv)
        corners, ids, _, _ = detector.detectBoard(grey)
        if ids is None or len(ids) < MIN_CHARUCO_CORNERS:
            return np.zeros(0, int), np.zeros((0, 2))
        return ids.ravel().astype(int), corners.reshape(-1, 2).astype(np.float64)

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


def board_from_table(table: dict) -> Board:
    """Validate a ``[board]`` table; errors name the field."""
    unknown = set(table) - set(_KEYS)
    if unknown:
        raise VideoTrackError(f"unknown key(s) {', '.join(sorted(unknown))}; expected "
                              f"{', '.join(_KEYS)}", field="board")
    kind = table.get("type")
    if kind not in TYPES:
        raise VideoTrackError(f"expected one of {', '.join(TYPES)}, got {kind!r}",
                              field="board.type")
    squares = table.get("squares")
    if (not isinstance(squares, list) or len(squares) != 2
            or not all(isinstance(s, int) and not isinstance(s, bool) and s >= 3
                       for s in squares)):
        raise VideoTrackError(f"expected two whole numbers >= 3 (squares along x and y), got "
                              f"{squares!r}", field="board.squares")
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
        dictionary = table.get("dictionary")
        if not isinstance(dictionary, str):
            raise VideoTrackError("a ChArUco board needs a dictionary name such as '4X4_50'",
                                  field="board.dictionary")
        available = _dictionary(dictionary).bytesList.shape[0]
        if squares[0] * squares[1] // 2 > available:
            raise VideoTrackError(f"dictionary {dictionary} has {available} markers, too few "
                                  f"for {squares[0]}x{squares[1]} squares",
                                  field="board.dictionary")
    legacy = table.get("legacy", False)
    if not isinstance(legacy, bool):
        raise VideoTrackError(f"expected true or false, got {legacy!r}", field="board.legacy")
    return Board(kind, (squares[0], squares[1]), square, marker, dictionary, legacy)


def load_board(path) -> Board:
    """Read a board config (see the module docstring); errors name the file and field."""
    path = Path(path)
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
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
