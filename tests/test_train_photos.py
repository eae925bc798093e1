"""Training the gain Normalizer on your own photographs: ``alcn train-real-light --set photos=[...]``
(alcn_cv.train.config.RealLightConfig.photos, alcn_cv.data.permissive_images.folder_photographs)."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest

from alcn_cv.data.permissive_images import USER_LICENCE, Photograph, folder_photographs, relit_scenes
from alcn_cv.data.scenes import Scene
from alcn_cv.errors import DatasetError, InputError
from alcn_cv.presets import preset
from alcn_cv.train.config import REAL_LIGHT_CONFS, RealLightConfig

CROP, PATCH = 96, 32


def _photo(h: int = 120, w: int = 130, seed: int = 0) -> np.ndarray:
    """A textured uint8 photograph ``(h, w)``."""
    noise = np.random.default_rng(seed).random((h, w)).astype(np.float32)
    return np.rint(255 * cv2.normalize(cv2.GaussianBlur(noise, (0, 0), 2.0), None, 0, 1, cv2.NORM_MINMAX)).astype(
        np.uint8
    )


def _folder(path, count: int = 2, h: int = 120, w: int = 130):
    path.mkdir(parents=True)
    for i in range(count):
        cv2.imwrite(str(path / f"p{i}.png"), _photo(h, w, seed=i))
    return path


@pytest.fixture
def shipped(monkeypatch):
    """Two stand-ins for the permissive photographs (reading the real ones takes seconds)."""
    from alcn_cv.train import real_light

    photos = [Photograph(f"shipped{i}", _photo(110, 120, seed=10 + i), "CC0", "test") for i in range(2)]
    monkeypatch.setattr(real_light, "training_photographs", lambda shared: photos)
    return photos


def test_every_format_depth_and_colour_is_read_as_eight_bits(tmp_path, caplog):
    folder = tmp_path / "mine"
    folder.mkdir()
    gray = _photo()
    colour = np.dstack([gray, gray[::-1], gray[:, ::-1]])
    cv2.imwrite(str(folder / "a.jpg"), colour)
    cv2.imwrite(str(folder / "b.png"), gray.astype(np.uint16) * 257)  # 16-bit, the whole range
    cv2.imwrite(str(folder / "c.tif"), colour.astype(np.uint16) * 257)
    cv2.imwrite(str(folder / "d.bmp"), gray)
    (folder / "notes.txt").write_text("not an image")
    with caplog.at_level("WARNING"):
        photos = folder_photographs([folder], min_side=CROP)
    assert [p.name for p in photos] == ["mine/a.jpg", "mine/b.png", "mine/c.tif", "mine/d.bmp"]
    assert all(p.image.dtype == np.uint8 and p.licence == USER_LICENCE for p in photos)
    assert [p.image.ndim for p in photos] == [3, 2, 3, 2]  # colour kept: the light's colour relights it
    np.testing.assert_array_equal(photos[1].image, gray)
    np.testing.assert_array_equal(photos[2].image, colour)
    assert not caplog.records


def test_twelve_bit_photographs_are_warned_about(tmp_path, caplog):
    folder = tmp_path / "deep"
    folder.mkdir()
    cv2.imwrite(str(folder / "raw.png"), (_photo().astype(np.uint16) * 16).clip(0, 4095))  # 12-bit data
    with caplog.at_level("WARNING"):
        folder_photographs([folder])
    assert any("raw.png" in r.getMessage() and "maximum of 4080" in r.getMessage() for r in caplog.records)


def test_photos_are_relit_after_the_shipped_ones_which_stay_as_they_were(tmp_path, shipped):
    from alcn_cv.train.real_light import training_scenes

    folder = _folder(tmp_path / "mine")
    base = RealLightConfig(relit=3, crop=CROP, patch=PATCH, seed=5)
    alone, _ = training_scenes(base)
    both, _ = training_scenes(dataclasses.replace(base, photos=[str(folder)]))
    assert [s.name for s in both] == ["00_shipped0", "01_shipped1", "02_mine_p0_png", "03_mine_p1_png"]
    for a, b in zip(alone, both):
        np.testing.assert_array_equal(a.frames, b.frames)
    # the user's photographs relit exactly as a shipped one would be in their place
    expected = relit_scenes([*shipped, *folder_photographs([folder])], 3, 5)[2]
    inside = (slice(None), slice(CROP // 2, -CROP // 2), slice(CROP // 2, -CROP // 2))  # the padding left out
    np.testing.assert_array_equal(both[2].frames[inside], expected.unit_frames())

    mine, _ = training_scenes(dataclasses.replace(base, photos=[str(folder)], shipped_photos=False))
    assert [s.name for s in mine] == ["00_mine_p0_png", "01_mine_p1_png"]


def test_photo_folders_expand_the_home_and_start_from_the_working_folder(tmp_path, monkeypatch, shipped):
    from alcn_cv.train.real_light import training_scenes

    _folder(tmp_path / "home" / "mine", count=1)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.chdir(tmp_path / "home")
    for given in ("~/mine", "mine", "./mine"):
        cfg = RealLightConfig(relit=2, crop=CROP, patch=PATCH, photos=[given], shipped_photos=False)
        cfg.check()
        assert [s.name for s in training_scenes(cfg)[0]] == ["00_mine_p0_png"]


def test_bad_photo_folders_and_files_are_one_line_errors(tmp_path, shipped):
    from alcn_cv.train.real_light import training_scenes

    (tmp_path / "empty").mkdir()
    (tmp_path / "empty" / "readme.txt").write_text("no images here")
    cases = {"missing": "folder not found", "empty": "no image"}
    for name, match in cases.items():
        cfg = RealLightConfig(relit=2, photos=[str(tmp_path / name)])
        for run in (cfg.check, lambda cfg=cfg: training_scenes(cfg)):
            with pytest.raises(InputError, match=f"photos: .*{name}: {match}") as err:
                run()
            assert "\n" not in str(err.value)
    broken = _folder(tmp_path / "broken", count=1)
    (broken / "zz.png").write_bytes(b"\x89PNG\r\n\x1a\nnot really")
    RealLightConfig(relit=2, photos=[str(broken)]).check()  # listed, not read
    with pytest.raises(InputError, match="zz.png"):
        training_scenes(RealLightConfig(relit=2, crop=CROP, patch=PATCH, photos=[str(broken)]))
    small = _folder(tmp_path / "small", count=1, h=90, w=300)
    with pytest.raises(InputError, match=r"p0.png: 300x90 pixels, .*at least 96x96 pixels \(crop=96\)"):
        training_scenes(RealLightConfig(relit=2, crop=CROP, patch=PATCH, photos=[str(small)]))
    wide = _folder(tmp_path / "wide", count=1, h=100, w=1000)  # fitted to 640: 64 high
    with pytest.raises(InputError, match=r"1000x100 pixels \(640x64 once its longer side is brought to 640"):
        training_scenes(RealLightConfig(relit=2, crop=CROP, patch=PATCH, photos=[str(wide)]))


def test_the_settings_of_photos_are_checked(tmp_path):
    folder = _folder(tmp_path / "mine", count=1)
    with pytest.raises(InputError, match="relit >= 2"):
        RealLightConfig(relit=0, photos=[str(folder)]).check()
    with pytest.raises(InputError, match="no scenes given"):
        RealLightConfig(shipped_photos=False).check()
    RealLightConfig(shipped_photos=False, photos=[str(folder)]).check()
    cfg = preset(REAL_LIGHT_CONFS, "gain", [f"photos=['{folder}']", "shipped_photos=false"])
    assert (cfg.photos, cfg.shipped_photos, cfg.relit) == ([str(folder)], False, 4)
    with pytest.raises(InputError, match="'photos' must be a list"):
        preset(REAL_LIGHT_CONFS, "gain", [f"photos={folder}"])
    assert REAL_LIGHT_CONFS["gain"].photos == [] and REAL_LIGHT_CONFS["gain"].shipped_photos


def test_the_weight_file_records_no_absolute_path_of_the_machine(tmp_path, monkeypatch):
    """The weight file, which users share, recorded the folders absolute (`/home/<user>/...`) as the checkpoint does:
    it records them as given, a path under the home folder written from ~; the checkpoint, absolute."""
    import json

    import torch

    from alcn_cv.train.checkpoint import load_checkpoint
    from alcn_cv.train.real_light import train_real_light
    from alcn_cv.weight_file import load_normalizer_file
    from scene_sets import write_scene

    torch.set_num_threads(1)
    home = tmp_path / "home"
    _folder(home / "work" / "mine")
    write_scene(home / "rendered", 3, 120, 136, gamma=None, noise=0.2)
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.chdir(home / "work")
    cfg = RealLightConfig(
        photos=["mine"],
        shipped_photos=False,
        rendered=[str(home / "rendered")],  # absolute, as typed
        rendered_fraction=0.5,
        relit=2,
        steps=2,
        save_every=2,
        locations=8,
        min_distance=8,
        crop=CROP,
        patch=PATCH,
        net={"channels": 8},
    )
    meta = load_normalizer_file(train_real_light(cfg, tmp_path / "run", progress=False)).meta
    config = meta["training"]["config"]
    assert (config["photos"], config["rendered"], config["shipped_photos"]) == (["mine"], ["~/rendered"], False)
    assert str(tmp_path) not in json.dumps(meta)
    saved = load_checkpoint(tmp_path / "run" / "checkpoint.pt")["config"]
    assert (saved["photos"], saved["rendered"]) == ([str(home / "work" / "mine")], [str(home / "rendered")])


def test_frames_smaller_than_the_crop_or_the_patches_name_the_scene():
    from alcn_cv.train.real_light import training_scene

    frames = np.stack([_photo(80, 90, seed=i) for i in range(2)])
    scene = Scene("street", "webcam", frames, ("a.png", "b.png"))
    with pytest.raises(DatasetError, match=r"scene 'street': frames of 90x80 .*crop=96.*at least 96x96"):
        training_scene(scene, CROP // 2, PATCH, CROP)
    with pytest.raises(DatasetError, match=r"scene 'street': frames of 90x80 .*the 100x100 patches"):
        training_scene(scene, CROP // 2, 100)
    assert len(training_scene(scene, CROP // 2, PATCH).frames) == 2  # no crop given: the patches' bound only


def _warnings(caplog) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]


def test_a_photograph_without_texture_is_an_error_naming_it(tmp_path, shipped):
    """A uniform image trained silently on its relit copies' noise (a loss of 6.6 where real runs log 0.7-0.9)."""
    from alcn_cv.train.real_light import training_scenes

    folder = _folder(tmp_path / "mine")
    cv2.imwrite(str(folder / "grey.png"), np.full((130, 130), 128, np.uint8))
    with pytest.raises(InputError, match=r"photos: .*grey\.png: no texture: .*fewer than 2 of its 32x32 windows") as e:
        training_scenes(RealLightConfig(relit=2, crop=CROP, patch=PATCH, photos=[str(folder)]))
    assert "\n" not in str(e.value)


