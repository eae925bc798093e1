"""Reading and writing images and videos with OpenCV, with errors that name the file."""

from __future__ import annotations

import logging
import os
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from alcn_cv.errors import InputError

__all__ = ["IMAGE_SUFFIXES", "atomic_write", "map_video", "to_gray", "VIDEO_SUFFIXES", "VideoReader", "is_video", "list_images", "read_image", "write_image", "open_video_writer"]

logger = logging.getLogger(__name__)

IMAGE_SUFFIXES = frozenset({".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp", ".pgm", ".ppm", ".pnm"})
VIDEO_SUFFIXES = frozenset({".mp4", ".avi", ".mov", ".mkv", ".m4v", ".webm", ".mpg", ".mpeg", ".wmv"})
_FOURCC = {".avi": "MJPG", ".mkv": "MJPG"}  # everything else: mp4v
_UMASK = os.umask(0)
os.umask(_UMASK)


def is_video(path: str | Path) -> bool:
    return Path(path).suffix.lower() in VIDEO_SUFFIXES


def list_images(folder: str | Path) -> list[Path]:
    """Image files directly inside ``folder``, sorted by name.

    Raises:
        InputError: ``folder`` is not a folder or holds no image.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"not a folder: {folder}")
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file())
    if not files:
        raise InputError(f"{folder}: no images ({', '.join(sorted(IMAGE_SUFFIXES))}) in this folder")
    return files


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


def atomic_write(path: str | os.PathLike, data: bytes | str) -> Path:
    """Write ``data`` (text as UTF-8) to ``path`` through a temporary file in the same folder,
    then rename it, so that a reader never sees a half-written file."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data.encode("utf-8") if isinstance(data, str) else data)
        os.chmod(tmp, 0o666 & ~_UMASK)  # mkstemp makes 0600 files; give the usual permissions
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def to_gray(image: np.ndarray) -> np.ndarray:
    """A uint8 ``HxW`` grayscale image from a gray or BGR uint8 one (the gray input itself, not a copy)."""
    if not isinstance(image, np.ndarray) or image.size == 0:
        raise InputError("image must be a non-empty numpy array")
    if image.dtype != np.uint8:
        raise InputError(f"image must be uint8, got {image.dtype}")
    if image.ndim == 2:
        return image
    if image.ndim == 3 and image.shape[2] == 3:
        return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    raise InputError(f"image must be HxW or HxWx3, got shape {image.shape}")


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


def map_video(src: str | Path, dst: str | Path, fn: Callable[[np.ndarray], np.ndarray], desc: str | None = None) -> int:
    """Write ``fn(frame)`` for every frame of the video ``src`` into the video ``dst``.

    The output is written under a temporary name and renamed when complete; its frame size and
    colour follow ``fn``'s first output, its frame rate the input's. A progress bar shows the
    frames.

    Returns:
        The number of frames written.

    Raises:
        InputError: ``src`` cannot be opened or holds no decodable frame.
    """
    src, dst = Path(src), Path(dst)
    tmp = dst.with_name(f".{dst.stem}.tmp{dst.suffix}")
    writer = None
    count = 0
    try:
        with VideoReader(src) as video:
            for frame in tqdm(video, total=len(video) or None, desc=desc or src.name, unit="frame"):
                out = fn(frame)
                if writer is None:
                    writer = open_video_writer(tmp, video.fps, (out.shape[1], out.shape[0]), color=out.ndim == 3)
                writer.write(out)
                count += 1
    except BaseException:
        if writer is not None:
            writer.release()
        tmp.unlink(missing_ok=True)
        raise
    if writer is None:
        raise InputError(f"no frame could be decoded from {src}")
    writer.release()
    os.replace(tmp, dst)
    return count
