"""Tests of the COCO reader and writer."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from alcn_cv.errors import DatasetError
from alcn_cv.formats.coco import load_coco, write_coco


def _doc(tmp_path, **changes):
    (tmp_path / "images").mkdir(exist_ok=True)
    cv2.imwrite(str(tmp_path / "images" / "a.png"), np.zeros((40, 60, 3), np.uint8))
    doc = {
        "images": [{"id": 1, "file_name": "a.png", "width": 60, "height": 40}],
        "annotations": [{"id": 1, "image_id": 1, "category_id": 2, "bbox": [10, 5, 20, 15], "area": 300, "iscrowd": 0}],
        "categories": [{"id": 2, "name": "cup"}],
    }
    for k, v in changes.items():
        doc[k] = v
    path = tmp_path / "ann.json"
    path.write_text(json.dumps(doc))
    return path


def test_roundtrip_and_image_lookup(tmp_path):
    path = write_coco(
        tmp_path / "w.json",
        [{"id": 3, "file_name": "images/a.png", "width": 60, "height": 40, "light_family": "dark"}],
        [{"id": 1, "image_id": 3, "category_id": 1, "bbox": [1, 2, 3, 4]}],
        [{"id": 1, "name": "box"}],
        {"description": "t"},
    )
    _doc(tmp_path)
    ds = load_coco(path, check_images=True)
    assert ds.images[0].extra == {"light_family": "dark"} and ds.info["description"] == "t"
    a = ds.annotations_for(3)[0]
    np.testing.assert_array_equal(a.bbox, [1, 2, 3, 4])
    assert a.area == 12 and a.iscrowd == 0 and ds.category("box").id == 1
    np.testing.assert_allclose(a.center, [2.0, 3.5])
    assert ds.annotations_for(99) == []
    # A user's file with file names relative to an images/ folder.
    ds = load_coco(_doc(tmp_path), check_images=True)
    assert ds.images[0].path == tmp_path / "images" / "a.png"
    assert ds.read_image(ds.images[0]).shape == (40, 60, 3)


@pytest.mark.parametrize(
    "change, match",
    [
        ({"annotations": [{"id": 1, "image_id": 1, "category_id": 2, "bbox": [1, 2, 3]}]}, r"annotations\[0\]\.bbox"),
        ({"images": [{"id": 1, "file_name": "a.png", "width": "60", "height": 40}]}, r"images\[0\]\.width"),
        ({"annotations": [{"id": 1, "image_id": 7, "category_id": 2, "bbox": [1, 2, 3, 4]}]}, r"image_id"),
        ({"annotations": [{"id": 1, "image_id": 1, "category_id": 5, "bbox": [1, 2, 3, 4]}]}, r"category_id"),
        (
            {"annotations": [{"id": 1, "image_id": 1, "category_id": 2, "bbox": [0.1, 0.2, 600, 400]}]},
            r"bbox.*wrong unit",
        ),
        ({"categories": None}, r"categories"),
    ],
)
def test_malformed_fields_are_named(tmp_path, change, match):
    with pytest.raises(DatasetError, match=match) as info:
        load_coco(_doc(tmp_path, **change))
    assert "ann.json" in str(info.value)


def test_missing_truncated_and_size_mismatch(tmp_path):
    with pytest.raises(DatasetError, match="not found"):
        load_coco(tmp_path / "nope.json")
    path = _doc(tmp_path)
    text = path.read_text()
    path.write_text(text[: len(text) // 2])
    with pytest.raises(DatasetError, match="truncated"):
        load_coco(path)
    path = _doc(tmp_path, images=[{"id": 1, "file_name": "a.png", "width": 61, "height": 40}])
    ds = load_coco(path)  # sizes are only checked on request
    with pytest.raises(DatasetError, match=r"width/height"):
        load_coco(path, check_images=True)
    with pytest.raises(DatasetError, match="61x40"):
        ds.read_image(ds.images[0])
    path = _doc(tmp_path, images=[{"id": 1, "file_name": "missing.png", "width": 60, "height": 40}])
    with pytest.raises(DatasetError, match="missing.png"):
        load_coco(path, check_images=True)


def test_writer_validates(tmp_path):
    with pytest.raises(DatasetError, match=r"images\[0\]"):
        write_coco(tmp_path / "bad.json", [{"id": 1, "file_name": "a.png", "width": 0, "height": 4}], [], [])
    assert not (tmp_path / "bad.json").exists()


def test_a_truncated_jpeg_is_a_dataset_error_naming_the_annotation(tmp_path):
    image = np.random.default_rng(0).integers(0, 256, (40, 60, 3), np.uint8)
    data = cv2.imencode(".jpg", image)[1].tobytes()
    path = _doc(tmp_path, images=[{"id": 1, "file_name": "b.jpg", "width": 60, "height": 40}])
    (tmp_path / "images" / "b.jpg").write_bytes(data[: len(data) // 2])
    ds = load_coco(path)
    with pytest.raises(DatasetError, match=r"ann.json: image id 1: .*b.jpg: truncated or corrupt JPEG"):
        ds.read_image(ds.images[0])
    with pytest.raises(DatasetError, match=r"ann.json: field images\[0\].file_name: .*b.jpg: truncated"):
        load_coco(path, check_images=True)
    (tmp_path / "images" / "b.jpg").write_bytes(data)
    assert ds.read_image(ds.images[0]).shape == (40, 60, 3)


def test_read_image_gives_bgr_uint8_or_gray(tmp_path):
    path = _doc(tmp_path)
    cv2.imwrite(str(tmp_path / "images" / "a.png"), np.full((40, 60), 257 * 9, np.uint16))  # gray, 16 bits
    ds = load_coco(path)
    bgr = ds.read_image(ds.images[0])
    assert bgr.shape == (40, 60, 3) and bgr.dtype == np.uint8 and (bgr == 9).all()
    gray = ds.read_image(ds.images[0], gray=True)
    assert gray.shape == (40, 60) and gray.dtype == np.uint8