def test_a_photograph_with_almost_no_texture_is_warned_about(tmp_path, shipped, caplog):
    from alcn_cv.train.real_light import TEXTURED_SHARE, textured_share, training_scenes

    folder = _folder(tmp_path / "mine")
    # a wall lit from one side: a gradient everywhere (no error), under a grey level per pixel
    ramp = np.tile(np.linspace(60, 120, 130), (130, 1)).round().astype(np.uint8)
    cv2.imwrite(str(folder / "wall.png"), ramp)
    assert textured_share(ramp, PATCH) < TEXTURED_SHARE <= textured_share(_photo(), PATCH)
    with caplog.at_level("WARNING"):
        training_scenes(RealLightConfig(relit=2, crop=CROP, patch=PATCH, photos=[str(folder)]))
    (warning,) = _warnings(caplog)
    assert warning.startswith(f"photos: {folder / 'wall.png'}: almost no texture: ")
    assert "of its 32x32 windows reach an RMS gradient of 1 grey level per pixel (warned below 10%)" in warning


def test_a_photograph_twice_and_a_single_one_are_warned_about(tmp_path, shipped, caplog):
    from alcn_cv.train.real_light import training_scenes

    folder = _folder(tmp_path / "mine")
    cv2.imwrite(str(folder / "q.png"), _photo(seed=1))  # p1.png's pixels
    cv2.imwrite(str(folder / "theirs.png"), shipped[0].image)  # a shipped photograph's
    cfg = RealLightConfig(relit=2, crop=CROP, patch=PATCH, photos=[str(folder)])
    with caplog.at_level("WARNING"):
        scenes, _ = training_scenes(cfg)
    assert len(scenes) == 2 + 4  # warned about, not left out: the user may mean it
    assert _warnings(caplog) == [
        f"photos: {folder / 'q.png'}: the same pixels as {folder / 'p1.png'}: each copy is a scene of its own, "
        "drawn as often as any other photograph",
        f"photos: {folder / 'theirs.png'}: the same pixels as the shipped photograph shipped0: each copy is a scene of "
        "its own, drawn as often as any other photograph",
    ]

    single = _folder(tmp_path / "one", count=1)
    for shipped_photos, detail in (
        (True, "one of the 3 scenes each step draws from"),
        (False, "every step draws the same scene, its relit copies (shipped_photos=false and no scenes)"),
    ):
        caplog.clear()
        with caplog.at_level("WARNING"):
            training_scenes(dataclasses.replace(cfg, photos=[str(single)], shipped_photos=shipped_photos))
        assert _warnings(caplog) == [f"photos: a single photograph of yours, {single / 'p0.png'}: {detail}"]


