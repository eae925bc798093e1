"""What the scene loader (alcn_cv.data.scenes) tells about folders that are no usable registered scene: frames that
do not look registered, 12-bit data in 16-bit files, a scene path that names nothing."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from alcn_cv.data.scenes import (
    NARROW_16_BIT,
    REGISTERED_SCORE,
    WEBCAM_SCENES,
    load_scene_folder,
    read_eight_bits,
    registration_score,
    scene_dirs,
    shared_root,
)
from alcn_cv.errors import InputError
from scene_sets import lit, make_sets, texture


def _warnings(caplog) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]


def test_unrelated_photographs_of_one_size_are_warned_about(tmp_path, caplog):
    folder = tmp_path / "holiday"
    folder.mkdir()
    for i in range(4):  # four unrelated textures, each under its own light
        cv2.imwrite(str(folder / f"img_{i}.png"), lit(texture(seed=10 + i))[i % 3])
    root = make_sets(tmp_path / "sets")
    with caplog.at_level("WARNING"):
        (scene,) = load_scene_folder(folder)
        load_scene_folder(root / "webcam")
        load_scene_folder(root / "psm")
    assert registration_score(scene.frames) < REGISTERED_SCORE
    (message,) = _warnings(caplog)  # the registered scenes of make_sets pass
    assert "'holiday'" in message and "does not look registered" in message


def test_registration_score_of_a_scene_and_of_noise():
    frames = np.stack(lit(texture(seed=3)))
    assert registration_score(frames) > 0.8
    noise = np.random.default_rng(0).integers(0, 256, (3, 120, 160), dtype=np.uint8)
    assert registration_score(noise) < REGISTERED_SCORE


@pytest.mark.shared_data
def test_the_real_registered_scenes_pass_with_margin(shared_data):
    for data in ("webcam", "psm"):
        for scene in load_scene_folder(shared_data / data, max_frames=12):
            assert registration_score(scene.frames) > 2 * REGISTERED_SCORE, scene.name


def test_twelve_bit_frames_in_sixteen_bit_files_are_warned_about(tmp_path, caplog):
    deep, full = tmp_path / "deep", tmp_path / "full"
    for folder in (deep, full):
        folder.mkdir()
    for i, frame in enumerate(lit(texture())):
        cv2.imwrite(str(deep / f"{i}.png"), frame.astype(np.uint16) * 16)  # 12-bit values: at most 4080
        cv2.imwrite(str(full / f"{i}.png"), frame.astype(np.uint16) * 257)
    with caplog.at_level("WARNING"):
        load_scene_folder(full)
        assert not _warnings(caplog)
        load_scene_folder(deep)
    (message,) = _warnings(caplog)  # one line for the scene
    top = int(max(f.max() for f in lit(texture()))) * 16
    assert "scene 'deep'" in message and f"maximum of {top}" in message and ".png" in message


def test_the_dark_frames_of_a_sixteen_bit_scene_are_not_warned_about(tmp_path, caplog):
    """Every frame whose maximum was below 4096 was warned of: a multi-light scene has dark frames by design. The
    scene's maximum counts; a single photograph is warned of by its own (17 grey levels at 4095: 0 to 16)."""
    folder = tmp_path / "lights"
    folder.mkdir()
    base = texture()
    for i, top in enumerate((65535, 3000, 1000)):  # one bright frame, two dark ones
        cv2.imwrite(str(folder / f"{i}.png"), np.rint(base * top).astype(np.uint16))
    with caplog.at_level("WARNING"):
        (scene,) = load_scene_folder(folder)
    assert len(scene.frames) == 3 and not _warnings(caplog)
    dark = tmp_path / "dark.png"
    cv2.imwrite(str(dark), np.rint(base * (NARROW_16_BIT - 1)).astype(np.uint16))
    with caplog.at_level("WARNING"):
        read_eight_bits(dark)
    (message,) = _warnings(caplog)
    assert str(dark) in message and "maximum of 4095" in message and "keeps 17 grey levels (0 to 16)" in message


def test_a_misspelt_scene_is_neither_a_folder_nor_a_webcam_scene(tmp_path, monkeypatch):
    with pytest.raises(InputError, match="frankfrut: neither a folder nor a webcam scene") as err:
        scene_dirs(["frankfrut"])
    assert all(name in str(err.value) for name in WEBCAM_SCENES) and "\n" not in str(err.value)
    with pytest.raises(InputError, match="neither a folder"):
        scene_dirs([str(tmp_path / "missing")])
    (tmp_path / "home" / "mine").mkdir(parents=True)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert scene_dirs(["~/mine", "mexico"]) == [tmp_path / "home" / "mine", shared_root("webcam") / "mexico"]


def test_a_sixteen_bit_maximum_of_exactly_4096_is_not_warned_about(tmp_path, caplog):
    """The warning is for a maximum *below* :data:`NARROW_16_BIT` (less than a sixteenth of the range); a ``<=``
    warned of an image that reaches it."""
    base = texture()
    edge = tmp_path / "edge.png"
    image = np.rint(base * NARROW_16_BIT).astype(np.uint16)
    assert image.max() == NARROW_16_BIT
    cv2.imwrite(str(edge), image)
    with caplog.at_level("WARNING"):
        read_eight_bits(edge)
    assert not _warnings(caplog)
