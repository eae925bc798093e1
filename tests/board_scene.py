"""Images of a ChArUco board lying in a cluttered scene, under known camera poses.

Used to test camera calibration and the registration of training sequences (``calib``):
every image is an exact pinhole projection ``x = K [R | t] X`` (OpenCV pixel convention,
top-left pixel centre at (0, 0)) of the plane z = 0 of the board frame (mm, x right and y
down along the printed board, as ``cv2.aruco.CharucoBoard``), optionally followed by lens
distortion. The plane holds the board (``CharucoBoard.generateImage``, on white paper) on a
table covered with textures and photographs from :mod:`alcn_cv.data.textures`.

The plane is warped by the homography ``H = K [r1 r2 t] A`` where ``A`` maps texture pixels to
plane millimetres, rendered ``supersample`` times larger and reduced with pixel-area
averaging (so the board is anti-aliased), then lit by a smooth gain field with a colour tint,
gamma-encoded, and given Gaussian sensor noise. Deterministic for a seed.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import cv2
import numpy as np

from alcn_cv.data.textures import random_texture

logger = logging.getLogger(__name__)

__all__ = ["BoardScene", "look_at", "sample_board_poses", "render_board_views", "make_board_scene"]


@dataclass
class BoardScene:
    """Rendered views and their ground truth.

    Attributes:
        images: list of BGR uint8 (H, W, 3) images.
        K: float64 (3, 3) intrinsics (OpenCV convention).
        dist: float64 (5,) OpenCV distortion applied to the images (zeros: none).
        R_w2c: float64 (N, 3, 3) rotations board -> camera.
        t_w2c: float64 (N, 3) translations board -> camera, mm.
        board_size_mm: (width, height) of the checkered area.
    """

    images: list[np.ndarray]
    K: np.ndarray
    dist: np.ndarray
    R_w2c: np.ndarray
    t_w2c: np.ndarray
    board_size_mm: tuple[float, float]


def look_at(center: np.ndarray, target: np.ndarray, right_hint: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World-to-camera pose of a camera at ``center`` looking at ``target``.

    The camera's x axis is ``right_hint`` made orthogonal to the viewing direction; y = z x x
    (OpenCV: x right, y down, z forward). Returns ``(R_w2c (3, 3), t_w2c (3,))``.
    """
    z = np.asarray(target, float) - np.asarray(center, float)
    z /= np.linalg.norm(z)
    x = np.asarray(right_hint, float) - np.dot(right_hint, z) * z
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    return R, -R @ np.asarray(center, float)


def sample_board_poses(
    n: int,
    board_size_mm: tuple[float, float],
    rng: np.random.Generator,
    distance_mm: tuple[float, float] = (380.0, 600.0),
    tilt_deg: tuple[float, float] = (10.0, 50.0),
    roll_deg: float = 35.0,
    target_jitter: float = 0.15,
) -> tuple[np.ndarray, np.ndarray]:
    """Random camera poses viewing the printed (z < 0) side of a board.

    Args:
        n: number of poses.
        board_size_mm: (width, height) of the board; the camera aims near its centre.
        rng: random generator.
        distance_mm: range of distances from the aimed point.
        tilt_deg: range of angles between the viewing direction and the board normal.
        roll_deg: largest rotation about the viewing direction away from board-x-right.
        target_jitter: the aimed point moves by up to this fraction of the board size.

    Returns:
        ``R_w2c (n, 3, 3)``, ``t_w2c (n, 3)`` (mm).
    """
    w, h = board_size_mm
    Rs, ts = [], []
    for _ in range(n):
        target = np.array(
            [w / 2 + rng.uniform(-1, 1) * target_jitter * w, h / 2 + rng.uniform(-1, 1) * target_jitter * h, 0.0]
        )
        tilt = np.deg2rad(rng.uniform(*tilt_deg))
        azimuth = rng.uniform(0, 2 * np.pi)
        direction = np.array([np.sin(tilt) * np.cos(azimuth), np.sin(tilt) * np.sin(azimuth), -np.cos(tilt)])
        center = target + rng.uniform(*distance_mm) * direction
        roll = np.deg2rad(rng.uniform(-roll_deg, roll_deg))
        R, t = look_at(center, target, np.array([np.cos(roll), np.sin(roll), 0.0]))
        Rs.append(R)
        ts.append(t)
    return np.array(Rs), np.array(ts)


