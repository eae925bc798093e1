"""Tests of contact sheets, the PSM comparison and the ``alcn data`` command."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from alcn_cv.cli import main
from alcn_cv.data import detect, phos, pose, relief_scenes
from alcn_cv.data.preview import preview
from alcn_cv.data.stats import compare_psm, image_stats
from alcn_cv.errors import DatasetError, InputError


def test_contact_sheets_of_every_kind(tmp_path):
    d = detect.generate(tmp_path / "det", conf="small", n_test=2, n_train=1, progress=False)
    p = phos.generate(tmp_path / "phos", 40, 0, n_objects=3, progress=False)
    s = pose.generate(tmp_path / "pose", conf="small", n_frames=1, n_test=1, progress=False)
    for src in (d, d / "test.json", p, s, s / "test" / "000001"):
        out = preview(src, tmp_path / "sheet.png", n=4, overwrite=True)
        img = cv2.imread(str(out))
        assert img is not None and img.shape[0] > 100 and img.std() > 10
    # Boxes are drawn in the category colours: the sheet of a COCO file with objects has pure green.
    sheet = cv2.imread(str(preview(d / "train.json", tmp_path / "t.png", n=3)))
    assert ((sheet == (0, 255, 0)).all(-1)).sum() > 20
    with pytest.raises(DatasetError, match="not a dataset"):
        preview(tmp_path, tmp_path / "x.png")


def test_image_stats():
    g = np.zeros((32, 32), np.float32)
    g[:, 16:] = 1.0
    st = image_stats(g, np.ones_like(g, bool))
    assert st["mean"] == pytest.approx(0.5) and st["saturated"] == pytest.approx(0.5)
    assert st["black"] == pytest.approx(0.5) and st["dynamic_range"] == pytest.approx(1.0)
    with pytest.raises(DatasetError):
        image_stats(g, np.zeros_like(g, bool))


@pytest.mark.shared_data
def test_compare_psm(shared_data, tmp_path):
    stats = compare_psm(shared_data / "psm", tmp_path)
    assert set(stats) == {"real psm", "engine psm lights", "engine psm lights plain albedo", "engine light families"}
    for name in ("psm_comparison.png", "psm_comparison.md", "psm_comparison.json"):
        assert (tmp_path / name).stat().st_size > 100
    text = (tmp_path / "psm_comparison.md").read_text()  # the table was bare: no title, data, seed or definitions
    assert text.startswith("# Real photometric-stereo photographs") and "seed 0" in text
    assert "dynamic range (99th" in text
    # The random lighting families change appearance more than the 12 near-frontal PSM lights.
    assert (
        stats["engine light families"]["across_lights_pairwise_ncc"]["mean"]
        < stats["real psm"]["across_lights_pairwise_ncc"]["mean"]
    )


def test_cli(tmp_path, capsys):
    assert (
        main(["data", "detect", "--conf", "small", "--n-test", "1", "--n-train", "1", "--out", str(tmp_path / "d")])
        == 0
    )
    assert main(["data", "preview", str(tmp_path / "d"), "--out", str(tmp_path / "p.png")]) == 0
    assert (tmp_path / "p.png").exists()
    assert main(["data", "phos", "-n", "5", "--objects", "2", "--out", str(tmp_path / "w")]) == 0
    assert main(["data", "preview", str(tmp_path / "missing"), "--out", str(tmp_path / "q.png")]) == 2
    assert f"{tmp_path / 'missing'}: no such file or folder" in capsys.readouterr().err
    assert main(["data", "detect", "--conf", "small", "--out", str(tmp_path / "d")]) == 2  # exists


def _tiles(sheet_path, tile_h, tile_w, pad=2):
    """(rows, columns) of a contact sheet of tiles of ``tile_h`` x ``tile_w`` pixels."""
    h, w = cv2.imread(str(sheet_path)).shape[:2]
    assert (h - pad) % (tile_h + pad) == 0 and (w - pad) % (tile_w + pad) == 0, (h, w)
    return (h - pad) // (tile_h + pad), (w - pad) // (tile_w + pad)


def test_n_is_how_many_samples_a_sheet_shows(tmp_path):
    """-n is what a sheet shows, without empty columns: the frames of one pose sequence (was: a strip of 16
    columns, 13 empty), as many frames of every sequence of a pose root (was: one each whatever -n), Phos windows
    (was: at least 32)."""
    s = pose.generate(tmp_path / "pose", conf="small", n_frames=2, n_test=2, progress=False)  # 320x240 frames
    assert _tiles(preview(s / "test" / "000001", tmp_path / "a.png", n=16), 240, 320) == (1, 2)
    assert _tiles(preview(s, tmp_path / "b.png", n=6), 240, 320) == (2, 4)  # 3 sequences, 2 frames each
    assert _tiles(preview(s, tmp_path / "c.png", n=1), 240, 320) == (1, 3)  # at least one frame a sequence
    p = phos.generate(tmp_path / "phos", 40, 0, n_objects=3, progress=False)
    assert _tiles(preview(p, tmp_path / "d.png", n=4), 128, 128) == (1, 4)
    assert _tiles(preview(p, tmp_path / "e.png", n=12), 128, 128) == (2, 8)
    with pytest.raises(InputError, match=r"\(-n\) must be at least 1"):
        preview(p, tmp_path / "f.png", n=0)


def test_a_sheet_of_rendered_scenes_and_of_an_unknown_kind(tmp_path):
    """The folders of `alcn data scenes` are previewed (a few frames of a few scenes, a row each); another kind's
    error names the kinds previewed."""
    out = relief_scenes.generate(tmp_path / "scenes", scenes=3, frames=3, side=32, progress=False)
    sheet = preview(out, tmp_path / "s.png", n=4)
    assert _tiles(sheet, 256, 256) == (2, 2) and cv2.imread(str(sheet)).std() > 10
    sheet = preview(out, tmp_path / "t.png", n=16)  # 4 scenes of 4 frames asked, 3 of 3 there: a scene a row
    assert _tiles(sheet, 256, 256) == (3, 3)
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "manifest.json").write_text(
        json.dumps({"generator_version": "1", "kind": "other", "seed": 0, "parameters": {}})
    )
    with pytest.raises(DatasetError, match="unknown dataset kind 'other'; .*phos, detect, pose, relief_scenes"):
        preview(tmp_path / "other", tmp_path / "o.png")


def test_compare_psm_names_a_missing_folder_and_checks_its_output_first(tmp_path):
    with pytest.raises(DatasetError, match=r"nope: folder not found; a photometric-stereo set"):  # not lights.txt
        compare_psm(tmp_path / "nope", tmp_path / "out")
    blocker = tmp_path / "file.json"
    blocker.write_text("mine")
    with pytest.raises(InputError, match="is a file"):  # before reading the set and rendering
        compare_psm(tmp_path / "nope", blocker / "out")
    earlier = tmp_path / "earlier"
    earlier.mkdir()
    (earlier / "psm_comparison.md").write_text("an earlier comparison")
    with pytest.raises(InputError, match=r"psm_comparison.md exists \(--overwrite replaces it\)"):  # before the work
        compare_psm(tmp_path / "nope", earlier)


def test_load_psm_reads_the_photometric_set_and_checks_its_lights(tmp_path):
    from alcn_cv.data.scenes import load_photometric
    from alcn_cv.data.stats import load_psm

    folder = tmp_path / "psm" / "ball"
    folder.mkdir(parents=True)
    rng = np.random.default_rng(0)
    for i in range(2):
        cv2.imwrite(str(folder / f"ball.{i}.png"), rng.integers(0, 256, (12, 16), dtype=np.uint8))
    cv2.imwrite(str(folder / "ball.mask.png"), np.full((12, 16), 255, np.uint8))
    (tmp_path / "psm" / "lights.txt").write_text("2\n0 0 1\n0.5 0 0.8\n")
    objects, lights = load_psm(tmp_path / "psm")
    (obj,) = load_photometric(tmp_path / "psm")
    assert lights.shape == (2, 3) and list(objects) == ["ball"]
    assert np.array_equal(np.stack(objects["ball"][0]), obj.images) and objects["ball"][1].all()
    (tmp_path / "psm" / "lights.txt").write_text("3\n0 0 1\n0.5 0 0.8\n0 0.5 0.8\n")
    with pytest.raises(DatasetError, match="ball: 2 images, but lights.txt lists 3 lights"):
        load_psm(tmp_path / "psm")