def test_the_warning_about_a_single_photograph_counts_the_rendered_scenes(tmp_path, shipped, caplog):
    """With rendered scenes, it said every step drew the single photograph (shipped_photos=false and no scenes) though
    rendered_fraction of the steps draw a rendered scene."""
    from alcn_cv.train.real_light import training_scenes
    from scene_sets import write_scene

    single = _folder(tmp_path / "one", count=1)
    rendered = write_scene(tmp_path / "rendered", 3, 120, 136, gamma=None, noise=0.2)
    cfg = RealLightConfig(relit=2, crop=CROP, patch=PATCH, photos=[str(single)], rendered=[str(rendered)])
    steps = "the steps that draw no rendered scene (75% of them)"
    same = "its relit copies (shipped_photos=false and no scenes)"
    for shipped_photos, detail in (
        (True, f"one of the 3 scenes {steps} draw from"),
        (False, f"{steps} all draw the same scene, {same}"),
    ):
        caplog.clear()
        with caplog.at_level("WARNING"):
            training_scenes(dataclasses.replace(cfg, shipped_photos=shipped_photos, rendered_fraction=0.25))
        assert _warnings(caplog) == [f"photos: a single photograph of yours, {single / 'p0.png'}: {detail}"]
    caplog.clear()
    with caplog.at_level("WARNING"):
        training_scenes(dataclasses.replace(cfg, shipped_photos=False))  # rendered_fraction 0: none drawn
    assert _warnings(caplog)[0].endswith(f"{single / 'p0.png'}: every step draws the same scene, {same}")


