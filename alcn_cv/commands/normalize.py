"""``alcn normalize``: normalize an image, a folder of images, or a video file."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

import numpy as np
from tqdm import tqdm

from alcn_cv.enhance import available, create
from alcn_cv.enhance.registry import parse_params
from alcn_cv.errors import InputError
from alcn_cv.io import is_video, list_images, map_video, read_image, write_image

logger = logging.getLogger(__name__)


def main(src: Path, dst: Path, method: str = "alcn", params: dict[str, object] | None = None, gray: bool = False) -> None:
    """Normalize ``src`` (image, folder of images, or video) into ``dst`` with ``method``."""
    import cv2

    normalizer = create(method, **(params or {}))

    def load_frame(img: np.ndarray) -> np.ndarray:
        return cv2.cvtColor(img, cv2.COLOR_BGR2GRAY) if gray and img.ndim == 3 else img

    if src.is_dir():
        images = list_images(src)
        for path in tqdm(images, desc=f"normalize {src.name}", unit="image"):
            write_image(dst / path.name, normalizer.apply(load_frame(read_image(path))))
        logger.info("wrote %d images to %s", len(images), dst)
    elif is_video(src):
        if not is_video(dst):
            raise InputError(f"the output of a video must be a video file (.mp4, .avi, ...), got {dst}")
        frames = map_video(src, dst, lambda frame: normalizer.apply(load_frame(frame)), desc=f"normalize {src.name}")
        logger.info("wrote %d frames to %s", frames, dst)
    else:
        write_image(dst, normalizer.apply(load_frame(read_image(src))))
        logger.info("wrote %s", dst)


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "normalize",
        help="normalize an image, a folder of images or a video",
        description="Normalize an image, every image of a folder (into a folder), or every frame of a video "
        "(into a video) with ALCN or any registered normalization. Colour inputs are normalized on the "
        "L channel of CIE Lab; the output keeps the input's size, channels and bit depth.",
    )
    parser.add_argument("input", type=Path, help="image file, folder of images, or video file")
    parser.add_argument("output", type=Path, help="image file, folder, or video file (same kind as the input)")
    parser.add_argument("--method", "-m", default="alcn", help=f"normalization (default: alcn); one of: {', '.join(available())}")
    parser.add_argument(
        "--param", "-p", action="append", default=[], metavar="NAME=VALUE",
        help="parameter of the method, repeatable (e.g. -p scale=0.25, -p backend=torch)",
    )
    parser.add_argument("--gray", action="store_true", help="convert to grayscale before normalizing")
    parser.set_defaults(func=lambda args: main(args.input, args.output, args.method, parse_params(args.param), args.gray))
