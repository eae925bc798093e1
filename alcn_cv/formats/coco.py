"""COCO object-detection annotations: reader and writer.

The format is COCO's (https://cocodataset.org/#format-data): ``images`` (``id``, ``file_name``,
``width``, ``height``), ``annotations`` (``id``, ``image_id``, ``category_id``,
``bbox = [x, y, w, h]`` in pixels with (x, y) the top-left corner, ``area``, ``iscrowd``) and
``categories`` (``id``, ``name``). Extra keys are kept in ``extra`` dictionaries (the data engine
stores e.g. each test image's lighting family there).

Image files are looked up relative to ``image_root`` (default: the JSON file's folder, then its
``images/`` subfolder), so both the data engine's layout and COCO's usual ``annotations/`` +
image-folder layout (pass ``image_root``) read directly.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from alcn_cv.errors import DatasetError, InputError
from alcn_cv.formats import validate_json
from alcn_cv.io import eight_bits, read_image, read_json, write_json

__all__ = ["CocoImage", "CocoAnnotation", "CocoCategory", "CocoDataset", "load_coco", "write_coco"]


@dataclass
class CocoImage:
    """One image: ``path`` is the resolved file (it may not exist unless checked)."""

    id: int
    file_name: str
    width: int
    height: int
    path: Path
    extra: dict[str, Any] = field(default_factory=dict)


@dataclass
class CocoAnnotation:
    """One object instance; ``bbox`` is float64 (4,) ``[x, y, w, h]`` in pixels."""

    id: int
    image_id: int
    category_id: int
    bbox: np.ndarray
    area: float
    iscrowd: int = 0
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def center(self) -> np.ndarray:
        """Centre (x, y) of the box, with OpenCV's pixel-centre convention (float64 (2,))."""
        x, y, w, h = self.bbox
        return np.array([x + w / 2.0 - 0.5, y + h / 2.0 - 0.5])


@dataclass
class CocoCategory:
    id: int
    name: str
    supercategory: str = ""
    extra: dict[str, Any] = field(default_factory=dict)


@dataclass
class CocoDataset:
    """A COCO detection set.

    Attributes:
        path: the JSON file.
        images, annotations, categories: in file order.
        info: the ``info`` object (empty when absent).
    """

    path: Path
    images: list[CocoImage]
    annotations: list[CocoAnnotation]
    categories: list[CocoCategory]
    info: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self._by_image: dict[int, list[CocoAnnotation]] = {im.id: [] for im in self.images}
        for a in self.annotations:
            self._by_image.setdefault(a.image_id, []).append(a)

    def annotations_for(self, image_id: int) -> list[CocoAnnotation]:
        """Annotations of one image (empty list for an image without objects)."""
        return self._by_image.get(image_id, [])

    def category(self, name_or_id: str | int) -> CocoCategory:
        """The category of that name or id."""
        for c in self.categories:
            if c.id == name_or_id or c.name == name_or_id:
                return c
        raise KeyError(f"no category {name_or_id!r} in {self.path}")

    def read_image(self, image: CocoImage, gray: bool = False) -> np.ndarray:
        """Read an image with :func:`alcn_cv.io.read_image` and check its size against the annotation.

        Returns:
            ``HxWx3`` BGR uint8 (a gray file as three equal channels, 16 bits rounded to 8 by
            :func:`~alcn_cv.io.eight_bits`) or, with ``gray``, ``HxW`` uint8.

        Raises:
            DatasetError: the file is missing, unreadable, corrupt or truncated, or its size is not the
                annotation's; the message names the JSON file and the image id.
        """
        try:
            img = read_image(image.path, gray=gray)
        except InputError as exc:
            raise DatasetError(f"{self.path}: image id {image.id}: {exc}") from None
        if img.dtype == np.uint16:
            img = eight_bits(img)
        if not gray and img.ndim == 2:
            img = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
        if img.shape[:2] != (image.height, image.width):
            raise DatasetError(
                f"{self.path}: image id {image.id} field width/height: annotation says "
                f"{image.width}x{image.height} but {image.path} is {img.shape[1]}x{img.shape[0]}"
            )
        return img


