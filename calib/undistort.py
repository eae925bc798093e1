"""Undistortion of images, folders of images and videos with a calibration.

The output camera is the pinhole ``new_K`` of ``cv2.getOptimalNewCameraMatrix`` with the
given ``alpha`` (0: cropped to valid pixels, but for a few black ones at the border under a strong distortion, as
OpenCV's estimate of the valid region leaves them; 1: every source pixel kept, black borders),
or the input K with ``keep_K``. It is written as a camera YAML with zero distortion, so that the
undistorted images have a calibration of their own: ``<stem>.camera.yaml`` beside an output image
or video, ``camera.yaml`` inside an output folder.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from alcn_cv.errors import InputError
from alcn_cv.io import (
    IMAGE_SUFFIXES,
    atomic_paths,
    check_no_earlier_output,
    check_output_kind,
    is_video,
    list_images,
    map_video,
    read_image,
    write_image,
)

from .camera import Calibration, write_camera_yaml

logger = logging.getLogger(__name__)

__all__ = ["Undistorter", "main"]


class Undistorter:
    """Remaps frames of one calibrated camera to a pinhole camera without distortion.

    Args:
        calib: intrinsics and distortion; frames must have ``calib.image_size``.
        alpha: free scaling of ``cv2.getOptimalNewCameraMatrix`` in [0, 1].
        keep_K: use the input K as the output camera (ignores ``alpha``).
    """

    def __init__(self, calib: Calibration, alpha: float = 0.0, keep_K: bool = False) -> None:
        if not 0.0 <= alpha <= 1.0:
            raise InputError(f"alpha must be in [0, 1], got {alpha}")
        self.size = tuple(int(v) for v in calib.image_size)
        K = np.asarray(calib.K, float)
        dist = np.asarray(calib.dist, float)
        if keep_K:
            self.new_K = K.copy()
        else:
            self.new_K, _ = cv2.getOptimalNewCameraMatrix(K, dist, self.size, alpha, self.size)
        # With K kept and no distortion the remap is the identity: skip it (exact, and faster).
        self.identity = bool(keep_K and not np.any(dist))
        if not self.identity:
            self.map1, self.map2 = cv2.initUndistortRectifyMap(K, dist, None, self.new_K, self.size, cv2.CV_32FC1)

    def __call__(self, image: np.ndarray, name: str = "image") -> np.ndarray:
        """Undistort one image (any channels and dtype OpenCV remaps); same shape out.

        Raises:
            InputError: an image of another size than the calibration's; the message names ``name``."""
        if image.shape[1::-1] != self.size:
            raise InputError(
                f"{name} is {image.shape[1]}x{image.shape[0]} but the calibration is for "
                f"{self.size[0]}x{self.size[1]}; calibrate at this resolution"
            )
        if self.identity:
            return image
        return cv2.remap(image, self.map1, self.map2, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)


def main(
    source: str | os.PathLike,
    output: str | os.PathLike,
    calib: Calibration,
    alpha: float = 0.0,
    keep_K: bool = False,
    progress: bool = True,
    overwrite: bool = False,
) -> Path:
    """Undistort an image, a folder of images or a video.

    Args:
        source: image file, folder of images, or video.
        output: for an image: output image path; for a folder: output folder (same file
            names); for a video: output video path (``.mp4``/``.avi``).
        calib: calibration of the camera.
        alpha, keep_K: output camera (see :class:`Undistorter`).
        progress: a progress bar over a folder's images or a video's frames.
        overwrite: replace existing outputs (images, video, camera YAML).

    Returns:
        The path of the output camera YAML (``camera.yaml`` in the output folder, or
        ``<output stem>.camera.yaml`` beside an output file).

    Raises:
        InputError: the output is the input (it would be overwritten), an output of another kind than the source (a
            file name for a folder, not an image file for an image, not a video file for a video), outputs that
            exist without ``overwrite`` (all before any work), an unreadable source, or an unreadable image or one of
            another size than the calibration in a folder (then none of the folder's outputs is written).
    """
    source, output = Path(source), Path(output)
    if source.resolve() == output.resolve():  # resolved: ./a.png, a link to it and a.png are one file
        raise InputError(f"the output {output} is the input {source}: it would be overwritten; give another output")
    undistort = Undistorter(calib, alpha, keep_K)
    suffix = source.suffix.lower()
    if source.is_dir():
        check_output_kind(source, output)
        files = list_images(source)
        yaml_path = output / "camera.yaml"
        check_no_earlier_output([*(output / path.name for path in files), yaml_path], overwrite)
        # all or none: a bad image found on the way would leave those before it, which would refuse a rerun
        with atomic_paths(*(output / path.name for path in files)) as outputs:
            bar = {"desc": "undistorting", "unit": "image", "disable": not progress or len(files) < 10}
            for path, tmp in tqdm(zip(files, outputs), total=len(files), **bar):
                write_image(tmp, undistort(read_image(path), path.name))
    elif source.is_file() and (is_video(source) or suffix in IMAGE_SUFFIXES):
        check_output_kind(source, output)
        yaml_path = output.with_name(f"{output.stem}.camera.yaml")
        check_no_earlier_output([output, yaml_path], overwrite)
        if is_video(source):
            n = map_video(
                source, output, lambda frame: undistort(frame, source.name), desc="undistorting", progress=progress
            )
            logger.info("undistorted %d frames to %s", n, output)
        else:
            write_image(output, undistort(read_image(source), source.name))
    elif source.exists():
        raise InputError(f"{source}: expected an image, a folder of images or a video")
    else:
        raise InputError(f"{source}: no such file or folder")
    write_camera_yaml(yaml_path, undistort.new_K, np.zeros(5), undistort.size)
    return yaml_path