def _plane_texture(
    board_image: np.ndarray,
    px_per_mm: float,
    board_size_mm: tuple[float, float],
    rng: np.random.Generator,
    paper_mm: float,
    table_mm: float,
) -> tuple[np.ndarray, np.ndarray]:
    """BGR uint8 texture of the table with the board on white paper, and the 3x3 matrix A
    mapping texture pixel (u, v, 1) to plane millimetres (X, Y, 1)."""
    bh, bw = board_image.shape[:2]
    pad = int(round(table_mm * px_per_mm))
    H, W = bh + 2 * pad, bw + 2 * pad
    # Table: a textured background, upsampled (it needs no fine detail), plus objects.
    small = random_texture(rng, (256, int(256 * W / H)))
    table = cv2.resize(small, (W, H), interpolation=cv2.INTER_LINEAR)
    for _ in range(int(rng.integers(6, 12))):
        side = int(rng.uniform(0.15, 0.35) * min(H, W))
        patch = random_texture(rng, (side, int(side * rng.uniform(0.6, 1.6))))
        ph, pw = patch.shape[:2]
        y0 = int(rng.integers(0, H - ph))
        x0 = int(rng.integers(0, W - pw))
        table[y0 : y0 + ph, x0 : x0 + pw] = patch
    texture = (np.clip(table, 0, 1) ** (1 / 2.2) * 255).astype(np.uint8)[..., ::-1].copy()  # linear RGB -> BGR
    paper = int(round(paper_mm * px_per_mm))
    texture[pad - paper : pad + bh + paper, pad - paper : pad + bw + paper] = 245
    texture[pad : pad + bh, pad : pad + bw] = board_image[..., None]
    s = 1.0 / px_per_mm
    # Texture pixel u has its centre at plane x = (u - pad + 0.5) * s.
    A = np.array([[s, 0, (0.5 - pad) * s], [0, s, (0.5 - pad) * s], [0, 0, 1.0]])
    return texture, A


def _lighting(rng: np.random.Generator, shape: tuple[int, int]) -> np.ndarray:
    """A smooth gain field (H, W, 3) in about [0.55, 1.25]: gradient, soft spot, colour tint."""
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    xx, yy = xx / w - 0.5, yy / h - 0.5
    gain = rng.uniform(0.8, 1.05) + rng.uniform(-0.25, 0.25) * xx + rng.uniform(-0.25, 0.25) * yy
    cx, cy, r = rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), rng.uniform(0.2, 0.5)
    gain = gain + rng.uniform(0.0, 0.2) * np.exp(-((xx - cx) ** 2 + (yy - cy) ** 2) / (2 * r * r))
    tint = 1.0 + rng.uniform(-0.06, 0.06, 3)
    return np.clip(gain, 0.55, 1.25)[..., None] * tint.astype(np.float32)


