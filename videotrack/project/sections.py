"""The sections of a project file: ``[video]``, ``[[views]]``, ``[filters]`` (with the filter
steps), ``[markers]``, ``[output]``, ``[chain]``, ``[cameras]``, ``[anneal]``, ``[fit]`` and
``[keypoints]``, registered in this order (the order of the reference in docs/config.md).

Each is declared once with the schema mechanism of :mod:`videotrack.project.schema`: by hand as
:class:`~videotrack.project.schema.Key` entries, or derived from a settings record
(``[anneal]`` from :class:`kinematics.fit.settings.AnnealParams`, ``[keypoints.filter]`` from
:class:`videotrack.markerless.filters.KeypointFilterSettings`). Allowed values that a command's
options share come from one definition: the start modes and profiles of
:mod:`kinematics.fit.settings`, the keypoint formats of :data:`videotrack.io.keypoints.FORMATS`,
and :data:`TRIANGULATION_METHODS` here. Import them from :mod:`videotrack.project.config`.
"""

from __future__ import annotations

from collections.abc import Mapping

from kinematics.fit.settings import PROFILES, AnnealParams
from videotrack.io.keypoints import FORMATS as KEYPOINT_FORMATS
from videotrack.project.schema import (
    Key,
    Section,
    Variants,
    record_from_table,
    record_keys,
    record_section,
    register_section,
)

#: Backends of the 3D keypoint route and of ``videotrack triangulate --method``: the
#: functions ``triangulate_<method>`` of :mod:`kinematics.observe.triangulation`.
TRIANGULATION_METHODS = ("linear", "ransac", "optim")
#: Starting points of the optimised triangulation (``videotrack triangulate --init``).
TRIANGULATION_INITS = ("linear", "ransac")
#: Routes of the markerless fit (``[keypoints] route``).
KEYPOINT_ROUTES = ("2d", "3d")

# -- the sections of marker detection -----------------------------------------------------------


def _frames_rule(text: str) -> str | None:
    from videotrack.detect.video import parse_frame_range

    try:
        parse_frame_range(text)
    except ValueError as err:
        return str(err)
    return None


def _odd(value: int) -> str | None:
    return None if value % 2 == 1 else f"must be odd (a kernel has a centre pixel), got {value}"


def _roi_rule(roi: list) -> str | None:
    if roi and len(roi) != 4:
        return f"must be [x, y, width, height], got {len(roi)} entries"
    if roi and (roi[2] < 1 or roi[3] < 1):
        return f"width and height must be at least 1, got {roi[2]} x {roi[3]}"
    return None


def _view_hsv_rule(hsv: list) -> str | None:
    if not hsv:
        return None
    if len(hsv) != 3:
        return f"must be [hue, saturation, value], got {len(hsv)} entries"
    return _hsv_rule(hsv)


def _hsv_rule(hsv: list) -> str | None:
    if hsv[0] > 179:
        return f"OpenCV hue runs 0..179, got {hsv[0]}"
    return None


def _rects_rule(rects: list) -> str | None:
    for i, r in enumerate(rects):
        if len(r) != 4 or r[2] < 1 or r[3] < 1:
            return f"entry {i} must be [x, y, width, height] with a positive size, got {r}"
    return None


def _polygons_rule(polygons: list) -> str | None:
    for i, poly in enumerate(polygons):
        if len(poly) < 3 or any(len(p) != 2 for p in poly):
            return f"polygon {i} must have at least 3 [x, y] points"
    return None


VIDEO = register_section(Section("video", (
    Key("path", "path | list[path]", doc="Video file or image-sequence folder; a list of them "
        "for synchronised cameras (one file per camera). Not needed when [keypoints] files is "
        "set."),
    Key("fps", "float", 0.0, "Frame rate; 0 takes it from the video (image sequences: 25).",
        min=0.0, max=1e6),
    Key("deinterlace", "str", "none", "Split each frame into its two fields (half-frames).",
        choices=("none", "fields")),
    Key("field_order", "str", "top", "Which field was exposed first: 'top' (even rows) or "
        "'bottom' (odd rows; PAL DV).", choices=("top", "bottom")),
    Key("line_doubling", "str", "none", "Stretch half-frames back to full height: 'repeat' "
        "rows or 'linear' interpolation.", choices=("none", "repeat", "linear")),
    Key("frames", "str", "", "Frame range 'A:B' (start included, stop excluded, 0-based); "
        "empty for all.", check=_frames_rule),
), doc="The video(s) to read and how to split frames in time."))

