"""``alcn pose overlay-error``: how far the drawn box sits from the object's edges in the image.

A tracked pose can reproject the model's points within a pixel and still draw the box tens of
pixels off the object, when the box itself is misplaced in the model (:mod:`pose.box_fit`).
This measures the drawn box against the image, with no ground truth:

1. the box's *visible* edges under the pose: those of a face turned towards the camera
   (:func:`visible_edges`), projected and sampled every ``step`` pixels, the ends (``trim``)
   left out (corners are where the hand holds the box and where the edges of two faces meet);
2. the image's edges: Canny on the blurred colour frame, each edge pixel with the direction of
   its gradient (Sobel; :func:`image_edges`);
3. for each sample, the signed distance along the projected edge's normal to the nearest image
   edge pixel whose gradient is within ``max_angle`` degrees of that normal (an edge parallel to
   the drawn one; texture edges across it do not count), searched up to ``max_distance``
   pixels; a sample with none counts as ``max_distance`` (:func:`edge_offsets`).

A frame's error is the mean absolute distance over its samples (:func:`frame_error`); the
report (:func:`main`) gives per run (a part model and its poses, e.g. before and after a change
of the box fit) the mean, median and worst frames, a plot over the video, and the mean signed
offset of each of the 12 box edges (which edges are off, and in which direction).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from alcn_cv import io
from alcn_cv.errors import DatasetError, InputError
from alcn_cv.io import atomic_write, check_no_earlier_output, make_folder, write_json
from alcn_cv.report import describe_machine, machine, markdown_table, nan_to_none, new_figure, save_figure
from pose import model as part_model
from pose.box import facing_faces
from pose.model import BOX_EDGES
from pose.solver import project

logger = logging.getLogger(__name__)

#: The largest :attr:`EdgeSettings.max_distance`, pixels: five times the default; a box drawn farther off its
#: object is lost, not misplaced (and the search's cost grows with it).
MAX_DISTANCE = 200.0
#: The largest :attr:`EdgeSettings.max_angle`, degrees: an edge's gradient is at most 90 degrees from a normal
#: (either way across the edge), so 90 takes every image edge.
MAX_ANGLE = 90.0
#: The files :func:`main` writes into its folder.
REPORT_FILES = ("overlay_error.md", "overlay_error.json", "overlay_error.png", "overlay_frames.png")


@dataclass
class EdgeSettings:
    """Settings of :func:`edge_offsets`.

    Attributes:
        step: distance between samples along a projected edge, pixels.
        trim: fraction of each edge left out at each end.
        max_distance: search range along the normal, pixels, 1 to :data:`MAX_DISTANCE`; a sample without an image
            edge in range counts as this.
        max_angle: largest angle (degrees) between an image edge's gradient and the drawn
            edge's normal, above 0 and at most :data:`MAX_ANGLE`.
        canny: Canny's low and high thresholds; ``blur``: Gaussian sigma before it.

    Raises:
        InputError: ``max_distance`` or ``max_angle`` out of range (``alcn pose overlay-error`` checks its options
            as it parses them).
    """

    step: float = 3.0
    trim: float = 0.1
    max_distance: float = 40.0
    max_angle: float = 20.0
    canny: tuple[float, float] = (40.0, 100.0)
    blur: float = 1.5

    def __post_init__(self) -> None:
        # `not <=`: NaN is in no range
        if not 1 <= self.max_distance <= MAX_DISTANCE:
            raise InputError(f"--max-distance must be 1 to {MAX_DISTANCE:g} px, got {self.max_distance:g}")
        if not 0 < self.max_angle <= MAX_ANGLE:
            raise InputError(f"--max-angle must be above 0 and at most {MAX_ANGLE:g} degrees, got {self.max_angle:g}")


def visible_edges(corners: np.ndarray, rvec: np.ndarray, tvec: np.ndarray) -> list[tuple[int, int]]:
    """The edges (pairs of :data:`pose.model.BOX_EDGES`) of a face turned towards the camera.

    ``corners`` ``(8, 3)``: a box in the order of :func:`pose.model.box_corners` (its faces:
    :func:`pose.box.facing_faces`); ``rvec, tvec`` the object-to-camera pose."""
    R = cv2.Rodrigues(np.asarray(rvec, np.float64))[0]
    front = [set(quad) for quad in facing_faces(np.asarray(corners, np.float64), R, np.ravel(tvec))]
    return [(i, j) for i, j in BOX_EDGES if any({i, j} <= face for face in front)]


def image_edges(image: np.ndarray, settings: EdgeSettings) -> tuple[np.ndarray, np.ndarray]:
    """Canny edge mask ``(H, W)`` bool and the gradient direction ``(H, W)`` (radians) of ``image``
    (grey or BGR uint8). A colour image's edges are Canny's on its three channels (the channel of
    the strongest gradient at each pixel; its direction likewise): the yellow cookie box on the
    white tablecloth has almost no grey-level edge (``docs/journal.md``)."""
    g = cv2.GaussianBlur(image, (0, 0), settings.blur) if settings.blur > 0 else image
    edges = cv2.Canny(g, *settings.canny, L2gradient=True) > 0
    gx = cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3).reshape(*g.shape[:2], -1)
    gy = cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3).reshape(*g.shape[:2], -1)
    strongest = np.argmax(gx**2 + gy**2, axis=2)[..., None]
    gx, gy = np.take_along_axis(gx, strongest, 2)[..., 0], np.take_along_axis(gy, strongest, 2)[..., 0]
    return edges, np.arctan2(gy, gx)


def edge_offsets(
    edges: np.ndarray, angle: np.ndarray, a: np.ndarray, b: np.ndarray, settings: EdgeSettings
) -> np.ndarray:
    """Signed distances (pixels, along the normal ``(-dy, dx)`` of ``b - a``) from samples of the
    segment ``a -> b`` to the nearest image edge parallel to it; NaN where none is within
    ``settings.max_distance`` or the sample is outside the image. Empty when the segment less
    its trimmed ends (``settings.trim``) is shorter than two steps."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    length = float(np.linalg.norm(b - a))
    n_samples = int(length * (1 - 2 * settings.trim) / settings.step)
    if n_samples < 2:
        return np.zeros(0)
    d = (b - a) / length
    normal = np.array([-d[1], d[0]])
    t = np.linspace(settings.trim, 1 - settings.trim, n_samples)
    samples = a + t[:, None] * (b - a)
    r = int(np.ceil(settings.max_distance))
    offsets = np.arange(-r, r + 1, dtype=np.float64)
    pts = np.rint(samples[:, None, :] + offsets[None, :, None] * normal).astype(np.int64)
    h, w = edges.shape
    inside = (pts[..., 0] >= 0) & (pts[..., 0] < w) & (pts[..., 1] >= 0) & (pts[..., 1] < h)
    x, y = np.clip(pts[..., 0], 0, w - 1), np.clip(pts[..., 1], 0, h - 1)
    normal_angle = np.arctan2(normal[1], normal[0])
    # the gradient may point either way across the edge (dark-to-bright or bright-to-dark)
    diff = np.abs(np.angle(np.exp(2j * (angle[y, x] - normal_angle)))) / 2
    hit = inside & edges[y, x] & (diff <= np.radians(settings.max_angle))
    dist = np.where(hit, np.abs(offsets)[None, :], np.inf)
    nearest = np.argmin(dist, axis=1)
    out = offsets[nearest]
    out[~np.isfinite(dist[np.arange(n_samples), nearest])] = np.nan
    out[~inside[:, r]] = np.nan  # the sample itself is off the image: no measurement
    return out


