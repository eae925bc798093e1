"""Training frames of the corner detector (:mod:`pose.corners`), from a registered sequence.

Every view of the training sequence is downscaled, then copied; a share of the copies first sees
the box from a nearby viewpoint (:func:`novel_view`: each face warped by its own plane's
homography, the table by its plane's), then every copy gets the data engine's kinds of
augmentation applied to the whole frame: a random homography (in-plane rotation, scaling,
perspective and shift: the viewpoints between and around the training views), the background
(outside the BOP ``mask_visib``) replaced by the data engine's random textures
(:func:`alcn_cv.data.textures.display_texture`), and an intensity change ``a I + b`` with noise
(the ranges of :func:`alcn_cv.data.synthetic.augment`'s). The box's parts (:func:`pose.box.box_parts`:
its corners, the middles of its edges and the centres of its faces) follow the homography. Each
frame is normalized whole, as at test time, and labelled on the network's output grid
(:func:`label_grid`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np

from alcn_cv.errors import InputError
from alcn_cv.io import to_gray
from pose.box import box_parts, facing_faces, part_visibility, project_points
from pose.corners import PAD, STRIDE, downscale, grid_centres, grid_shape, normalization_for, scaled_camera, to_scaled
from pose.sequence import TrainingSequence

if TYPE_CHECKING:
    from alcn_cv.enhance.base import Normalization
    from pose.corner_train import CornerRecipe

logger = logging.getLogger(__name__)


def _read_mask(path: Path, shape: tuple[int, int]) -> np.ndarray | None:
    if not path.is_file():
        return None
    m = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    return m if m is not None and m.shape == shape else None


def replace_background(gray: np.ndarray, mask: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """``gray`` uint8 with the pixels outside ``mask`` (uint8, 255 = object; intermediate
    values blend) replaced by a random texture (:func:`alcn_cv.data.textures.display_texture`,
    gamma-encoded like a photograph)."""
    from alcn_cv.data.textures import display_texture

    texture = display_texture(rng, gray.shape)
    alpha = mask.astype(np.float32) / np.float32(255)
    out = alpha * gray.astype(np.float32) + (1 - alpha) * np.float32(255) * texture
    return np.clip(out + 0.5, 0, 255).astype(np.uint8)


def label_grid(
    uv: np.ndarray,
    classes: np.ndarray,
    hidden: np.ndarray,
    shape: tuple[int, int],
    *,
    pos_radius: float = 4.0,
    neg_radius: float = 7.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Targets of the network's output grid for one frame.

    Args:
        uv: ``(m, 2)`` visible parts (pixels of the frame the network sees).
        classes: ``(m,)`` their part indices (:func:`pose.box.box_parts` order).
        hidden: ``(p, 2)`` parts inside the frame but not visible.
        shape: ``(gh, gw)`` of the grid (:func:`pose.corners.grid_centres`).
        pos_radius: a cell whose window centre is within this of a visible part is that
            part's (the nearest); with the stride of 4 every part has at least one cell.
        neg_radius: cells between ``pos_radius`` and this from a part (visible or hidden) are
            ignored; the rest is background.

    Returns:
        ``labels (gh, gw)`` int64 (-1 ignored, 0 background, ``k + 1`` part ``k``),
        ``offsets (2, gh, gw)`` float32, the nearest visible part minus the window centre in
        strides, for the cells within ``neg_radius`` of it (0 elsewhere; the neighbours of a
        peak vote for the part's position too, :meth:`pose.corners.CornerDetector.peaks`), and
        ``owner (gh, gw)`` int64, the index of that part (-1: no offset target).
    """
    centres = grid_centres(shape)
    labels = np.zeros(shape, np.int64)
    offsets = np.zeros((2, *shape), np.float32)
    owner = np.full(shape, -1, np.int64)
    everything = np.concatenate([np.reshape(uv, (-1, 2)), np.reshape(hidden, (-1, 2))])
    if len(everything):
        d_all = np.linalg.norm(centres[None] - everything[:, None, None], axis=3).min(0)
        labels[d_all <= neg_radius] = -1
    if len(uv):
        d = np.linalg.norm(centres[None] - np.asarray(uv)[:, None, None], axis=3)
        nearest = d.argmin(0)
        pos = d.min(0) <= pos_radius
        labels[pos] = np.asarray(classes)[nearest[pos]] + 1
        near = d.min(0) <= neg_radius
        off = (np.asarray(uv)[nearest] - centres) / STRIDE
        offsets[:, near] = off[near].T
        owner[near] = np.asarray(classes)[nearest[near]]
    return labels, offsets, owner