VIEWS = register_section(Section("views", (
    Key("name", "str", doc="Name of the view, unique."),
    Key("roi", "list[int]", [], "Rectangle [x, y, width, height] of the frame holding the view; "
        "empty for the whole frame.", min=0, check=_roi_rule),
    Key("flip_x", "bool", False, "Mirror the view left-right (a mirror set-up)."),
    Key("flip_y", "bool", False, "Mirror the view top-bottom."),
    Key("camera", "str", "", "Camera of this view in the camera file; empty: the view's name."),
    Key("video", "int", 0, "Index of the view's video in video.path (synchronised cameras).",
        min=0),
    Key("model_markers", "list[str]", [], "The chain's markers this view shows (names, or "
        "patterns such as 'LF_*'); the fit matches the view's detections to these only. "
        "Empty: all. For markers of several colours: one view per colour on the same "
        "camera, each with its colour's markers and hsv_lower/hsv_upper."),
    Key("hsv_lower", "list[int]", [], "This view keeps only markers of this colour: lowest "
        "[hue, saturation, value], in place of the filter chain's hsv_range step (which the "
        "chain must have). Empty: the chain's own range.", min=0, max=255,
        check=_view_hsv_rule),
    Key("hsv_upper", "list[int]", [], "Highest [hue, saturation, value] of this view's "
        "colour (with hsv_lower).", min=0, max=255, check=_view_hsv_rule),
), doc="One entry per view: a rectangle of a video frame seen by one camera.", array=True))

_MORPH_KEYS = (
    Key("size", "int", 3, "Kernel size in pixels (odd).", min=1, max=99, check=_odd),
    Key("iterations", "int", 1, "How often the operation is repeated.", min=1, max=100),
    Key("shape", "str", "ellipse", "Kernel shape.", choices=("ellipse", "rect", "cross")),
)

FILTER_STEPS = Variants("filters.steps", "type", {
    "channel": Section("channel", (
        Key("channel", "str", doc="Colour channel to keep as the grey image.",
            choices=("blue", "green", "red")),
    ), doc="Colour → grey: keep one colour channel."),
    "grey": Section("grey", (), doc="Colour → grey: luminance (OpenCV's BGR2GRAY)."),
    "hsv_range": Section("hsv_range", (
        Key("lower", "list[int]", doc="Lowest [hue, saturation, value]; hue 0..179.",
            length=3, min=0, max=255, check=_hsv_rule),
        Key("upper", "list[int]", doc="Highest [hue, saturation, value]. A lower hue above the "
            "upper hue wraps around red.", length=3, min=0, max=255, check=_hsv_rule),
    ), doc="Colour → mask: pixels whose HSV colour lies in the range."),
    "background": Section("background", (
        Key("frames", "int", 25, "Frames sampled evenly over the whole video for the median.",
            min=3, max=500),
        Key("polarity", "str", "brighter", "Keep what is brighter than the background, darker, "
            "or both (absolute difference).", choices=("brighter", "darker", "both")),
    ), doc="Grey → grey: subtract the per-pixel median of sampled frames (computed once)."),
    "invert": Section("invert", (), doc="Grey or mask: 255 - value (dark markers become bright)."),
    "threshold": Section("threshold", (
        Key("value", "int", doc="Pixels brighter than this grey level become marker pixels.",
            min=0, max=254),
    ), doc="Grey → mask: global threshold."),
    "otsu": Section("otsu", (), doc="Grey → mask: threshold chosen per image by Otsu's method."),
    "adaptive": Section("adaptive", (
        Key("block_size", "int", 15, "Side of the neighbourhood in pixels (odd).", min=3,
            max=255, check=_odd),
        Key("offset", "float", 10.0, "A pixel is a marker pixel when it exceeds its "
            "neighbourhood's mean by more than this.", min=-255.0, max=255.0),
        Key("method", "str", "mean", "Neighbourhood mean: plain or Gaussian-weighted.",
            choices=("mean", "gaussian")),
    ), doc="Grey → mask: threshold relative to the local mean."),
    "erode": Section("erode", _MORPH_KEYS, doc="Shrink bright regions (grey or mask)."),
    "dilate": Section("dilate", _MORPH_KEYS, doc="Grow bright regions (grey or mask)."),
    "open": Section("open", _MORPH_KEYS, doc="Erode then dilate: removes specks."),
    "close": Section("close", _MORPH_KEYS, doc="Dilate then erode: fills small holes."),
    "mask": Section("mask", (
        Key("rects", "list[list[int]]", [], "Rectangles [x, y, width, height] in view "
            "coordinates.", min=0, check=_rects_rule),
        Key("polygons", "list[list[list[float]]]", [], "Polygons [[x, y], ...] in view "
            "coordinates.", check=_polygons_rule),
        Key("image", "path", "", "Image of the view's size; non-zero pixels are masked."),
        Key("keep", "bool", False, "true: keep only the masked area, discard the rest."),
        Key("view", "str", "", "Apply to this view only; empty: every view."),
    ), doc="Any → same: zero the masked area (static reflections, the frame of a mirror)."),
}, doc="Filter steps run in order on each view image; the chain must end with a mask.")