@dataclass
class FrameError:
    """The drawn box against one frame's edges.

    Attributes:
        mean_px: mean absolute distance over the samples (a sample without an image edge in
            range counts as ``max_distance``); NaN without a pose or a visible edge.
        found: share of the samples with an image edge in range.
        matched_px: mean absolute distance over those samples only.
        edges: per visible box edge ``(i, j)``, the mean signed offset (pixels, NaN when none found).
    """

    mean_px: float
    found: float
    matched_px: float
    edges: dict[tuple[int, int], float]


def frame_error(
    image: np.ndarray,
    corners: np.ndarray,
    rvec: np.ndarray,
    tvec: np.ndarray,
    K: np.ndarray,
    settings: EdgeSettings | None = None,
    dist: np.ndarray | None = None,
) -> FrameError:
    """How far the box ``corners (8, 3)`` drawn with the pose ``rvec, tvec`` is from the edges of
    ``image`` (grey or BGR uint8, :func:`image_edges`)."""
    settings = settings or EdgeSettings()
    edges, angle = image_edges(image, settings)
    uv = project(corners, rvec, tvec, K, dist)
    per_edge, values = {}, []
    for i, j in visible_edges(corners, rvec, tvec):
        off = edge_offsets(edges, angle, uv[i], uv[j], settings)
        if len(off) == 0:
            continue
        per_edge[(i, j)] = float(np.nanmean(off)) if np.any(~np.isnan(off)) else float("nan")
        values.append(off)
    if not values:
        return FrameError(float("nan"), 0.0, float("nan"), {})
    allv = np.concatenate(values)
    found = ~np.isnan(allv)
    err = np.where(found, np.abs(allv), settings.max_distance)
    matched = float(err[found].mean()) if found.any() else float("nan")
    return FrameError(float(err.mean()), float(found.mean()), matched, per_edge)