def render_board_views(
    board: cv2.aruco.CharucoBoard,
    K: np.ndarray,
    R_w2c: np.ndarray,
    t_w2c: np.ndarray,
    image_size: tuple[int, int],
    rng: np.random.Generator,
    dist: np.ndarray | None = None,
    px_per_mm: float = 4.0,
    supersample: int = 3,
    noise_sigma: float = 2.0,
    lighting: bool = True,
) -> list[np.ndarray]:
    """Render the board (on a cluttered table) seen by each camera.

    Args:
        board: the ChArUco board; its square length is in mm.
        K: (3, 3) intrinsics, OpenCV convention.
        R_w2c, t_w2c: (N, 3, 3) and (N, 3) poses, board frame -> camera, mm.
        image_size: (width, height).
        rng: random generator (clutter, lighting, noise).
        dist: OpenCV distortion to apply, or None.
        px_per_mm: resolution of the board texture.
        supersample: rendering scale before pixel-area reduction.
        noise_sigma: std of the Gaussian sensor noise, grey levels.
        lighting: apply the random smooth lighting and gamma.

    Returns:
        BGR uint8 images (H, W, 3).
    """
    cols, rows = board.getChessboardSize()
    square = float(board.getSquareLength())
    size_mm = (cols * square, rows * square)
    square_px = int(round(square * px_per_mm))
    px_per_mm = square_px / square  # exact integer squares in the texture
    board_image = board.generateImage((cols * square_px, rows * square_px), marginSize=0, borderBits=1)
    texture, A = _plane_texture(
        board_image, px_per_mm, size_mm, rng, paper_mm=0.3 * square, table_mm=1.0 * max(size_mm)
    )
    w, h = image_size
    f = int(supersample)
    # Pixel centre p of the f-times larger image and p' of the output: p = f p' + (f - 1) / 2.
    S = np.array([[f, 0, (f - 1) / 2], [0, f, (f - 1) / 2], [0, 0, 1.0]])
    K = np.asarray(K, float)
    images = []
    for R, t in zip(np.asarray(R_w2c, float), np.asarray(t_w2c, float)):
        Hm = S @ K @ np.c_[R[:, :2], t] @ A
        big = cv2.warpPerspective(
            texture,
            Hm,
            (w * f, h * f),
            flags=cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_CONSTANT,
            borderValue=(40, 40, 40),
        )
        img = cv2.resize(big, (w, h), interpolation=cv2.INTER_AREA).astype(np.float32) / 255.0
        if dist is not None and np.any(dist):
            # For each distorted output pixel, the undistorted pixel it comes from.
            grid = np.stack(np.meshgrid(np.arange(w), np.arange(h)), -1).reshape(-1, 1, 2).astype(np.float64)
            und = cv2.undistortPoints(
                grid,
                K,
                np.asarray(dist, float),
                None,
                None,
                K,
                (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-9),
            )
            maps = und.reshape(h, w, 2).astype(np.float32)
            img = cv2.remap(img, maps[..., 0], maps[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        if lighting:
            img = (img**2.2) * _lighting(rng, (h, w))  # light acts on linear values
            img = np.clip(img, 0, 1) ** (1 / rng.uniform(1.9, 2.5))
        img = img * 255.0 + rng.normal(0, noise_sigma, img.shape)
        images.append(np.clip(np.rint(img), 0, 255).astype(np.uint8))
    return images


def make_board_scene(
    n_views: int = 12,
    image_size: tuple[int, int] = (640, 480),
    focal: float = 600.0,
    cols: int = 7,
    rows: int = 5,
    square_mm: float = 35.0,
    marker_mm: float = 26.0,
    dictionary: str = "DICT_5X5_100",
    dist: np.ndarray | None = None,
    seed: int = 0,
    **render_kwargs,
) -> BoardScene:
    """Render ``n_views`` random views of a ChArUco board (default: the 7x5, 35 mm board
    that ``alcn calib board`` prints) with a camera of focal length ``focal`` px and
    principal point slightly off centre. Extra keyword arguments go to
    :func:`render_board_views`."""
    rng = np.random.default_rng(seed)
    w, h = image_size
    K = np.array([[focal, 0, w / 2 - 3.7], [0, focal * 1.002, h / 2 + 2.4], [0, 0, 1.0]])
    board = cv2.aruco.CharucoBoard(
        (cols, rows), square_mm, marker_mm, cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary))
    )
    size_mm = (cols * square_mm, rows * square_mm)
    scale = focal / 600.0 * 640.0 / w  # keep the board's apparent size for other cameras
    R, t = sample_board_poses(n_views, size_mm, rng, distance_mm=(380.0 * scale, 600.0 * scale))
    images = render_board_views(board, K, R, t, image_size, rng, dist=dist, **render_kwargs)
    return BoardScene(images, K, np.zeros(5) if dist is None else np.asarray(dist, float), R, t, size_mm)