FILTERS = register_section(Section("filters", (
    Key("steps", "list[table]", doc="Ordered filter steps ([[filters.steps]] tables); not "
        "needed when [keypoints] files is set.",
        items=FILTER_STEPS),
), doc="The filter chain that turns a view image into a mask of marker pixels."))

MARKERS = register_section(Section("markers", (
    Key("min_area", "int", 1, "Smallest marker region in pixels.", min=1, max=10**7),
    Key("max_area", "int", 10000, "Largest marker region in pixels.", min=1, max=10**8),
    Key("max_aspect", "float", 0.0, "Largest ratio of a region's long to short axis (second "
        "moments); 0 turns the gate off.", min=0.0, max=1000.0,
        check=lambda v: None if v == 0 or v >= 1 else f"must be 0 (off) or at least 1, got {v}"),
    Key("min_circularity", "float", 0.0, "Smallest circularity area/(2π·(λ1+λ2)) (1 for a "
        "disc, lower for elongated or ragged regions); 0 turns the gate off.", min=0.0,
        max=1.0),
    Key("weighting", "str", "intensity", "Centroid of the pixel intensities (sub-pixel) or of "
        "the region's pixels ('binary').", choices=("intensity", "binary")),
    Key("window_pad", "int", 1, "Pixels added around a region for the intensity-weighted "
        "centroid and its local background.", min=0, max=20),
    Key("connectivity", "int", 8, "Pixel neighbourhood of a region.", choices=(4, 8)),
), doc="Which regions of the mask are markers, and how their centroids are measured."))

OUTPUT = register_section(Section("output", (
    Key("detections", "path", "", "Detections file; empty: '<first video>.detections.npz' "
        "beside the config file."),
), doc="Where results go."))


# -- model and fitting ----------------------------------------------------------------------

CHAIN = register_section(Section("chain", (
    Key("path", "path", "", "Chain XML file (joints, axes, segments, markers)."),
    Key("histograms", "path", "", "Histogram archive XML applied on top of the chain's own "
        "histograms (e.g. learned in an earlier experiment); empty for none."),
), doc="The kinematic model fitted to the detections."))

CAMERAS = register_section(Section("cameras", (
    Key("path", "path", "", "Camera TOML file; every view's camera must be in it."),
), doc="Where the cameras of the views are described."))

# Every field of AnnealParams (and of its ErrorOptions, flattened: ``error`` is the mode) is a
# key, with the type, default, bounds and doc declared in kinematics/fit/settings.py.
_ANNEAL_DOC = ("Simulated annealing (Eq. 6), the error function (Eq. 5 or a variant) and the "
               "choice among candidate postures; defaults are the best measured settings, "
               "profile = \"paper\" gives the paper's (Table 1, Eq. 5).")