#: A run as drawn: the box corners, ``K``, the distortion or None, and the ``(rvec, tvec)`` of every posed frame.
Drawn = tuple[np.ndarray, np.ndarray, np.ndarray | None, dict[str, tuple[np.ndarray, np.ndarray]]]


def _camera_and_poses(model_path: str | Path, poses_path: str | Path) -> Drawn:
    """The box corners, the camera the poses were solved with (``K``, and its distortion or ``None``: the one their
    ``_info.json`` records, :func:`pose.track.tracked_camera`, else the part model's, which ``alcn pose track`` tracks
    with by default) and the ``(rvec, tvec)`` of every posed frame (``tvec`` in the model's units:
    :func:`pose.track.read_poses`).

    Raises:
        DatasetError: as :func:`pose.track.tracked_camera` (poses of another model, an unrecorded camera), or no
            camera at all.
    """
    from pose.track import read_poses, tracked_camera

    model = part_model.load(model_path)
    poses = read_poses(poses_path, model.units)  # first: an info beside other poses is refused as such
    camera = tracked_camera(poses_path, model_path)
    if camera is None:
        if "K" not in model.extra:
            raise DatasetError(f"{model_path}: stores no camera (build it from a video with `alcn pose build`)")
        dist = model.extra.get("dist")  # a model built before it stored the distortion has none
        camera = np.asarray(model.extra["K"], np.float64), None if dist is None else np.asarray(dist, np.float64)
    return model.corners, *camera, poses


def measure(
    model_path: str | Path,
    poses_path: str | Path,
    video: str | Path,
    settings: EdgeSettings | None = None,
    progress: bool = True,
) -> dict[str, FrameError]:
    """:class:`FrameError` of every frame of ``video`` posed in ``poses_path`` (``alcn pose track``'s
    JSON) with the box of ``model_path`` and the camera the poses were solved with (:func:`_camera_and_poses`)."""
    return _measure(_camera_and_poses(model_path, poses_path), video, settings, progress)


def _measure(drawn: Drawn, video: str | Path, settings: EdgeSettings | None, progress: bool) -> dict[str, FrameError]:
    corners, K, dist, poses = drawn
    out = {}
    frames = io.iter_frames(video)
    for name, frame in io.frame_progress(
        frames, io.count_frames(video), desc="overlay error", leave=False, disable=not progress
    ):
        if name not in poses:
            out[name] = FrameError(float("nan"), 0.0, float("nan"), {})
            continue
        out[name] = frame_error(frame, corners, *poses[name], K, settings, dist)
    return out


