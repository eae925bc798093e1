"""``alcn normalize``: normalize an image, a folder of images, or a video file."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

import numpy as np
from tqdm import tqdm

from alcn_cv.enhance import available, create
from alcn_cv.enhance.registry import describe, parse_params
from alcn_cv.errors import InputError
from alcn_cv.io import IMAGE_SUFFIXES, is_video, list_images, make_folder, map_video, read_image, write_image

logger = logging.getLogger(__name__)


def main(
    src: Path,
    dst: Path,
    method: str = "alcn",
    params: dict[str, object] | None = None,
    gray: bool = False,
    allow_partial: bool = False,
) -> None:
    """Normalize ``src`` (image, folder of images, or video) into ``dst`` with ``method``.

    An alpha channel is kept (passed through unchanged). ``allow_partial`` accepts a video
    that ends before its header's frame count (see :func:`alcn_cv.io.map_video`).
    """
    import cv2

    if src.is_dir():
        if dst.exists() and not dst.is_dir():
            raise InputError(f"the output of a folder must be a folder, but {dst} is a file")
    elif is_video(src):
        if not is_video(dst):
            raise InputError(f"the output of a video must be a video file (.mp4, .avi, ...), got {dst}")
    elif dst.suffix.lower() not in IMAGE_SUFFIXES:
        raise InputError(f"the output of an image must be an image file ({', '.join(sorted(IMAGE_SUFFIXES))}), got {dst}")
    normalization = create(method, **(params or {}))

    def load_frame(img: np.ndarray) -> np.ndarray:
        if not gray or img.ndim == 2:
            return img
        if img.shape[2] == 4:  # gray and alpha
            return np.dstack([cv2.cvtColor(img, cv2.COLOR_BGRA2GRAY), img[..., 3]])
        return cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)

    if src.is_dir():
        images = list_images(src)
        make_folder(dst)
        for path in tqdm(images, desc=f"normalize {src.name}", unit="image"):
            write_image(dst / path.name, normalization.apply(load_frame(read_image(path, alpha=True))))
        logger.info("wrote %d images to %s", len(images), dst)
    elif is_video(src):
        frames = map_video(
            src, dst, lambda frame: normalization.apply(load_frame(frame)), desc=f"normalize {src.name}", allow_partial=allow_partial
        )
        logger.info("wrote %d frames to %s", frames, dst)
    else:
        write_image(dst, normalization.apply(load_frame(read_image(src, alpha=True))))
        logger.info("wrote %s", dst)


def methods_table() -> str:
    """Every registered method with its one-line summary and reference, one per line."""
    width = max(map(len, available()))
    lines = []
    for name in available():
        summary, reference = describe(name)
        lines.append(f"{name:<{width}}  {summary}" + (f" [{reference}]" if reference else ""))
    return "\n".join(lines)


def _run(args: argparse.Namespace) -> None:
    if args.list:
        print(methods_table())
        return
    if args.input is None or args.output is None:
        raise InputError("give an INPUT and an OUTPUT (or --list to see the methods)")
    main(args.input, args.output, args.method, parse_params(args.param), args.gray, args.allow_partial)


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "normalize",
        help="normalize an image, a folder of images or a video",
        description="Normalize an image, every image of a folder (into a folder), or every frame of a video "
        "(into a video) with ALCN or any registered normalization. Colour inputs are normalized on the "
        "L channel of CIE Lab; the output keeps the input's size, channels (an alpha channel is passed "
        "through) and bit depth. --list explains the methods.",
    )
    parser.add_argument("input", type=Path, nargs="?", help="image file, folder of images, or video file")
    parser.add_argument("output", type=Path, nargs="?", help="image file, folder, or video file (same kind as the input)")
    parser.add_argument("--method", "-m", default="alcn", help=f"normalization (default: alcn); one of: {', '.join(available())}")
    parser.add_argument(
        "--param", "-p", action="append", default=[], metavar="NAME=VALUE",
        help="parameter of the method, repeatable (e.g. -p scale=0.25, -p backend=torch)",
    )
    parser.add_argument("--gray", action="store_true", help="convert to grayscale before normalizing (an alpha channel is kept)")
    parser.add_argument("--list", action="store_true", help="list the methods, each with one line and its reference, and exit")
    parser.add_argument(
        "--allow-partial", action="store_true",
        help="accept a video that ends before the frame count of its header (truncated): write the decoded frames",
    )
    parser.set_defaults(func=_run)
