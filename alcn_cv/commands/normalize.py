"""``alcn normalize``: normalize an image, a folder of images, or a video file."""

from __future__ import annotations

import argparse
import inspect
import logging
from collections import Counter
from collections.abc import Callable
from pathlib import Path

import numpy as np
from tqdm import tqdm

from alcn_cv.enhance import available, create
from alcn_cv.enhance.registry import describe, parameters, parse_params
from alcn_cv.errors import InputError
from alcn_cv.io import IMAGE_SUFFIXES, check_writable, is_video, list_images, map_video, read_image, write_image

logger = logging.getLogger(__name__)


def _check_output(src: Path, dst: Path, overwrite: bool, in_place: bool) -> list[Path]:
    """The files ``dst`` names for ``src`` (one, or one per image of a folder), checked before
    any work: an output that is its input needs ``in_place``, an existing one ``overwrite``, and
    the folder must be writable.

    Raises:
        InputError: an output is its input (without ``in_place``), exists (without ``overwrite``)
            or cannot be written (the message names the output given).
    """
    if src.resolve() == dst.resolve():
        if not in_place:
            raise InputError(f"the output {dst} is the input {src}: it would be replaced (--in-place replaces it)")
        return [src] if not src.is_dir() else list_images(src)
    if src.is_dir():
        if dst.exists() and not dst.is_dir():
            raise InputError(f"the output of a folder must be a folder, but {dst} is a file")
        outputs = [dst / path.name for path in list_images(src)]
    elif is_video(src):
        if not is_video(dst):
            raise InputError(f"the output of a video must be a video file (.mp4, .avi, ...), got {dst}")
        outputs = [dst]
    elif dst.suffix.lower() not in IMAGE_SUFFIXES:
        raise InputError(f"the output of an image must be an image file ({', '.join(sorted(IMAGE_SUFFIXES))}), got {dst}")
    else:
        outputs = [dst]
    existing = [path for path in outputs if path.exists()]
    if existing and not overwrite:
        more = f" and {len(existing) - 1} more" if len(existing) > 1 else ""
        raise InputError(f"the output {existing[0]}{more} exists (--overwrite replaces it)")
    check_writable(outputs[0])
    return outputs


def main(
    src: Path,
    dst: Path,
    method: str = "alcn",
    params: dict[str, object] | None = None,
    gray: bool = False,
    allow_partial: bool = False,
    overwrite: bool = False,
    in_place: bool = False,
    skip_bad: bool = False,
) -> None:
    """Normalize ``src`` (image, folder of images, or video) into ``dst`` with ``method``.

    ``method`` is a name or spec ``NAME[:KEY=VALUE...]`` (:func:`alcn_cv.enhance.create`), with
    ``params``. An alpha channel is kept (passed through unchanged). Nothing is written when an
    output is the input (unless ``in_place``), exists (unless ``overwrite``) or is not writable.
    In a folder, an image that cannot be read stops the run before anything is written, or with
    ``skip_bad`` is skipped; the end says how many images were written and what was skipped
    and why. ``allow_partial`` accepts a video that ends before its header's frame count (see
    :func:`alcn_cv.io.map_video`).
    """
    import cv2

    outputs = _check_output(src, dst, overwrite, in_place)
    normalization = create(method, **(params or {}))

    def load_frame(img: np.ndarray) -> np.ndarray:
        if not gray or img.ndim == 2:
            return img
        if img.shape[2] == 4:  # gray and alpha
            return np.dstack([cv2.cvtColor(img, cv2.COLOR_BGRA2GRAY), img[..., 3]])
        return cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)

    if src.is_dir():
        _normalize_folder(src, outputs, lambda img: normalization.apply(load_frame(img)), skip_bad)
    elif is_video(src):
        frames = map_video(
            src, dst, lambda frame: normalization.apply(load_frame(frame)), desc=f"normalize {src.name}", allow_partial=allow_partial
        )
        logger.info("wrote %d frames to %s", frames, dst)
    else:
        write_image(dst, normalization.apply(load_frame(read_image(src, alpha=True))))
        logger.info("wrote %s", dst)


