"""Features, matches and 3D points of a training sequence (hloc-style: OpenCV features imported
into a COLMAP database, pycolmap for the geometry).

1. :func:`extract_features`: OpenCV keypoints/descriptors (ORB, SIFT, AKAZE) on the *normalized*
   training images (the same normalization and feature as at tracking time), optionally inside
   a mask.
2. :func:`write_database`: keypoints in COLMAP's pixel convention (top-left pixel centre at
   (0.5, 0.5)), brute force + Lowe's ratio test on every pair (or the ``window`` nearest frames of
   a video), then pycolmap's two-view geometric verification (``pycolmap.verify_matches``).
3. :func:`triangulate_fixed_poses` (registered sequence: the bundle adjustment refines the
   points only) or :func:`reconstruct_incremental` (unregistered video: unknown scale).
4. :func:`collect_points`: each 3D point seen in at least :data:`MIN_TRACK` images keeps up to
   :data:`DESCRIPTORS_PER_POINT` of its track's descriptors (:func:`representatives`).

pycolmap's own log (glog, hundreds of lines per build) goes to this module's logger at debug
level (:func:`calib.colmap_log.pycolmap_log`): ``alcn --verbose`` shows it.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np
from tqdm import tqdm

from alcn_cv import io
from alcn_cv.enhance.registry import from_spec
from alcn_cv.errors import DatasetError
from alcn_cv.io import make_folder, to_gray
from calib.colmap_log import pycolmap_log
from pose.parts import create_feature, match_descriptors
from pose.sequence import TrainingSequence

if TYPE_CHECKING:
    import pycolmap

logger = logging.getLogger(__name__)

#: Seed of pycolmap's RANSAC (verification) and mapping, so that a model builds the same every time.
RANDOM_SEED = 0
#: :func:`collect_points` keeps the 3D points seen in at least this many training images.
MIN_TRACK = 2
#: :func:`collect_points` keeps up to this many descriptors of each 3D point's track (:func:`representatives`): a
#: view unlike the typical one still finds a close descriptor.
DESCRIPTORS_PER_POINT = 8


@dataclass
class Features:
    """The features of one training image (:func:`extract_features`).

    Attributes:
        keypoints: ``(N, 2)`` float32 pixels, OpenCV pixel convention.
        descriptors: ``(N, D)`` uint8 (binary: ORB, AKAZE) or float32 (SIFT).
        colors: ``(N, 3)`` uint8 RGB of the image at each keypoint.
    """

    keypoints: np.ndarray
    descriptors: np.ndarray
    colors: np.ndarray


def extract_features(
    seq: TrainingSequence,
    feature: str = "ORB",
    n_features: int = 4000,
    normalization: str = "none",
    masks: dict[str, np.ndarray] | None = None,
    progress: bool = True,
) -> dict[str, Features]:
    """Features of every view of ``seq`` on its normalized grayscale image (``progress``: a progress bar)."""
    det = create_feature(feature, n_features)
    norm = from_spec(normalization)
    out = {}
    for v in tqdm(seq.views, desc="features", unit="img", leave=False, disable=not progress):
        img = io.read_image(seq.image_dir / v.name)
        if img.dtype != np.uint8:
            img = (img >> 8).astype(np.uint8)
        bgr = img if img.ndim == 3 else cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
        kps, desc = det.detectAndCompute(norm.apply(to_gray(bgr)), None if masks is None else masks.get(v.name))
        pts = np.array([k.pt for k in kps], np.float32).reshape(-1, 2)
        if desc is None:
            desc = np.zeros((0, det.descriptorSize()), np.uint8 if det.descriptorType() == cv2.CV_8U else np.float32)
        ij = np.clip(np.round(pts).astype(int), 0, [bgr.shape[1] - 1, bgr.shape[0] - 1])
        out[v.name] = Features(pts, desc, bgr[ij[:, 1], ij[:, 0], ::-1].copy())
    logger.info("%s: %.0f keypoints per image on average", feature, np.mean([len(f.keypoints) for f in out.values()]))
    return out


def image_pairs(n: int, window: int | None = None) -> list[tuple[int, int]]:
    """All pairs ``i < j`` of ``n`` images, or only those with ``j - i <= window``."""
    return [(i, j) for i in range(n) for j in range(i + 1, n) if window is None or j - i <= window]


def write_database(
    db_path: Path,
    seq: TrainingSequence,
    feats: dict[str, Features],
    pairs: list[tuple[int, int]],
    norm: int,
    ratio: float = 0.8,
    progress: bool = True,
) -> Path:
    """Create the COLMAP database: cameras (known intrinsics), images, keypoints, raw matches;
    writes the pairs file and runs pycolmap's geometric verification (``progress``: a progress bar over
    the pairs). Returns the pairs file."""
    with pycolmap_log(logger):
        return _write_database(db_path, seq, feats, pairs, norm, ratio, progress)


def _write_database(
    db_path: Path,
    seq: TrainingSequence,
    feats: dict[str, Features],
    pairs: list[tuple[int, int]],
    norm: int,
    ratio: float,
    progress: bool,
) -> Path:
    import pycolmap

    from alcn_cv.formats.colmap import camera_from_opencv, points_opencv_to_colmap

    pycolmap.Database.open(db_path).close()
    same = all(np.array_equal(v.K, seq.views[0].K) for v in seq.views) and seq.info.get("format") == "video"
    mode = pycolmap.CameraMode.SINGLE if same else pycolmap.CameraMode.PER_IMAGE
    pycolmap.import_images(db_path, seq.image_dir, mode, image_names=[v.name for v in seq.views])
    db = pycolmap.Database.open(db_path)
    try:
        ids = {im.name: im for im in db.read_all_images()}
        for v in seq.views:
            im = ids[v.name]
            cam = db.read_camera(im.camera_id)
            cc = camera_from_opencv(v.K, v.dist, cam.width, cam.height, im.camera_id)
            cam.model, cam.params = cc.model, cc.params
            db.update_camera(cam)
            db.write_keypoints(im.image_id, points_opencv_to_colmap(feats[v.name].keypoints).astype(np.float32))
        lines = []
        for i, j in tqdm(pairs, desc="match", unit="pair", leave=False, disable=not progress):
            a, b = seq.views[i].name, seq.views[j].name
            m = match_descriptors(feats[a].descriptors, feats[b].descriptors, norm, ratio)
            db.write_matches(ids[a].image_id, ids[b].image_id, m.astype(np.uint32))
            lines.append(f"{a} {b}")
    finally:
        db.close()
    pairs_path = db_path.with_name("pairs.txt")
    pairs_path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    opts = pycolmap.TwoViewGeometryOptions()
    opts.filter_stationary_matches = True  # a static background seen by a static camera
    opts.ransac.random_seed = RANDOM_SEED
    pycolmap.verify_matches(db_path, pairs_path, opts)
    return pairs_path


def triangulate_fixed_poses(seq: TrainingSequence, db_path: Path, out_dir: Path) -> pycolmap.Reconstruction:
    """Triangulate with the known poses held fixed; returns a ``pycolmap.Reconstruction``."""
    import pycolmap

    db = pycolmap.Database.open(db_path)
    try:
        rec = pycolmap.Reconstruction()
        for im in db.read_all_images():
            v = next(v for v in seq.views if v.name == im.name)
            rec.add_camera_with_trivial_rig(db.read_camera(im.camera_id))
            pose = pycolmap.Rigid3d(np.hstack([v.R_w2c, np.reshape(v.t_w2c, (3, 1))]))
            rec.add_image_with_trivial_frame(
                pycolmap.Image(name=im.name, camera_id=im.camera_id, image_id=im.image_id), pose
            )
    finally:
        db.close()
    make_folder(out_dir)
    opts = pycolmap.IncrementalPipelineOptions()
    opts.min_num_matches = 8
    opts.random_seed = RANDOM_SEED
    with pycolmap_log(logger):
        return pycolmap.triangulate_points(rec, db_path, seq.image_dir, out_dir, options=opts)


def reconstruct_incremental(
    seq: TrainingSequence, db_path: Path, out_dir: Path, refine_focal: bool = False, progress: bool = True
) -> pycolmap.Reconstruction:
    """pycolmap incremental mapping; returns the largest reconstruction (unknown scale).

    The intrinsics are held fixed, except the focal length with ``refine_focal`` (self-calibration
    in the bundle adjustment, for a video whose focal length is only roughly known). ``progress``: a bar of the
    images registered (the mapper's own callbacks)."""
    import pycolmap

    opts = pycolmap.IncrementalPipelineOptions()
    opts.ba_refine_focal_length = refine_focal
    opts.ba_refine_principal_point = False
    opts.ba_refine_extra_params = False
    opts.min_num_matches = 12
    opts.random_seed = RANDOM_SEED
    # one thread: COLMAP's mapper is reproducible only single-threaded (Ceres sums in thread order);
    # with two, the cookie-box video gave 5961 or 5940 points from one run to the next
    opts.num_threads = 1
    make_folder(out_dir)
    logger.info("incremental mapping of %d images (pycolmap, one thread)", len(seq.views))
    bar = tqdm(total=len(seq.views), desc="register images", unit="image", leave=False, disable=not progress)

    def registered(count: int) -> None:  # a mapper that starts a second model registers images again: capped
        bar.update(min(count, bar.total - bar.n))

    with bar, pycolmap_log(logger):
        recs = pycolmap.incremental_mapping(
            db_path,
            seq.image_dir,
            out_dir,
            opts,
            initial_image_pair_callback=lambda: registered(2),
            next_image_callback=lambda: registered(1),
        )
    if not recs:
        raise DatasetError(
            f"{seq.info.get('path')}: pycolmap registered no image pair (too little texture, motion or overlap)"
        )
    rec = max(recs.values(), key=lambda r: r.num_reg_images())
    logger.info(
        "incremental mapping: %d of %d images registered, %d points",
        rec.num_reg_images(),
        len(seq.views),
        rec.num_points3D(),
    )
    return rec


def representatives(desc: np.ndarray, norm: int, k: int) -> np.ndarray:
    """Indices of at most ``k`` descriptors that represent one track ``(T, D)``: its medoid (the
    one closest to all others), then, greedily, the one farthest from those already chosen
    (farthest-point sampling), so that the views that differ most (another viewing angle, the
    face more foreshortened) keep a descriptor of their own."""
    if len(desc) == 1:
        return np.zeros(1, np.int64)
    from scipy.spatial.distance import cdist

    if norm == cv2.NORM_HAMMING:
        bits = np.unpackbits(desc, axis=1)
        d = cdist(bits, bits, "hamming")
    else:
        d = cdist(desc.astype(np.float64), desc.astype(np.float64))
    chosen = [int(np.argmin(d.sum(1)))]
    gap = d[chosen[0]].copy()
    while len(chosen) < min(k, len(desc)) and gap.max() > 0:
        chosen.append(int(np.argmax(gap)))
        gap = np.minimum(gap, d[chosen[-1]])
    return np.array(chosen, np.int64)


def collect_points(
    rec: pycolmap.Reconstruction,
    feats: dict[str, Features],
    norm: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """3D points ``(N, 3)`` (those seen in at least :data:`MIN_TRACK` images), descriptors ``(M, D)`` with the
    point each describes ``(M,)`` (up to :data:`DESCRIPTORS_PER_POINT` per point, chosen by
    :func:`representatives`), track lengths ``(N,)`` and RGB colours ``(N, 3)`` of a reconstruction whose keypoints
    are those of ``feats``."""
    names = {iid: im.name for iid, im in rec.images.items()}
    xyz, desc, owner, tl, rgb = [], [], [], [], []
    for p in rec.points3D.values():
        els = p.track.elements
        if len(els) < MIN_TRACK:
            continue
        d = np.stack([feats[names[e.image_id]].descriptors[e.point2D_idx] for e in els])
        c = np.stack([feats[names[e.image_id]].colors[e.point2D_idx] for e in els])
        chosen = representatives(d, norm, DESCRIPTORS_PER_POINT)
        desc.append(d[chosen])
        owner.append(np.full(len(chosen), len(xyz), np.int32))
        xyz.append(p.xyz)
        tl.append(len(els))
        rgb.append(np.median(c, 0))
    if not xyz:
        raise DatasetError(
            "no 3D point was triangulated (too little texture or overlap between the training images, or wrong poses)"
        )
    return (np.array(xyz), np.concatenate(desc), np.concatenate(owner), np.array(tl, np.int32), np.array(rgb, np.uint8))
