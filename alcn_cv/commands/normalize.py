"""``alcn normalize``: normalize an image, a folder of images, or a video file."""

from __future__ import annotations

import argparse
import inspect
import logging
import os
import time
from collections import Counter
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
from tqdm import tqdm

from alcn_cv.cli import COUNT, add_progress_option
from alcn_cv.enhance import available, create
from alcn_cv.enhance.alcn import ALCN, default_mixture
from alcn_cv.enhance.registry import describe, format_param, parameters, parse_params, parse_spec
from alcn_cv.errors import InputError
from alcn_cv.extras import require
from alcn_cv.io import (
    check_no_earlier_output,
    check_output_kind,
    check_writable,
    held_folder,
    is_video,
    list_images,
    map_batches,
    map_video,
    read_image,
    write_image,
)

logger = logging.getLogger(__name__)

#: Frames per batch of ``--device``.
DEFAULT_BATCH = 32


def _check_output(src: Path, dst: Path, overwrite: bool, in_place: bool) -> list[Path]:
    """The files ``dst`` names for ``src`` (one, or one per image of a folder), checked before
    any work: an output that is its input needs ``in_place``, an existing one ``overwrite``, and
    the folder must be writable.

    Raises:
        InputError: no input ``src``; an output is its input (without ``in_place``), exists (without
            ``overwrite``) or cannot be written (the message names the output given).
    """
    if not src.exists():  # else its kind, told by its name, would be judged by the output's
        raise InputError(f"no such image, folder or video: {src}")
    if src.resolve() == dst.resolve() or (dst.exists() and os.path.samefile(src, dst)):  # a case-insensitive disk
        if not in_place:
            raise InputError(f"the output {dst} is the input {src}: it would be replaced (--in-place replaces it)")
        return [src] if not src.is_dir() else list_images(src)
    check_output_kind(src, dst)
    outputs = [dst / path.name for path in list_images(src)] if src.is_dir() else [dst]
    check_no_earlier_output(outputs, overwrite)
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
    device: str | None = None,
    batch_size: int | None = None,
    max_frames: int | None = None,
    progress: bool = True,
) -> None:
    """Normalize ``src`` (image, folder of images, or video) into ``dst`` with ``method``.

    ``method`` is a name or spec ``NAME[:KEY=VALUE...]`` (:func:`alcn_cv.enhance.create`), with
    ``params``. An alpha channel is kept (passed through unchanged). Nothing is written when an
    output is the input (unless ``in_place``), exists (unless ``overwrite``) or is not writable. A folder
    ``dst`` is held while the run writes it (:func:`alcn_cv.io.held_folder`): a second run into it is refused.
    In a folder, an image that cannot be read stops the run before anything is written, or with
    ``skip_bad`` is skipped; the end says how many images were written and what was skipped
    and why, and the frames per second. ``allow_partial`` accepts a video that ends before its
    header's frame count (see :func:`alcn_cv.io.map_video`); ``max_frames`` writes a video's first frames only;
    ``progress``: the progress bars.

    ``device`` (``"cpu"``, ``"cuda"``, ...): ALCN on that torch device, ``batch_size`` (default
    :data:`DEFAULT_BATCH`) frames of one size at a time (:meth:`ALCN.apply_batch
    <alcn_cv.enhance.alcn.ALCN.apply_batch>`, colour frames on their CIE L as
    :meth:`~alcn_cv.enhance.base.Normalization.apply`); None: ``apply`` on each frame.

    Raises:
        InputError: a check fails, another run holds the folder ``dst``, or ``device`` is given for a method
            other than ALCN or with another backend.
        MissingDependencyError: ``device`` is given and torch or kornia is not installed (the [train] extra).
    """
    import cv2

    outputs = _check_output(src, dst, overwrite, in_place)
    if max_frames is not None and not is_video(src):
        raise InputError(f"--max-frames counts the frames of a video; {src} is not one")
    if batch_size is not None and device is None:
        raise InputError("--batch-size sets the batches of --device; without it each frame is normalized alone")
    batch_size = DEFAULT_BATCH if batch_size is None else batch_size
    params = dict(params or {})
    if device is not None:
        name, spec_params = parse_spec(method)
        if name != ALCN.name:
            raise InputError(
                f"--device runs ALCN's batched torch path (-m alcn); {name!r} runs on the CPU, one "
                "frame at a time, without --device"
            )
        given = {**spec_params, **params}
        if given.get("backend", "torch") != "torch":
            raise InputError("--device runs ALCN with backend='torch'; drop the backend parameter")
        if given.get("device", device) != device:
            raise InputError(f"--device {device} and the device parameter {given['device']!r} differ; give one")
        if batch_size < 1:
            raise InputError(f"--batch-size must be positive, got {batch_size}")
        require("torch", "kornia", what="alcn normalize --device", preferred="train")
        params.update(backend="torch", device=device)
    normalization = create(method, **params)
    if (
        device is not None
        and isinstance(normalization, ALCN)
        and default_mixture(normalization.weights_meta, "opencv") == "pyramid"
        and "mixture" not in {**parse_spec(method)[1], **params}
    ):
        logger.info("--device runs Eq. 3 exactly (mixture='exact'); without it %s runs the pyramid", method)

    def load_frame(img: np.ndarray) -> np.ndarray:
        if not gray or img.ndim == 2:
            return img
        if img.shape[2] == 4:  # gray and alpha
            return np.dstack([cv2.cvtColor(img, cv2.COLOR_BGRA2GRAY), img[..., 3]])
        return cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)

    def normalize_each(frames: list[np.ndarray]) -> list[np.ndarray]:
        return [normalization.apply(load_frame(frame)) for frame in frames]

    normalize: Callable[[list[np.ndarray]], list[np.ndarray]] = normalize_each
    if device is not None and isinstance(normalization, ALCN):  # with a device, the name was checked above
        normalize = _batch_normalizer(normalization, load_frame)
    size = 1 if device is None else batch_size
    start = time.perf_counter()
    if src.is_dir():
        with held_folder(dst):  # two runs into one folder would mix their images
            outputs = _check_output(src, dst, overwrite, in_place)  # again, held: a run into it may have ended since
            frames = _normalize_folder(src, outputs, normalize, size, skip_bad, progress)
    elif is_video(src):
        frames = map_video(
            src,
            dst,
            normalize,
            f"normalize {src.name}",
            allow_partial,
            batch_size=size,
            max_frames=max_frames,
            progress=progress,
        )
        logger.info("wrote %s to %s", _count(frames, "frame"), dst)
    else:
        write_image(dst, normalize([read_image(src, alpha=True)])[0])
        logger.info("wrote %s", dst)
        return
    seconds = time.perf_counter() - start
    where = "one frame at a time" if device is None else f"batches of {batch_size} on {device}"
    logger.info(
        "%.1f frames/s (%s in %.2f s, %s; reading and writing included)",
        frames / seconds,
        _count(frames, "frame"),
        seconds,
        where,
    )