def summarize(errors: dict[str, FrameError], worst: int = 5) -> dict[str, Any]:
    """Mean, median, 90th percentile and worst frames of a run's :class:`FrameError`s, and the mean
    signed offset of each box edge over the frames where it was visible."""
    names = [n for n, e in errors.items() if np.isfinite(e.mean_px)]
    values = np.array([errors[n].mean_px for n in names])
    if len(values) == 0:
        return {"frames": 0}
    order = np.argsort(-values)[:worst]
    per_edge = {}
    for i, j in BOX_EDGES:
        v = [e.edges[(i, j)] for e in errors.values() if np.isfinite(e.edges.get((i, j), np.nan))]
        if v:
            per_edge[f"{i}-{j}"] = {
                "mean_signed_px": float(np.mean(v)),
                "mean_abs_px": float(np.mean(np.abs(v))),
                "frames": len(v),
            }
    # the box's systematic misplacement: how far each edge is off on average, whatever the texture
    bias = [abs(e["mean_signed_px"]) for e in per_edge.values()]
    # frames where no sample found an image edge have no mean of those found (NaN; not a warning of numpy's)
    matched = [errors[n].matched_px for n in names if np.isfinite(errors[n].matched_px)]
    return {
        "frames": len(values),
        "mean_px": float(values.mean()),
        "median_px": float(np.median(values)),
        "edge_bias_px": float(np.mean(bias)) if bias else float("nan"),
        "p90_px": float(np.percentile(values, 90)),
        "found": float(np.mean([errors[n].found for n in names])),
        "matched_px": float(np.mean(matched)) if matched else float("nan"),
        "worst": [[names[k], float(values[k])] for k in order],
        "edges": per_edge,
    }


def plot_errors(runs: dict[str, dict[str, FrameError]], path: str | Path, max_distance: float) -> Path:
    """Per-frame error of each run over the video."""
    plt, fig, axes = new_figure(figsize=(10, 3.5))
    ax = axes[0, 0]
    for label, errors in runs.items():
        v = np.array([e.mean_px for e in errors.values()])
        ax.plot(np.arange(len(v)), v, lw=1, label=f"{label} (mean {np.nanmean(v):.1f} px)")
    ax.set(
        xlabel="frame",
        ylabel="mean distance to image edges (px)",
        ylim=(0, max_distance),
        title="Drawn box vs. the image's edges (visible box edges, Canny, oriented)",
    )
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return save_figure(plt, fig, path, dpi=110)


def plot_frames(video: str | Path, runs: dict[str, Drawn], names: Sequence[str], path: str | Path) -> Path:
    """The frames ``names`` of ``video`` with each run's box (label -> :data:`Drawn`) in its own colour, side by
    side; a run without a pose for a frame (not tracked, or lost) is labelled so there, and said in the log."""
    from pose.track import draw_box

    colors = [(0, 0, 255), (255, 120, 0), (0, 200, 0), (0, 220, 255)]
    wanted, tiles = set(names), {}
    for name, frame in io.iter_frames(video):
        if name in wanted:
            vis = frame.copy()
            for k, (label, (corners, K, dist, poses)) in enumerate(runs.items()):
                color, shown = colors[k % len(colors)], label
                if name in poses:
                    draw_box(vis, corners, *poses[name], K, color, thickness=1, dist=dist)
                else:
                    logger.warning("%s: the run %r has no pose for it (not tracked, or lost): no box", name, label)
                    shown = f"{label}: no pose"
                cv2.putText(vis, shown, (8, 20 + 18 * k), cv2.FONT_HERSHEY_SIMPLEX, 0.55, color, 2)
            cv2.putText(vis, name, (8, vis.shape[0] - 10), cv2.FONT_HERSHEY_SIMPLEX, 0.55, (255, 255, 255), 2)
            tiles[name] = vis
    missing = [n for n in names if n not in tiles]
    if missing:
        logger.warning("%s holds no frame named %s; %s leaves it out", video, ", ".join(missing), Path(path).name)
    io.write_image(path, np.hstack([tiles[n] for n in names if n in tiles]))
    return Path(path)


