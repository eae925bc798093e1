"""Tests of the ALCN-2D-like detection benchmark generator."""

from __future__ import annotations

import json

import jsonschema
import numpy as np
import pytest

from alcn_cv.data import detect, detect_settings
from alcn_cv.data.detect import _tight_box
from alcn_cv.data.manifest import MANIFEST_SCHEMA
from alcn_cv.errors import InputError
from alcn_cv.formats import schema
from alcn_cv.formats.coco import load_coco
from alcn_cv.io import read_json


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    return detect.generate(tmp_path_factory.mktemp("det") / "small", conf="small", seed=1, n_test=5, progress=False)


def test_layout_manifest_and_schema(bench):
    man = json.loads((bench / "manifest.json").read_text())
    jsonschema.validate(man, read_json(MANIFEST_SCHEMA))
    assert man["kind"] == "detect" and man["seed"] == 1
    assert man["box_size"] == 36 and man["working_scale"] == pytest.approx(0.5)
    assert {o["material"] for o in man["objects"]} == {"matte", "velvet", "metal"}
    assert man["files"] == {"train": "train.json", "test": "test.json", "val": "val.json"}
    assert man["parameters"]["n_val"] == detect_settings.CONFS["small"].n_val == 2
    for name in ("train.json", "test.json", "val.json"):
        jsonschema.validate(json.loads((bench / name).read_text()), schema("coco"))


def test_loader_reads_what_the_generator_writes(bench):
    train = load_coco(bench / "train.json", check_images=True)
    test = load_coco(bench / "test.json", check_images=True)
    assert len(train.categories) == 3 and len(train.images) == 3 * 3
    counts = np.bincount([a.category_id for a in train.annotations], minlength=4)[1:]
    assert (counts == 3).all()  # n_train images per object, one object each
    assert len(test.images) == 5
    man = json.loads((bench / "manifest.json").read_text())
    for ds in (train, test):
        for im in ds.images:
            img = ds.read_image(im)
            assert img.shape == (200, 320, 3)
            for a in ds.annotations_for(im.id):
                side = max(a.bbox[2], a.bbox[3]) * man["working_scale"]
                assert 25 <= side <= 50  # about box_size at the working scale
    families = {im.extra["light_family"] for im in test.images}
    assert len(families) >= 2
    # Training images share one lighting.
    assert len({json.dumps(im.extra["lighting"]) for im in train.images}) == 1


def test_validation_images_are_test_like_and_none_is_a_test_image(bench):
    val = load_coco(bench / "val.json", check_images=True)
    test = load_coco(bench / "test.json")
    assert [im.file_name for im in val.images] == ["images/val/00000.png", "images/val/00001.png"]  # n_val of small
    assert all(im.extra["light_family"] and im.extra["lighting"] for im in val.images)
    assert {c.id for c in val.categories} == {c.id for c in test.categories}
    test_images = [test.read_image(im) for im in test.images]
    for im in val.images:
        img = val.read_image(im)
        assert img.shape == (200, 320, 3)
        assert not any(np.array_equal(img, t) for t in test_images), im.file_name


def test_the_validation_images_change_neither_training_nor_test_images(bench, tmp_path):
    # each split draws from its own random streams: more or no validation images, the same other bytes
    other = detect.generate(tmp_path / "val4", conf="small", seed=1, n_test=5, n_val=4, progress=False)
    assert len(load_coco(other / "val.json").images) == 4
    none = detect.generate(tmp_path / "none", conf="small", seed=1, n_test=5, n_val=0, progress=False)
    assert len(load_coco(none / "val.json").images) == 0
    files = sorted(p.relative_to(bench) for p in bench.rglob("*") if p.is_file())
    kept = [f for f in files if f.name not in ("val.json", "manifest.json") and f.parts[:2] != ("images", "val")]
    assert len(kept) == 2 + 3 * 3 + 5  # train.json, test.json, the training and test images
    for f in kept:
        assert (bench / f).read_bytes() == (other / f).read_bytes() == (none / f).read_bytes(), f
    # the first validation images are the same whatever their number
    for name in ("00000.png", "00001.png"):
        assert (bench / "images" / "val" / name).read_bytes() == (other / "images" / "val" / name).read_bytes()


def test_same_seed_gives_identical_bytes(bench, tmp_path):
    again = detect.generate(tmp_path / "again", conf="small", seed=1, n_test=5, progress=False)
    files = sorted(p.relative_to(bench) for p in bench.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(again) for p in again.rglob("*") if p.is_file())
    for f in files:
        assert (bench / f).read_bytes() == (again / f).read_bytes(), f


def test_bad_arguments(tmp_path):
    with pytest.raises(InputError):
        detect.generate(tmp_path / "x", conf="huge")
    with pytest.raises(InputError):
        detect.generate(tmp_path / "x", conf="small", width=100, progress=False)
    with pytest.raises(InputError):  # 0 was read as the preset's width
        detect.generate(tmp_path / "x", conf="small", width=0, progress=False)
    with pytest.raises(InputError, match="n_val=-1"):
        detect.generate(tmp_path / "x", conf="small", n_val=-1, progress=False)
    with pytest.raises(InputError, match="p_object"):
        detect.generate(tmp_path / "x", conf="small", p_object=1.5, progress=False)
    assert not (tmp_path / "x").exists()


def test_a_failed_run_leaves_nothing_behind(tmp_path, monkeypatch):
    calls = []

    def fail(*args, **kwargs):
        calls.append(1)
        raise RuntimeError("disk full")

    monkeypatch.setattr(detect, "_test_image", fail)
    with pytest.raises(RuntimeError, match="disk full"):
        detect.generate(tmp_path / "out", conf="small", n_train=1, progress=False)
    assert calls and list(tmp_path.iterdir()) == []


def test_workers_do_not_change_the_output(bench, tmp_path):
    two = detect.generate(tmp_path / "two", conf="small", seed=1, n_test=5, progress=False, workers=2)
    files = sorted(p.relative_to(bench) for p in bench.rglob("*") if p.is_file())
    for f in files:
        assert (bench / f).read_bytes() == (two / f).read_bytes(), f


def test_the_tight_box_holds_every_covered_pixel():
    """COCO ``[x, y, w, h]`` of the silhouette: pixels 3..7 across and 2..4 down are 5 wide and 3 high."""
    cov = np.zeros((10, 12), np.float32)
    cov[2:5, 3:8] = 1.0
    cov[6, 9] = 0.4  # under half covered: not the object's
    assert _tight_box(cov) == [3.0, 2.0, 5.0, 3.0]
    assert _tight_box(np.zeros((4, 4))) is None
