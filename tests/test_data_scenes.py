"""The loader of registered multi-light scenes (alcn_cv.data.scenes)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from alcn_cv.data.scenes import (
    TEST_SCENES,
    TRAIN_SCENES,
    Scene,
    load_scene_folder,
    load_scenes,
    mean_pairwise_ncc,
    scene_dirs,
    scene_names,
    select_scenes,
    shared_root,
)
from alcn_cv.errors import DatasetError, InputError
from scene_sets import make_sets


def test_loader_layouts(tmp_path):
    root = make_sets(tmp_path)
    webcam = load_scene_folder(root / "webcam")
    assert [s.name for s in webcam] == ["square", "street"] and webcam[0].group == "webcam"
    assert webcam[0].frames.shape == (3, 120, 160) and webcam[0].frames.dtype == np.uint8
    (ball,) = load_scene_folder(root / "psm")
    assert ball.name == "ball" and ball.files == ("ball.0.png", "ball.1.png", "ball.2.png", "ball.10.png")  # no mask
    (flat,) = load_scene_folder(root / "psm" / "ball")  # the same files in the root itself, grouped by NAME
    assert flat.name == "ball" and len(flat.frames) == 4
    assert load_scene_folder(root / "psm", max_frames=2)[0].files == ("ball.0.png", "ball.10.png")  # evenly spaced
    scenes = load_scenes([root / "webcam", root / "psm"])
    assert [s.name for s in select_scenes(scenes, ["psm", "street"])] == ["ball", "street"]
    with pytest.raises(InputError):
        select_scenes(scenes, ["mexico"])
    # a comma list, as --methods takes, where the scene options take words: the way out named
    with pytest.raises(InputError, match=r"'street,psm' \(scenes are given apart: street psm\); available: "):
        select_scenes(scenes, ["street,psm"])
    with pytest.raises(DatasetError):
        load_scenes([root / "psm", root / "psm"])  # duplicate names
    with pytest.raises(DatasetError):
        load_scene_folder(root / "psm" / "notes")
    with pytest.raises(DatasetError):
        load_scene_folder(tmp_path / "missing")


def test_a_scene_folder_and_a_folder_of_scenes(tmp_path):
    """The trainer's entries: one scene's folder (its own frames), or a folder of scene folders."""
    root = make_sets(tmp_path)
    (street,) = load_scene_folder(root / "webcam" / "street")
    (same,) = select_scenes(load_scene_folder(root / "webcam"), ["street"])
    assert (street.name, street.files) == (same.name, same.files)
    np.testing.assert_array_equal(street.frames, same.frames)
    (root / "webcam" / "manifest.json").write_text("{}")  # what `alcn data scenes` writes beside the scenes
    assert [s.name for s in load_scene_folder(root / "webcam")] == ["square", "street"]
    single = tmp_path / "single"
    single.mkdir()
    cv2.imwrite(str(single / "a.png"), np.zeros((40, 40), np.uint8))
    with pytest.raises(DatasetError):
        load_scene_folder(single)
    with pytest.raises(InputError):
        load_scene_folder(root / "webcam", max_frames=1)


def test_unit_frames_are_every_image_in_name_order_over_255(tmp_path):
    """The trainer's frames: each image of the folder, grayscale, in name order, divided by 255."""
    folder = tmp_path / "scene_000"
    folder.mkdir()
    rng = np.random.default_rng(0)
    images = [rng.integers(0, 256, (20, 24, 3), dtype=np.uint8) for _ in range(3)]
    for i, image in enumerate(images):
        cv2.imwrite(str(folder / f"frame_{i:02d}.png"), image)
    (scene,) = load_scene_folder(folder)
    unit = scene.unit_frames()
    expected = np.stack([cv2.cvtColor(im, cv2.COLOR_BGR2GRAY) for im in images]).astype(np.float32) / np.float32(255)
    assert unit.dtype == np.float32
    np.testing.assert_array_equal(unit, expected)


def test_sixteen_bit_frames_are_rounded_to_eight(tmp_path):
    """Every 16-bit value x to round(x / 257) (:func:`alcn_cv.io.eight_bits`)."""
    folder = tmp_path / "deep"
    folder.mkdir()
    every = np.arange(65536, dtype=np.uint16).reshape(256, 256)
    for i, frame in enumerate((every, every[::-1])):  # a scene has two frames or more
        cv2.imwrite(str(folder / f"{i}.png"), frame)
    np.testing.assert_array_equal(load_scene_folder(folder)[0].frames[0], np.rint(every / 257).astype(np.uint8))