def main(
    video: str | Path,
    runs: Sequence[tuple[str, str | Path, str | Path]],
    out_dir: str | Path,
    *,
    settings: EdgeSettings | None = None,
    command: str = "",
    show: Sequence[str] = ("frame_000300",),
    overwrite: bool = False,
    progress: bool = True,
) -> dict[str, Any]:
    """Measure every run ``(label, model, poses)`` on ``video``; writes ``overlay_error.md``,
    ``overlay_error.json``, ``overlay_error.png`` (the error over the video) and
    ``overlay_frames.png`` (the frames ``show`` and the first run's two worst with every run's
    box) into ``out_dir`` (:data:`REPORT_FILES`), all or none: a failure while writing removes them all, an earlier
    report's replaced ones included.

    Args:
        overwrite: replace the report of an earlier run in ``out_dir``.

    Raises:
        InputError: ``out_dir`` a file, or a report in it without ``overwrite`` (before any work); a run without a
            posed frame of ``video``.
    """
    settings = settings or EdgeSettings()
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError(f"{out_dir} is a file; the output is a folder")
    check_no_earlier_output([out_dir / name for name in REPORT_FILES], overwrite)
    drawn = {label: _camera_and_poses(model, poses) for label, model, poses in runs}  # all checked before any work
    errors = {label: _measure(d, video, settings, progress) for label, d in drawn.items()}
    for (label, _, poses), measured in zip(runs, errors.values()):
        if not any(np.isfinite(e.mean_px) for e in measured.values()):
            raise InputError(f"run {label}: no frame of {video} is posed in {poses}; nothing to measure")
    make_folder(out_dir)
    summary = {label: summarize(e) for label, e in errors.items()}
    host = machine()
    rows = [
        [
            label,
            s.get("frames"),
            s.get("mean_px"),
            s.get("median_px"),
            s.get("p90_px"),
            s.get("found"),
            s.get("matched_px"),
            s.get("edge_bias_px"),
            ", ".join(f"{n} ({v:.1f})" for n, v in s.get("worst", [])[:3]),
        ]
        for label, s in summary.items()
    ]
    edge_rows = [
        [f"{i}-{j}", *(summary[label].get("edges", {}).get(f"{i}-{j}", {}).get("mean_signed_px") for label in errors)]
        for i, j in BOX_EDGES
    ]
    md = (
        "# The drawn box against the image's edges\n\n"
        f"Command: `{command}`\n\nMachine: {describe_machine(host)}\n\nVideo: `{video}`. Per frame: the mean "
        "distance (px) from samples of the box's visible projected edges to the nearest parallel image edge "
        f"(Canny on the colour frame blurred by sigma {settings.blur:g}, thresholds {settings.canny[0]:g}/"
        f"{settings.canny[1]:g}; gradient within {settings.max_angle:g} deg of the drawn edge's normal; none "
        f"within {settings.max_distance:g} px counts as {settings.max_distance:g}); `found`: share of the samples "
        "with an image edge in range, `mean of found`: their mean distance alone; `edge bias`: the mean over the "
        "box's edges of the absolute value of each edge's mean signed offset (the box's systematic misplacement, "
        "which the texture's random matches average out of). Texture edges parallel to the box's, the hand and "
        "motion blur give the per-frame distances a floor of several pixels.\n\n"
        + markdown_table(
            [
                "run",
                "frames",
                "mean (px)",
                "median (px)",
                "90th pct (px)",
                "found",
                "mean of found (px)",
                "edge bias (px)",
                "worst frames",
            ],
            rows,
            digits=2,
        )
        + "\n\nMean signed offset of each box edge (px, along the normal of the projected edge; corners "
        "numbered as in `pose.model.box_corners`):\n\n" + markdown_table(["edge", *errors], edge_rows, digits=1) + "\n"
    )
    record = {
        "command": command,
        "machine": host,
        "video": str(video),
        "settings": vars(settings),
        # a statistic of no sample (the mean distance of the edges found, where none was) is null, not NaN
        "runs": nan_to_none(
            {
                label: {
                    "model": str(m),
                    "poses": str(p),
                    **summary[label],
                    "per_frame": {n: e.mean_px for n, e in errors[label].items()},
                }
                for label, m, p in runs
            }
        ),
    }
    worst = [n for n, _ in next(iter(summary.values())).get("worst", [])[:2]]
    paths = [out_dir / name for name in REPORT_FILES]
    md_path, json_path, plot_path, frames_path = paths
    try:
        write_json(json_path, record)
        plot_errors(errors, plot_path, settings.max_distance)
        plot_frames(video, drawn, list(dict.fromkeys([*show, *worst])), frames_path)
        atomic_write(md_path, md)
    except BaseException:
        # no report in part, nor this run's files beside an earlier report's (--overwrite): a failed report is not
        # mistaken for a whole one
        for path in paths:
            path.unlink(missing_ok=True)
        raise
    for label, s in summary.items():
        logger.info(
            "%s: mean %.2f px, median %.2f px over %d frames",
            label,
            s.get("mean_px", np.nan),
            s.get("median_px", np.nan),
            s.get("frames", 0),
        )
    return summary