def load_coco(
    path: str | os.PathLike, *, image_root: str | os.PathLike | None = None, check_images: bool = False
) -> CocoDataset:
    """Read a COCO detection JSON file.

    Args:
        path: the JSON file.
        image_root: folder that ``file_name`` is relative to (default: the JSON's folder, or its
            ``images/`` subfolder when the file is there).
        check_images: also read every image (:func:`alcn_cv.io.read_image`) and check it exists, is whole (no
            truncated JPEG) and matches ``width``/``height``.

    Raises:
        DatasetError: missing, truncated or malformed file; a field violating the schema; an
            annotation referring to an unknown image or category; a box outside its image; with
            ``check_images``, a missing, unreadable or truncated image or one whose size differs from its
            annotation. The message names the file and the field.
    """
    path = Path(path)
    doc = read_json(path)
    validate_json(doc, "coco", path)
    root = Path(image_root) if image_root is not None else path.parent
    images = []
    seen: set[int] = set()
    for i, d in enumerate(doc["images"]):
        if d["id"] in seen:
            raise DatasetError(f"{path}: field images[{i}].id: duplicate id {d['id']}")
        seen.add(d["id"])
        p = root / d["file_name"]
        if image_root is None and not p.exists() and (root / "images" / d["file_name"]).exists():
            p = root / "images" / d["file_name"]
        extra = {k: v for k, v in d.items() if k not in ("id", "file_name", "width", "height")}
        images.append(CocoImage(int(d["id"]), d["file_name"], int(d["width"]), int(d["height"]), p, extra))
    by_id = {im.id: im for im in images}
    cats = []
    for d in doc["categories"]:
        extra = {k: v for k, v in d.items() if k not in ("id", "name", "supercategory")}
        cats.append(CocoCategory(int(d["id"]), d["name"], d.get("supercategory", ""), extra))
    cat_ids = {c.id for c in cats}
    anns = []
    for i, d in enumerate(doc["annotations"]):
        if d["image_id"] not in by_id:
            raise DatasetError(f"{path}: field annotations[{i}].image_id: no image with id {d['image_id']}")
        if d["category_id"] not in cat_ids:
            raise DatasetError(f"{path}: field annotations[{i}].category_id: no category with id {d['category_id']}")
        box = np.asarray(d["bbox"], np.float64)
        im = by_id[d["image_id"]]
        if (
            box[2] <= 0
            or box[3] <= 0
            or box[0] < -0.5
            or box[1] < -0.5
            or box[0] + box[2] > im.width + 0.5
            or box[1] + box[3] > im.height + 0.5
        ):
            raise DatasetError(
                f"{path}: field annotations[{i}].bbox: {box.tolist()} is empty or outside its "
                f"{im.width}x{im.height} image (wrong unit or image size?)"
            )
        extra = {k: v for k, v in d.items() if k not in ("id", "image_id", "category_id", "bbox", "area", "iscrowd")}
        anns.append(
            CocoAnnotation(
                int(d["id"]),
                int(d["image_id"]),
                int(d["category_id"]),
                box,
                float(d.get("area", box[2] * box[3])),
                int(d.get("iscrowd", 0)),
                extra,
            )
        )
    if check_images:
        for i, im in enumerate(images):
            try:
                height, width = read_image(im.path).shape[:2]
            except InputError as exc:
                raise DatasetError(f"{path}: field images[{i}].file_name: {exc}") from None
            size = (width, height)
            if size != (im.width, im.height):
                raise DatasetError(
                    f"{path}: field images[{i}].width/height: {im.width}x{im.height} but "
                    f"{im.path} is {size[0]}x{size[1]}"
                )
    return CocoDataset(path, images, anns, cats, dict(doc.get("info", {})))


def write_coco(
    path: str | os.PathLike,
    images: Iterable[dict[str, Any]],
    annotations: Iterable[dict[str, Any]],
    categories: Iterable[dict[str, Any]],
    info: dict[str, Any] | None = None,
) -> Path:
    """Write a COCO detection file atomically, after validating it against the schema.

    Args:
        path: output JSON file.
        images: dicts with ``id``, ``file_name``, ``width``, ``height`` (extra keys kept).
        annotations: dicts with ``id``, ``image_id``, ``category_id``, ``bbox`` ([x, y, w, h]);
            ``area`` defaults to ``w * h`` and ``iscrowd`` to 0.
        categories: dicts with ``id`` and ``name``.
        info: the ``info`` object.
    """
    path = Path(path)
    anns = []
    for a in annotations:
        a = dict(a)
        a["bbox"] = [round(float(v), 3) for v in a["bbox"]]
        a.setdefault("area", round(a["bbox"][2] * a["bbox"][3], 3))
        a.setdefault("iscrowd", 0)
        anns.append(a)
    doc = {"info": info or {}, "images": list(images), "annotations": anns, "categories": list(categories)}
    validate_json(doc, "coco", path)
    return write_json(path, doc, indent=None)