def test_scene_dirs_are_folders_or_shared_webcam_scenes(tmp_path):
    assert not set(TRAIN_SCENES) & set(TEST_SCENES)
    dirs = scene_dirs()
    assert [d.name for d in dirs] == list(TRAIN_SCENES) and all(d.parent == shared_root("webcam") for d in dirs)
    assert scene_dirs([tmp_path, "mexico"]) == [tmp_path, shared_root("webcam") / "mexico"]


@pytest.mark.shared_data
def test_shared_scenes(shared_data):
    scenes = load_scenes([shared_data / "webcam", shared_data / "psm"], max_frames=3)
    names = {s.name for s in scenes}
    assert set(TRAIN_SCENES) <= names and "mexico" in names
    assert {s.name for s in select_scenes(scenes, ["psm"])} == {"buddha", "cat", "horse", "owl"}
    assert all(len(s.frames) == 3 and s.frames.dtype == np.uint8 for s in scenes)


def test_scene_names_are_the_loaders_without_reading_an_image(tmp_path, monkeypatch):
    """The bench named a weight file's scene folders itself, counting hidden files and one-frame scenes."""
    root = make_sets(tmp_path)
    psm = root / "psm"
    for name in (".ghost.0.png", ".ghost.1.png", "lone.0.png"):  # hidden files; a scene of one frame
        cv2.imwrite(str(psm / "ball" / name), np.zeros((40, 40), np.uint8))
    (psm / ".hidden").mkdir()
    for i in range(2):
        cv2.imwrite(str(psm / ".hidden" / f"{i}.png"), np.zeros((40, 40), np.uint8))
    for folder in (root / "webcam", psm, psm / "ball"):
        loaded = [s.name for s in load_scene_folder(folder)]
        monkeypatch.setattr("alcn_cv.data.scenes.read_image", None)  # names from the file names alone
        assert scene_names(folder) == loaded
        monkeypatch.undo()
    assert scene_names(psm / "ball", subfolders=False) == ["ball"] and scene_names(tmp_path / "missing") == []


def test_a_scene_named_twice_is_selected_once():
    """``["psm", "ball"]``: the data set and one of its scenes name the ball once (a repeat would weigh it twice in
    training)."""
    frames = np.zeros((2, 4, 4), np.uint8)
    scenes = [Scene("ball", "psm", frames, ("a", "b")), Scene("cat", "psm", frames, ("a", "b"))]
    assert [s.name for s in select_scenes(scenes, ["psm", "ball"])] == ["ball", "cat"]
    assert [s.name for s in select_scenes(scenes, ["ball", "ball"])] == ["ball"]


def test_mean_pairwise_ncc_ignores_a_gain_and_an_offset():
    """1 for images that agree up to a gain and an offset, -1 for a negative, 0 for a constant one."""
    rng = np.random.default_rng(0)
    a = rng.random((16, 16)).astype(np.float32)
    mask = np.ones((16, 16), bool)
    assert mean_pairwise_ncc([a, 0.5 * a + 0.3], mask) == pytest.approx(1.0)
    assert mean_pairwise_ncc([a, 1.0 - a], mask) == pytest.approx(-1.0)
    assert mean_pairwise_ncc([a, np.full_like(a, 0.7)], mask) == 0.0


def test_a_photometric_set_at_a_scale_keeps_its_masks_on_its_images(tmp_path):
    """``scale`` resizes the images and the masks alike: a mask resized to (h, w) where the images are (w, h) (a
    swapped size, unseen on square objects) would no longer lie on its object, or not even have its images' shape."""
    from alcn_cv.data.scenes import load_photometric

    folder = tmp_path / "psm" / "ball"
    folder.mkdir(parents=True)
    rng = np.random.default_rng(0)
    images = [rng.integers(0, 256, (40, 60), dtype=np.uint8) for _ in range(2)]
    for i, image in enumerate(images):
        cv2.imwrite(str(folder / f"ball.{i}.png"), image)
    mask = np.zeros((40, 60), np.uint8)
    mask[4:20, 10:50] = 255
    cv2.imwrite(str(folder / "ball.mask.png"), mask)
    (obj,) = load_photometric(tmp_path / "psm", scale=0.5)
    assert obj.images.shape == (2, 20, 30) and obj.mask.shape == (20, 30)
    expected = np.zeros((20, 30), bool)
    expected[2:10, 5:25] = True
    np.testing.assert_array_equal(obj.mask, expected)
    area = cv2.resize(images[1], (30, 20), interpolation=cv2.INTER_AREA)
    np.testing.assert_array_equal(obj.images[1], area.astype(np.float32) / np.float32(255))