def _count(number: int, noun: str) -> str:
    """``number`` and ``noun``, plural unless one: ``1 frame``, ``2 frames``, ``0 frames``."""
    return f"{number} {noun}{'' if number == 1 else 's'}"


def _batch_normalizer(
    alcn: ALCN, load: Callable[[np.ndarray], np.ndarray]
) -> Callable[[list[np.ndarray]], list[np.ndarray]]:
    """``alcn.apply`` on a list of images by :meth:`~alcn_cv.enhance.alcn.ALCN.apply_batch`, one batch per
    shape and dtype (a folder may mix them)."""

    def normalize_batch(images: list[np.ndarray]) -> list[np.ndarray]:
        images = [load(img) for img in images]
        groups: dict[tuple, list[int]] = {}
        for index, img in enumerate(images):
            groups.setdefault((img.shape, img.dtype), []).append(index)
        outs: list[np.ndarray] = [images[0]] * len(images)
        for indices in groups.values():
            for index, out in zip(indices, alcn.apply_batch(np.stack([images[i] for i in indices]))):
                outs[index] = out
        return outs

    return normalize_batch


def _normalize_folder(
    src: Path,
    outputs: list[Path],
    normalize: Callable[[list[np.ndarray]], list[np.ndarray]],
    batch_size: int,
    skip_bad: bool,
    progress: bool,
) -> int:
    images = list_images(src)
    skipped = {
        path.name: "not an image"
        for path in sorted(src.iterdir())
        if path.is_file() and path not in images and not path.name.startswith(".")
    }
    if not skip_bad:  # every image is read first: a bad one stops the run before anything is written
        for path in tqdm(images, desc=f"check {src.name}", unit="image", disable=not progress):
            read_image(path, alpha=True)

    def readable() -> Iterator[tuple[Path, np.ndarray]]:
        for path, output in zip(images, outputs):
            try:
                yield output, read_image(path, alpha=True)
            except InputError as exc:
                if not skip_bad:
                    raise
                logger.warning("skipped an image: %s", exc)
                skipped[path.name] = "unreadable"

    def normalize_pairs(pairs: list[tuple[Path, np.ndarray]]) -> list[tuple[Path, np.ndarray]]:
        return list(zip([output for output, _ in pairs], normalize([img for _, img in pairs])))

    with tqdm(total=len(images), desc=f"normalize {src.name}", unit="image", disable=not progress) as bar:
        written = map_batches(readable(), normalize_pairs, lambda pair: write_image(*pair), batch_size, bar)
    reasons = ", ".join(f"{count} {reason}" for reason, count in sorted(Counter(skipped.values()).items()))
    logger.info(
        "wrote %s to %s; skipped %d%s",
        _count(written, "image"),
        outputs[0].parent,
        len(skipped),
        f" ({reasons})" if reasons else "",
    )
    return written


