"""Reading and writing images and videos with OpenCV, with errors that name the file."""

from __future__ import annotations

import logging
import os
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np

from alcn_cv.errors import InputError

__all__ = ["IMAGE_SUFFIXES", "VIDEO_SUFFIXES", "VideoReader", "is_video", "list_images", "read_image", "write_image", "open_video_writer"]

logger = logging.getLogger(__name__)

IMAGE_SUFFIXES = frozenset({".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp", ".pgm", ".ppm", ".pnm"})
VIDEO_SUFFIXES = frozenset({".mp4", ".avi", ".mov", ".mkv", ".m4v", ".webm", ".mpg", ".mpeg", ".wmv"})
_FOURCC = {".avi": "MJPG", ".mkv": "MJPG"}  # everything else: mp4v


def is_video(path: str | Path) -> bool:
    return Path(path).suffix.lower() in VIDEO_SUFFIXES


def list_images(folder: str | Path) -> list[Path]:
    """Image files directly inside ``folder``, sorted by name."""
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"not a folder: {folder}")
    return sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file())


def read_image(path: str | Path) -> np.ndarray:
    """Read an image as OpenCV does, keeping 16-bit depth; an alpha channel is dropped.

    Returns:
        ``HxW`` grayscale or ``HxWx3`` BGR, uint8 or uint16.

    Raises:
        InputError: the file is missing, unreadable or corrupt.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"image not found: {path}")
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None or img.size == 0:
        raise InputError(f"cannot read image {path}: corrupt or unsupported format")
    if img.ndim == 3 and img.shape[2] == 4:
        logger.debug("dropping the alpha channel of %s", path)
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2BGR)
    if img.dtype not in (np.uint8, np.uint16):
        raise InputError(f"{path}: unsupported pixel type {img.dtype} (8- or 16-bit images only)")
    return img


def write_image(path: str | Path, img: np.ndarray) -> Path:
    """Write an image atomically (temporary name, then rename), creating the folder."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.tmp{path.suffix}")
    if not cv2.imwrite(str(tmp), img):
        tmp.unlink(missing_ok=True)
        raise OSError(f"cannot write image {path} (unsupported extension or folder not writable)")
    os.replace(tmp, path)
    return path


class VideoReader:
    """Frames of a video file, as an iterator of BGR uint8 arrays.

    Example:
        >>> with VideoReader("box.mp4") as video:  # doctest: +SKIP
        ...     for frame in video: ...
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise InputError(f"video not found: {self.path}")
        self._cap = cv2.VideoCapture(str(self.path))
        if not self._cap.isOpened():
            raise InputError(f"cannot open video {self.path}: corrupt or unsupported format")
        self.fps = self._cap.get(cv2.CAP_PROP_FPS) or 30.0
        self.frame_count = int(self._cap.get(cv2.CAP_PROP_FRAME_COUNT))
        self.size = (int(self._cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(self._cap.get(cv2.CAP_PROP_FRAME_HEIGHT)))

    def __iter__(self) -> Iterator[np.ndarray]:
        while True:
            ok, frame = self._cap.read()
            if not ok:
                return
            yield frame

    def __len__(self) -> int:
        return self.frame_count

    def close(self) -> None:
        self._cap.release()

    def __enter__(self) -> VideoReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def open_video_writer(path: str | Path, fps: float, size: tuple[int, int], color: bool = True) -> cv2.VideoWriter:
    """A ``cv2.VideoWriter`` for ``path`` (codec from the extension: MJPG for .avi/.mkv, else mp4v)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fourcc = cv2.VideoWriter_fourcc(*_FOURCC.get(path.suffix.lower(), "mp4v"))
    writer = cv2.VideoWriter(str(path), fourcc, fps, size, color)
    if not writer.isOpened():
        raise OSError(f"cannot write video {path} (unsupported extension or codec)")
    return writer
