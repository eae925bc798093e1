"""``alcn demo``: the main job on data the project generates itself.

1. Renders a small ALCN-2D-like detection set (three objects: matte, velvet-like, specular)
   with test images under different lightings: the ``demo`` preset of :mod:`alcn_cv.data.detect`.
2. Normalizes those test images with every registered method and writes a side-by-side
   grid, ``normalized.png`` (rows: lightings, columns: methods).
3. Runs the ``demo`` preset of the detection benchmark on that set (:mod:`alcn_cv.bench.detect`):
   for ALCN, no normalization and the strongest classical methods, the same detector is trained
   from 1 and from 3 images per object and scored
   on the test images; ``bench/detect.md`` holds the AUC table, ``bench/*.png`` the
   precision-recall curves.

Both presets are used as they are: ``alcn data detect --conf demo`` and ``alcn bench detect --conf demo``
make the same run.

The output folder is the demo's own: ``demo.json`` in it marks it so (written first), and a later demo replaces an
earlier one's outputs (``make demo`` twice in a row); a folder that holds other files than the demo's and no
``demo.json`` is refused before anything is written.
"""

from __future__ import annotations

import argparse
import logging
import re
import textwrap
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np
from tqdm import tqdm

from alcn_cv.cli import SEED, add_progress_option
from alcn_cv.enhance import available, create
from alcn_cv.errors import InputError
from alcn_cv.extras import require
from alcn_cv.io import make_folder, write_json

if TYPE_CHECKING:
    from alcn_cv.enhance.base import Normalization
    from alcn_cv.formats.coco import CocoImage

logger = logging.getLogger(__name__)

#: The file that marks a folder as the demo's output (written before its work): a later demo replaces that folder's
#: outputs, never those of a folder without it.
MARKER = "demo.json"
#: What the demo writes into its folder: a folder holding nothing else, its rendered set among it, is an earlier
#: demo's without the marker (written before it was).
OUTPUTS = frozenset({MARKER, "normalized.png", "bench", "data"})


def method_title(method: Normalization) -> str:
    """The method's registered name and its full name (the first words of its class docstring),
    e.g. ``"dog: Difference of Gaussians"``."""
    doc = (type(method).__doc__ or "").strip().splitlines()
    full = re.split(r" \(|:|,|\.", doc[0], maxsplit=1)[0].strip() if doc else ""
    return f"{method.name}: {full}" if full else method.name


def image_label(index: int, image: CocoImage) -> str:
    """A row title: the test image's number, its lighting family and exposure gain (two images
    of the same family differ in their number and gain)."""
    lighting = image.extra.get("lighting", {})
    gain = f", gain {lighting['gain']:.2f}" if "gain" in lighting else ""
    return f"test image {index + 1}\n{image.extra.get('light_family', '?')} light{gain}"


def normalization_grid(
    images: list[np.ndarray],
    labels: list[str],
    methods: list[str],
    path: Path,
    progress: bool = True,
    **params: dict[str, object],
) -> Path:
    """Write a PNG grid: one row per image, one column per normalization method.

    Args:
        images: BGR uint8 images.
        labels: a distinct row title per image (e.g. its number and lighting).
        methods: registered method names; ``params[name]`` gives a method's parameters. The
            column titles give each name and the method's full name.
        path: the PNG to write.
        progress: a progress bar over the methods.
    """
    from alcn_cv.report import new_figure, save_figure

    h, w = images[0].shape[:2]
    cell = 2.2
    height = cell * h / w * len(images) + 1.0
    plt, fig, axes = new_figure(len(images), len(methods), figsize=(cell * len(methods) + 0.6, height))
    for j, name in enumerate(tqdm(methods, desc="normalize", unit="method", disable=not progress)):
        method = create(name, **params.get(name, {}))
        for i, img in enumerate(images):
            out = method.apply(img)
            ax = axes[i, j]
            ax.imshow(cv2.cvtColor(out, cv2.COLOR_BGR2RGB))
            ax.set_xticks([])
            ax.set_yticks([])
            if i == 0:
                ax.set_title(textwrap.fill(method_title(method), 24), fontsize=8)
            if j == 0:
                ax.set_ylabel(labels[i], fontsize=8)
    fig.suptitle(
        "Rows: test images under different lights; columns: every normalization, as apply() gives it", fontsize=10
    )
    fig.tight_layout(pad=0.3, rect=(0, 0, 1, 1 - 0.35 / height))  # room for the title line
    return save_figure(plt, fig, path, dpi=110)