ANNEAL = register_section(Section("anneal", (
    Key("profile", "str", "best", "Settings every other key of this section starts from: "
        "'best' (the best measured, the defaults listed here) or 'paper' (the paper's Table 1 "
        "and Eq. 5, no refinement, one answer per frame: reproduces Table 2). Keys you set "
        "yourself override the profile.", choices=PROFILES),
    *record_section("anneal", AnnealParams).keys), _ANNEAL_DOC))


def anneal_from_table(table: Mapping, given=None, *, file=None) -> AnnealParams:
    """The :class:`AnnealParams` of a checked ``[anneal]`` table: its profile's settings,
    with the keys the file sets (``given``; default every key) on top."""
    profile = table.get("profile", "best")
    base = {k.key.name: k.key.default for k in record_keys(AnnealParams,
                                                           AnnealParams.profile(profile))}
    given = set(table if given is None else given)
    values = {name: (table[name] if name in given else default)
              for name, default in base.items()}
    return record_from_table(AnnealParams, values, file=file, where="anneal")

FIT = register_section(Section("fit", (
    Key("results", "path", "", "Results CSV; empty: '<detections>.results.csv' beside the "
        "detections file."),
    Key("plot", "bool", False, "Also write a PNG of the angle time courses with bad frames "
        "marked (beside the results)."),
    Key("jobs", "int", 0, "Threads for fitting; 0 uses every core.", min=0, max=1024),
), doc="Outputs of 'videotrack fit' and 'videotrack run'."))


# -- the markerless route -------------------------------------------------------------------

def _pairs_rule(offsets: list) -> str | None:
    for i, pair in enumerate(offsets):
        if len(pair) != 2:
            return f"entry {i} must be [x, y], got {pair}"
    return None


def _names_rule(table: Mapping) -> str | None:
    for kp, marker in table.items():
        if not isinstance(marker, str) or not marker:
            return f"{kp}: must name a chain marker (a string), got {marker!r}"
    return None


def _keypoint_filter_section() -> Section:
    from videotrack.markerless.filters import KeypointFilterSettings

    return record_section("keypoints.filter", KeypointFilterSettings,
                          "Anipose's 2D filters, each off by default (docs/markerless.md).")


KEYPOINTS = register_section(Section("keypoints", (
    Key("files", "list[path]", [], "2D keypoint files (or OpenPose JSON folders), one per "
        "camera: per view in the order of [[views]], else per camera in the camera file's "
        "order. Empty: the marker route (detect markers in the video)."),
    Key("format", "str", "", "Keypoint file format; empty: detected from each file.",
        choices=("", *KEYPOINT_FORMATS)),
    Key("individual", "str", "", "The animal, track or person to follow: a name or an index; "
        "empty: the first (OpenPose: the largest person)."),
    Key("model", "str", "", "OpenPose keypoint names: BODY_25, BODY_25B or COCO; empty: "
        "from the number of points."),
    Key("crop_offsets", "list[list[float]]", [], "Per file, [x, y] pixels added to its "
        "keypoints (the tracker ran on a crop); empty: none.", check=_pairs_rule),
    Key("frame_offsets", "list[int]", [], "Per file, added to its frame numbers (the tracked "
        "video started later); empty: none."),
    Key("markers", "table", {}, "Keypoint name = chain marker name; empty: keypoints map to "
        "the markers named like them. Keypoints without a marker are left out.",
        check=_names_rule),
    Key("route", "str", "2d", "'2d': fit the chain to the 2D keypoints (labelled "
        "reprojection error); '3d': triangulate them first and fit the chain to the 3D "
        "points (set [anneal] tau0 and reanalysis_threshold in length units).",
        choices=KEYPOINT_ROUTES),
    Key("triangulation", "str", "linear", "Route '3d': the triangulation backend.",
        choices=TRIANGULATION_METHODS),
    Key("min_score", "float", 0.0, "Keypoints scored below this are not used (after the "
        "filters).", min=0.0, max=1.0),
    Key("filter", "table", {}, "[keypoints.filter]: the 2D filters (keys below).",
        items=_keypoint_filter_section()),
), doc="The markerless route: fit the chain to 2D keypoints (DeepLabCut, SLEAP, OpenPose, "
       "Lightning Pose, Anipose) instead of detected markers; [video] and [filters] are then "
       "not needed."))