def random_homography(
    rng: np.random.Generator,
    shape: tuple[int, int],
    *,
    max_rotation_deg: float = 15.0,
    scale: tuple[float, float] = (0.8, 1.25),
    perspective: float = 0.06,
    max_shift: float = 0.1,
) -> np.ndarray:
    """A 3x3 homography about the frame's centre: rotation, scaling, the image corners moved by
    up to ``perspective`` of the frame's size, a shift of up to ``max_shift`` of it."""
    h, w = shape
    c = np.array([(w - 1) / 2, (h - 1) / 2])
    src = np.array([[0, 0], [w - 1, 0], [w - 1, h - 1], [0, h - 1]], np.float64)
    dst = src + rng.uniform(-perspective, perspective, (4, 2)) * [w, h]
    P = cv2.getPerspectiveTransform(src.astype(np.float32), dst.astype(np.float32))
    A = np.eye(3)
    A[:2] = cv2.getRotationMatrix2D(tuple(c), rng.uniform(-max_rotation_deg, max_rotation_deg), rng.uniform(*scale))
    A[:2, 2] += rng.uniform(-max_shift, max_shift, 2) * [w, h]
    return A @ P


def _project(points: np.ndarray, R: np.ndarray, t: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Pixels ``(n, 2)`` of ``points`` as in homogeneous coordinates (a point of the table's plane behind the camera
    too: the homographies between two views hold for it)."""
    return project_points(points, R, t, K)[0]


#: :func:`novel_view`'s viewpoints: their elevation (degrees above the plane of the box's bottom face) is kept in
#: ``NOVEL_ELEVATION_RANGE``; one is kept only when every face it sees is seen in the view at least
#: ``NOVEL_MIN_STRETCH`` as large (a face seen edge-on has no texture to give); ``NOVEL_TRIES`` are drawn at most.
NOVEL_ELEVATION_RANGE = (20.0, 70.0)
NOVEL_MIN_STRETCH = 0.35
NOVEL_TRIES = 8


def novel_view(
    image: np.ndarray,
    corners: np.ndarray,
    R: np.ndarray,
    t: np.ndarray,
    K: np.ndarray,
    rng: np.random.Generator,
    *,
    azimuth_deg: float = 8.0,
    elevation_deg: float = 20.0,
    distance: tuple[float, float],
    parts: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """The box of a registered view seen from a nearby viewpoint: each face of the box warped by
    its own plane's homography, the rest (the table) by the homography of the plane of the box's
    bottom face. Exact for a box and a table with Lambertian surfaces under the view's light (a
    face keeps its shading), as a homography of the whole frame is not.

    The camera turns about the box's centre by up to ``azimuth_deg`` about the box's z axis (up)
    and ``elevation_deg`` in elevation (kept within :data:`NOVEL_ELEVATION_RANGE` above the bottom face's
    plane), its distance scaled within ``distance`` ``(low, high)``. A viewpoint is kept only when every face it
    sees is seen in the view at least :data:`NOVEL_MIN_STRETCH` as large (a face seen edge-on has no
    texture to give); ``None`` after :data:`NOVEL_TRIES` refusals.

    Args:
        image: the view, uint8 ``(H, W)``.
        corners: ``(8, 3)`` box corners (:func:`pose.model.box_corners` order, z up).
        R, t: the view's object-to-camera pose; ``K``: its intrinsics.
        parts: ``(n, 3)`` points of the box's surface to project (:func:`pose.box.box_parts`; default the corners).

    Returns:
        ``(image, mask, uv, visible)``: the new view, the box's pixels in it (uint8, 255), the
        parts' pixels ``(n, 2)`` and which of them are visible (:func:`pose.box.part_visibility`).
    """
    from scipy.spatial.transform import Rotation  # here: scipy.spatial takes 0.2 s to import (every `alcn` start)

    corners = np.asarray(corners, np.float64)
    h, w = image.shape
    centre = corners.mean(0)
    eye = -R.T @ t - centre
    radius = np.linalg.norm(eye)
    elevation = np.degrees(np.arcsin(np.clip(eye[2] / radius, -1, 1)))
    seen = {
        quad: cv2.contourArea(_project(corners[list(quad)], R, t, K).astype(np.float32))
        for quad in facing_faces(corners, R, t)
    }
    for _ in range(NOVEL_TRIES):
        new_elevation = np.clip(elevation + rng.uniform(-elevation_deg, elevation_deg), *NOVEL_ELEVATION_RANGE)
        azimuth = np.arctan2(eye[1], eye[0]) + np.radians(rng.uniform(-azimuth_deg, azimuth_deg))
        e = np.radians(new_elevation)
        eye2 = (
            radius
            * rng.uniform(*distance)
            * np.array([np.cos(e) * np.cos(azimuth), np.cos(e) * np.sin(azimuth), np.sin(e)])
        )
        # the camera rig turned about the box's centre: the box stays where it was in the frame
        R2 = R @ Rotation.align_vectors(eye2, eye)[0].as_matrix().T  # the smallest rotation taking eye to eye2
        t2 = -R2 @ (eye2 + centre)
        faces = facing_faces(corners, R2, t2)
        areas = [cv2.contourArea(_project(corners[list(q)], R2, t2, K).astype(np.float32)) for q in faces]
        if all(q in seen and seen[q] >= NOVEL_MIN_STRETCH * a for q, a in zip(faces, areas)):
            break
    else:
        return None
    bottom = corners[corners[:, 2] <= corners[:, 2].min() + 1e-9]  # the table's plane: the bottom face's
    plane = bottom.mean(0) + 4 * (bottom[[0, 1, 3, 2]] - bottom.mean(0))
    H = cv2.getPerspectiveTransform(
        _project(plane, R, t, K).astype(np.float32), _project(plane, R2, t2, K).astype(np.float32)
    )
    out = cv2.warpPerspective(image, H, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT_101)
    mask = np.zeros((h, w), np.uint8)
    for quad in faces:
        src, dst = (_project(corners[list(quad)], *pose, K).astype(np.float32) for pose in ((R, t), (R2, t2)))
        face = cv2.warpPerspective(
            image,
            cv2.getPerspectiveTransform(src, dst),
            (w, h),
            flags=cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_REFLECT_101,
        )
        inside = cv2.fillConvexPoly(
            np.zeros((h, w), np.uint8), np.round(dst * 16).astype(np.int32), 255, cv2.LINE_AA, 4
        )
        out[inside > 0] = face[inside > 0]
        mask |= inside
    uv, visible = part_visibility(corners, R2, t2, K, (h, w), parts=parts)
    return out, mask, uv, visible


def _transform(H: np.ndarray, uv: np.ndarray) -> np.ndarray:
    return cv2.perspectiveTransform(np.asarray(uv, np.float64).reshape(-1, 1, 2), H).reshape(-1, 2)


def _intensity_noise(
    gray: np.ndarray, rng: np.random.Generator, scale: tuple[float, float], offset: float, noise: float
) -> np.ndarray:
    """``a I + b`` plus Gaussian noise on a uint8 frame (intensities in [0, 1])."""
    x = gray.astype(np.float32) / np.float32(255)
    x = rng.uniform(*scale) * x + rng.uniform(-offset, offset)
    x += rng.normal(0, rng.uniform(0, noise), x.shape).astype(np.float32)
    return np.clip(x * 255 + 0.5, 0, 255).astype(np.uint8)


@dataclass
class CornerFrames:
    """Training frames of the corner detector, normalized, padded and labelled.

    Attributes:
        images: ``(n, h + 2 PAD, w + 2 PAD)`` float32 normalized frames standardized by
            ``(x - input_mean) / input_std`` (constants over the frames) and padded
            (``BORDER_REFLECT_101``) as :meth:`pose.corners.CornerDetector.outputs` pads.
        labels: ``(n, gh, gw)`` int64 grid labels (:func:`label_grid`).
        offsets: ``(n, 2, gh, gw)`` float32 offset targets and ``owner`` ``(n, gh, gw)`` int64
            their parts (:func:`label_grid`).
        corners: per frame, ``(m, 3)`` visible parts: x, y (pixels of the downscaled frame), index.
        view: ``(n,)`` the training view each frame comes from.
    """

    images: np.ndarray
    labels: np.ndarray
    offsets: np.ndarray
    owner: np.ndarray
    corners: list[np.ndarray]
    view: np.ndarray
    input_mean: float
    input_std: float


def _view_frames(
    small: np.ndarray,
    small_mask: np.ndarray | None,
    uv: np.ndarray,
    visible: np.ndarray,
    norm: Normalization,
    rng: np.random.Generator,
    recipe: CornerRecipe,
    box: tuple[np.ndarray, ...] | None = None,
) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """One downscaled view ``small`` (uint8) and its ``recipe.copies`` augmented copies, each
    normalized by ``norm`` and labelled: ``(image, labels, offsets, owner, visible parts (m, 3))``
    per frame (``uv (n, 2)`` the parts in ``small``'s pixels; ``box``: ``(corners, R, t, K, parts)``
    of the view at ``small``'s scale, for :func:`novel_view`; without it no novel view)."""
    h, w = small.shape
    out = []
    for c in range(recipe.copies + 1):
        image, m, xy, vis = small, small_mask, uv, visible
        if c:
            view = (
                novel_view(small, *box[:4], rng, distance=tuple(recipe.novel_distance), parts=box[4])
                if box is not None and rng.random() < recipe.novel_views
                else None
            )
            if view is not None:
                image, m, xy, vis = view
            H = random_homography(rng, (h, w))
            image = cv2.warpPerspective(image, H, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT_101)
            xy = _transform(H, xy)
            if m is not None:
                m = cv2.warpPerspective(m, H, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
                if rng.random() < recipe.backgrounds:
                    image = replace_background(image, m, rng)
            image = _intensity_noise(image, rng, tuple(recipe.intensity_scale), recipe.intensity_offset, recipe.noise)
        inside = (xy[:, 0] >= 0) & (xy[:, 0] <= w - 1) & (xy[:, 1] >= 0) & (xy[:, 1] <= h - 1)
        shown = vis & inside
        normed = norm.normalize(image.astype(np.float32) / np.float32(255))
        lab, off, own = label_grid(
            xy[shown],
            np.flatnonzero(shown),
            xy[inside & ~vis],
            grid_shape(h, w),
            pos_radius=recipe.pos_radius,
            neg_radius=recipe.neg_radius,
        )
        out.append(
            (normed.astype(np.float32), lab, off, own, np.concatenate([xy[shown], np.flatnonzero(shown)[:, None]], 1))
        )
    return out


def _stack_frames(per_view: list[list[tuple[np.ndarray, ...]]]) -> CornerFrames:
    """:class:`CornerFrames` of the frames of :func:`_view_frames` per view, standardized by one
    fixed affine map for every input (the normalizations' output ranges differ widely), from the
    views themselves (each list's first frame)."""
    if not any((f[1] > 0).any() for frames in per_view for f in frames):
        raise InputError("no part of the box is visible in any training image")
    originals = [frames[0][0] for frames in per_view]
    mean = float(np.mean([im.mean() for im in originals]))
    std = float(np.sqrt(np.mean([im.var() for im in originals]))) + 1e-6
    flat = [(v, f) for v, frames in enumerate(per_view) for f in frames]
    padded = np.stack(
        [cv2.copyMakeBorder((f[0] - mean) / std, PAD, PAD, PAD, PAD, cv2.BORDER_REFLECT_101) for _, f in flat]
    ).astype(np.float32)
    return CornerFrames(
        padded,
        np.stack([f[1] for _, f in flat]),
        np.stack([f[2] for _, f in flat]),
        np.stack([f[3] for _, f in flat]),
        [f[4] for _, f in flat],
        np.array([v for v, _ in flat]),
        mean,
        std,
    )


def build_frames(
    sequence: TrainingSequence, corners: np.ndarray, normalization: str, recipe: CornerRecipe, *, seed: int = 0
) -> CornerFrames:
    """The labelled training frames of a registered sequence (:func:`pose.sequence.load_sequence`):
    each view downscaled by ``recipe.scale`` and its ``recipe.copies`` augmented copies (the keys of
    :class:`pose.corner_train.CornerRecipe`), normalized by the spec ``normalization``.

    Args:
        sequence: a :class:`pose.sequence.TrainingSequence` with poses (world = object frame).
        corners: ``(8, 3)`` box corners in the object frame (:func:`pose.model.box_corners` order).
        normalization: a spec for :func:`pose.corners.normalization_for`.
        recipe: the frames' keys of the recipe.
        seed: random seed.

    Raises:
        InputError: an unregistered sequence, a view with lens distortion (its parts would be placed by a pinhole
            projection, and its novel views warped by homographies), or no visible part in any view.
    """
    from alcn_cv import io

    if not sequence.registered:
        raise InputError("the training sequence must be registered (a pose for every image)")
    distorted = next((v.name for v in sequence.views if v.dist is not None and np.any(v.dist)), None)
    if distorted is not None:
        raise InputError(
            f"{sequence.info.get('path', sequence.image_dir)}: view {distorted} has lens distortion, which the corner "
            "detector does not model; undistort the sequence first (`alcn calib undistort --keep-K`)"
        )
    recipe.check()
    scale = recipe.scale
    norm = normalization_for(normalization)
    rng = np.random.default_rng(seed)
    mask_dir = sequence.image_dir.parent / "mask_visib"
    parts = box_parts(corners, recipe.divisions)
    per_view = []
    for view in sequence.views:
        gray = to_gray(io.read_image(sequence.image_dir / view.name))
        mask = _read_mask(view.mask or mask_dir / f"{Path(view.name).stem}_000000.png", gray.shape)
        uv, vis = part_visibility(corners, view.R_w2c, view.t_w2c, view.K, gray.shape, mask, parts=parts)
        small = downscale(gray, scale)
        K = scaled_camera(view.K, scale)  # of the downscaled frame
        per_view.append(
            _view_frames(
                small,
                None if mask is None else downscale(mask, scale),
                to_scaled(uv, scale),
                vis,
                norm,
                rng,
                recipe,
                box=(corners, view.R_w2c, view.t_w2c, K, parts),
            )
        )
    frames = _stack_frames(per_view)
    logger.info(
        "corner frames: %d (%d views x %d), %d parts, %d part cells",
        len(frames.labels),
        len(sequence.views),
        recipe.copies + 1,
        len(parts),
        int((frames.labels > 0).sum()),
    )
    return frames


def build_image_frames(
    gray: np.ndarray, uv: np.ndarray, normalization: str, recipe: CornerRecipe, *, seed: int = 0
) -> CornerFrames:
    """The labelled training frames of one image whose parts are at ``uv (n, 2)`` (pixels of
    ``gray``, uint8): the image and ``recipe.copies`` copies of it, as :func:`build_frames` makes of
    each view of a sequence without novel views nor new backgrounds (the parts' surroundings are
    the target's).

    Raises:
        InputError: ``uv`` is not ``(n, 2)`` or no part is inside the image.
    """
    uv = np.asarray(uv, np.float64)
    if uv.ndim != 2 or uv.shape[1] != 2 or not len(uv) or not np.isfinite(uv).all():
        raise InputError(f"need the parts' pixels as a finite (n, 2) array, got {uv.shape}")
    recipe.check()
    frames = _stack_frames(
        [
            _view_frames(
                downscale(gray, recipe.scale),
                None,
                to_scaled(uv, recipe.scale),
                np.ones(len(uv), bool),
                normalization_for(normalization),
                np.random.default_rng(seed),
                recipe,
            )
        ]
    )
    logger.info(
        "corner frames: %d (1 image x %d), %d part cells",
        len(frames.labels),
        recipe.copies + 1,
        int((frames.labels > 0).sum()),
    )
    return frames