def check_out_dir(out_dir: Path) -> None:
    """Check, before any work, that the demo may write into ``out_dir``: a new path, an empty folder, or an earlier
    demo's output: it holds :data:`MARKER`, or nothing but :data:`OUTPUTS` with the demo's own ``normalized.png`` and
    data set (``data/manifest.json`` of the ``demo`` preset of ``alcn data detect``), whose files are replaced.

    Raises:
        InputError: ``out_dir`` is a file, or a folder of other files (the user's, say) without :data:`MARKER`.
    """
    if not out_dir.exists() or (out_dir / MARKER).is_file():
        return
    if not out_dir.is_dir():
        raise InputError(f"{out_dir} is a file, not an output folder: not replaced; give another --out")
    if any(out_dir.iterdir()) and not _unmarked_demo(out_dir):
        raise InputError(f"{out_dir} is not an earlier demo's output (no {MARKER}): not replaced; give another --out")


def _unmarked_demo(out_dir: Path) -> bool:
    """Whether ``out_dir`` holds a demo's outputs from before :data:`MARKER`, and nothing else: a user's data set of
    another kind or preset in ``out_dir/data`` is not the demo's."""
    from alcn_cv.data.manifest import read_manifest
    from alcn_cv.errors import DatasetError

    if not (out_dir / "normalized.png").is_file() or any(p.name not in OUTPUTS for p in out_dir.iterdir()):
        return False
    try:
        manifest = read_manifest(out_dir / "data", "detect")
    except DatasetError:
        return False
    return manifest["parameters"].get("conf") == "demo"


def main(out_dir: Path, seed: int = 0, progress: bool = True) -> Path:
    """Run the demo (see the module) into ``out_dir``.

    Args:
        out_dir: the output folder: new, empty, or an earlier demo's (:func:`check_out_dir`), whose outputs are
            replaced.
        seed: seed of the generated data (>= 0).
        progress: progress bars.

    Returns:
        ``out_dir``.

    Raises:
        InputError: a negative ``seed``, or an ``out_dir`` :func:`check_out_dir` refuses, before anything is written.
        MissingDependencyError: a package of the [bench] extra is missing.
    """
    if seed < 0:
        raise InputError(f"--seed must be >= 0, got {seed}")
    check_out_dir(out_dir)
    # the rendering, the grid and the benchmark need the [bench] extra: checked before anything is rendered or written
    require("skimage", "matplotlib", "torch", "kornia", what="alcn demo", preferred="bench")
    from alcn_cv.data import detect
    from alcn_cv.data.manifest import read_manifest
    from alcn_cv.formats.coco import load_coco

    make_folder(out_dir)
    write_json(out_dir / MARKER, {"command": "alcn demo", "seed": seed})  # first: an interrupted demo's is its own
    data_dir = out_dir / "data"
    logger.info("rendering a small detection set into %s", data_dir)
    detect.generate(data_dir, seed=seed, conf="demo", overwrite=True, progress=progress)
    test = load_coco(data_dir / "test.json")
    images = [test.read_image(im) for im in test.images]
    labels = [image_label(k, im) for k, im in enumerate(test.images)]
    scale = float(read_manifest(data_dir, "detect")["working_scale"])
    grid = normalization_grid(images, labels, available(), out_dir / "normalized.png", progress, alcn={"scale": scale})
    logger.info("wrote %s", grid)

    from alcn_cv.bench import detect as bench
    from alcn_cv.bench.detect_settings import CONFS
    from alcn_cv.presets import preset

    # the demo's own folder, made again on every run (as its data): `make demo` twice in a row replaces it
    bench.main(data_dir, out_dir / "bench", preset(CONFS, "demo"), progress=progress, overwrite=True)
    table = out_dir / "bench" / "detect.md"
    logger.info(
        "detection benchmark (demo preset; the full one is `alcn bench detect`):\n%s",
        table.read_text(encoding="utf-8"),
    )
    logger.info("outputs: %s (normalized.png, bench/detect.md, bench/*.png)", out_dir)
    return out_dir


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "demo",
        help="run the main job on generated data (what `make demo` runs)",
        description="Render a small detection set under several lightings, normalize it with every available "
        "method, and run a small detection benchmark on it. Writes OUT/normalized.png (rows: lightings, columns: "
        "methods), OUT/bench/detect.md (AUC per object and method) with precision-recall curves OUT/bench/*.png, "
        f"the data in OUT/data, and OUT/{MARKER}, which marks OUT as the demo's: a later demo replaces those files "
        "(`make demo` twice), and OUT is refused when it holds other files without it.",
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=Path("demo_out"),
        help=f"output folder: new, empty, or an earlier demo's (holding {MARKER}), replaced (default: demo_out)",
    )
    parser.add_argument("--seed", type=SEED, default=0, help="seed of the generated data (default 0)")
    add_progress_option(parser)
    parser.set_defaults(func=lambda args: main(args.out, args.seed, not args.no_progress) and 0)