def test_the_shipped_photographs_pass_the_texture_rule(shared_data):
    """The rule warns about the user's photographs only; the shipped ones, which the recipe trains on, pass it."""
    from alcn_cv.data.permissive_images import training_photographs
    from alcn_cv.train.real_light import TEXTURED_SHARE, textured_share

    shares = {p.name: textured_share(p.image, RealLightConfig.patch) for p in training_photographs(shared_data)}
    assert min(shares.values()) >= TEXTURED_SHARE, shares


def test_a_file_given_for_a_folder_of_photos_says_so(tmp_path):
    folder = _folder(tmp_path / "mine", count=1)
    with pytest.raises(InputError) as e:
        RealLightConfig(relit=2, photos=[str(folder / "p0.png")]).check()
    assert str(e.value) == (
        f"photos: {folder / 'p0.png'}: a file, not a folder: photos lists folders, and every image directly in each is "
        f"trained on; give its folder (photos=['{folder}']) or put the photographs meant in one of their own"
    )


def test_a_phones_or_a_cameras_photographs_that_opencv_cannot_read_are_named(tmp_path, caplog):
    """A folder of a JPEG, a HEIC and a DNG trained on the JPEG alone; only a warning about a single photograph hinted
    that the others were skipped."""
    folder = _folder(tmp_path / "phone", count=1)
    for name in ("IMG_0001.HEIC", "IMG_0002.dng", "notes.txt"):
        (folder / name).write_bytes(b"not read")
    with caplog.at_level("WARNING"):
        photos = folder_photographs([folder])
    assert [p.name for p in photos] == ["phone/p0.png"]
    assert f"photos: {folder}: IMG_0001.HEIC, IMG_0002.dng skipped: not an image OpenCV reads here" in caplog.text


def test_a_folder_of_heic_photographs_alone_says_so(tmp_path):
    folder = tmp_path / "phone"
    folder.mkdir()
    (folder / "IMG_0001.HEIC").write_bytes(b"not read")
    with pytest.raises(InputError, match=r"no image .* in this folder; IMG_0001.HEIC: not read here \(convert them"):
        folder_photographs([folder])