def methods_table() -> str:
    """Every registered method: its name, one-line summary and reference, then its parameters
    with their defaults, as a spec ``NAME:KEY=VALUE...`` would give them."""
    width = max(map(len, available()))
    lines = []
    for name in available():
        summary, reference = describe(name)
        lines.append(f"{name:<{width}}  {summary}" + (f" [{reference}]" if reference else ""))
        params = [
            key if value is inspect.Parameter.empty else format_param(key, value)
            for key, value in parameters(name).items()
        ]
        lines.append(f"{'':<{width}}  parameters: {' '.join(params) or 'none'}")
    return "\n".join(lines)


def _run(args: argparse.Namespace) -> None:
    if args.list:
        print(methods_table())
        return
    if args.input is None or args.output is None:
        raise InputError("give an INPUT and an OUTPUT (or --list to see the methods)")
    main(
        args.input,
        args.output,
        args.method,
        parse_params(args.param),
        args.gray,
        args.allow_partial,
        overwrite=args.overwrite,
        in_place=args.in_place,
        skip_bad=args.skip_bad,
        device=args.device,
        batch_size=args.batch_size,
        max_frames=args.max_frames,
        progress=not args.no_progress,
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
        "skipped with --skip-bad); the end counts what was written and skipped, and the frames per second. "
        "Interrupted (Ctrl-C), a folder keeps the images written so far, each whole (run it again with "
        "--overwrite), and a video is written whole or not at all.\n\n"
        "By default each frame is normalized on the CPU by the method's apply(). With --device DEV (cpu, cuda, "
        "cuda:1; ALCN only), ALCN runs on that torch device --batch-size frames at a time (apply_batch): the next "
        "frames are decoded and the previous ones encoded in two threads while the device works, and colour "
        "frames are normalized on their CIE L as in the per-frame path (the same output within a grey level; "
        "for the lite and paper models the exact Eq. 3, -m alcn:model=lite:mixture=exact's, where the per-frame "
        "default is its pyramid approximation, a few grey levels apart). "
        "--device cpu runs that path on the CPU, where it is slower than the default (which "
        "runs Eq. 3 in OpenCV).",
        epilog="methods (-m NAME or NAME:KEY=VALUE..., e.g. -m dog:sigma1=1:sigma2=2 or -m clahe:clip_limit=3; "
        "OpenCV's camelCase names are also accepted in snake_case):\n" + methods_table(),
    )
    parser.add_argument("input", type=Path, nargs="?", help="image file, folder of images, or video file")
    parser.add_argument(
        "output", type=Path, nargs="?", help="image file, folder, or video file (same kind as the input)"
    )
    parser.add_argument(
        "--method",
        "-m",
        default="alcn",
        metavar="SPEC",
        help="normalization NAME[:KEY=VALUE...] (default: alcn); the methods and their parameters are listed below",
    )
    parser.add_argument(
        "--param",
        "-p",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="parameter of the method, repeatable (e.g. -p scale=0.25, -p backend=torch); "
        "the same as :NAME=VALUE in -m",
    )
    parser.add_argument(
        "--gray", action="store_true", help="convert to grayscale before normalizing (an alpha channel is kept)"
    )
    parser.add_argument(
        "--list", action="store_true", help="list the methods with their parameters and defaults, and exit"
    )
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="replace outputs that exist (by default an existing output is an error)",
    )
    parser.add_argument(
        "--in-place",
        action="store_true",
        help="allow the output to be the input (a file, video or folder), which is replaced (by default an error)",
    )
    parser.add_argument(
        "--skip-bad",
        action="store_true",
        help="in a folder, skip images that cannot be read and go on (by default the first one stops the run "
        "before anything is written)",
    )
    parser.add_argument(
        "--allow-partial",
        action="store_true",
        help="accept a video that ends before the frame count of its header (truncated): write the decoded frames",
    )
    parser.add_argument(
        "--max-frames",
        type=COUNT,
        metavar="N",
        help="of a video, normalize and write the first N frames only (default: every frame)",
    )
    parser.add_argument(
        "--device",
        metavar="DEV",
        help="run ALCN on this torch device (cpu, cuda, cuda:1), in batches of --batch-size frames of one size, "
        "decoding and encoding overlapped; ALCN only (default: each frame by apply() on the CPU)",
    )
    parser.add_argument(
        "--batch-size",
        type=int,
        metavar="N",
        help=f"frames per batch with --device (default: {DEFAULT_BATCH}; fewer if the device runs out of memory)",
    )
    add_progress_option(parser)
    parser.set_defaults(func=_run)