def _normalize_folder(src: Path, outputs: list[Path], normalize: Callable[[np.ndarray], np.ndarray], skip_bad: bool) -> None:
    images = list_images(src)
    skipped = {path.name: "not an image" for path in sorted(src.iterdir()) if path.is_file() and path not in images
               and not path.name.startswith(".")}
    if not skip_bad:  # every image is read first: a bad one stops the run before anything is written
        for path in tqdm(images, desc=f"check {src.name}", unit="image"):
            read_image(path, alpha=True)
    written = 0
    for path, output in tqdm(list(zip(images, outputs)), desc=f"normalize {src.name}", unit="image"):
        try:
            img = read_image(path, alpha=True)
        except InputError as exc:
            if not skip_bad:
                raise
            logger.warning("skipped %s", exc)
            skipped[path.name] = "unreadable"
            continue
        write_image(output, normalize(img))
        written += 1
    reasons = ", ".join(f"{count} {reason}" for reason, count in sorted(Counter(skipped.values()).items()))
    logger.info("wrote %d images to %s; skipped %d%s", written, outputs[0].parent, len(skipped), f" ({reasons})" if reasons else "")


def methods_table() -> str:
    """Every registered method: its name, one-line summary and reference, then its parameters
    with their defaults, as a spec ``NAME:KEY=VALUE...`` would give them."""
    width = max(map(len, available()))
    lines = []
    for name in available():
        summary, reference = describe(name)
        lines.append(f"{name:<{width}}  {summary}" + (f" [{reference}]" if reference else ""))
        params = [key if value is inspect.Parameter.empty else f"{key}={value!r}".replace(" ", "")
                  for key, value in parameters(name).items()]
        lines.append(f"{'':<{width}}  parameters: {' '.join(params) or 'none'}")
    return "\n".join(lines)


def _run(args: argparse.Namespace) -> None:
    if args.list:
        print(methods_table())
        return
    if args.input is None or args.output is None:
        raise InputError("give an INPUT and an OUTPUT (or --list to see the methods)")
    main(
        args.input, args.output, args.method, parse_params(args.param), args.gray, args.allow_partial,
        overwrite=args.overwrite, in_place=args.in_place, skip_bad=args.skip_bad,
    )


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "normalize",
        help="normalize an image, a folder of images or a video",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Normalize an image, every image of a folder (into a folder), or every frame of a video "
        "(into a video) with ALCN or any registered normalization. Colour inputs are normalized on the "
        "L channel of CIE Lab; the output keeps the input's size, channels (an alpha channel is passed "
        "through) and bit depth. An existing output is replaced only with --overwrite, the input itself "
        "only with --in-place; nothing is written when a check fails. In a folder, files that are not "
        "images are skipped, and an unreadable image stops the run before anything is written (or is "
        "skipped with --skip-bad); the end counts what was written and skipped.",
        epilog="methods (-m NAME or NAME:KEY=VALUE..., e.g. -m dog:sigma1=1:sigma2=2 or -m clahe:clip_limit=3; "
        "OpenCV's camelCase names are also accepted in snake_case):\n" + methods_table(),
    )
    parser.add_argument("input", type=Path, nargs="?", help="image file, folder of images, or video file")
    parser.add_argument("output", type=Path, nargs="?", help="image file, folder, or video file (same kind as the input)")
    parser.add_argument(
        "--method", "-m", default="alcn", metavar="SPEC",
        help="normalization NAME[:KEY=VALUE...] (default: alcn); the methods and their parameters are listed below",
    )
    parser.add_argument(
        "--param", "-p", action="append", default=[], metavar="NAME=VALUE",
        help="parameter of the method, repeatable (e.g. -p scale=0.25, -p backend=torch); the same as :NAME=VALUE in -m",
    )
    parser.add_argument("--gray", action="store_true", help="convert to grayscale before normalizing (an alpha channel is kept)")
    parser.add_argument("--list", action="store_true", help="list the methods with their parameters and defaults, and exit")
    parser.add_argument("--overwrite", action="store_true", help="replace outputs that exist (by default an existing output is an error)")
    parser.add_argument(
        "--in-place", action="store_true",
        help="allow the output to be the input (a file, video or folder), which is replaced (by default an error)",
    )
    parser.add_argument(
        "--skip-bad", action="store_true",
        help="in a folder, skip images that cannot be read and go on (by default the first one stops the run "
        "before anything is written)",
    )
    parser.add_argument(
        "--allow-partial", action="store_true",
        help="accept a video that ends before the frame count of its header (truncated): write the decoded frames",
    )
    parser.set_defaults(func=_run)
