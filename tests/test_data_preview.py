"""Tests of contact sheets, the PSM comparison and the ``alcn data`` command."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from alcn_cv.cli import main
from alcn_cv.data import detect, phos, pose
from alcn_cv.data.preview import preview
from alcn_cv.data.stats import compare_psm, image_stats
from alcn_cv.errors import DatasetError


def test_contact_sheets_of_every_kind(tmp_path):
    d = detect.generate(tmp_path / "det", size="small", n_test=2, n_train=1, progress=False)
    p = phos.generate(tmp_path / "phos", 40, 0, n_objects=3, progress=False)
    s = pose.generate(tmp_path / "pose", size="small", n_frames=1, n_test=1, progress=False)
    for src in (d, d / "test.json", p, s, s / "test" / "000001"):
        out = preview(src, tmp_path / "sheet.png", n=4)
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
    # The random lighting families change appearance more than the 12 near-frontal PSM lights.
    assert (
        stats["engine light families"]["across_lights_pairwise_ncc"]["mean"]
        < stats["real psm"]["across_lights_pairwise_ncc"]["mean"]
    )


def test_cli(tmp_path, capsys):
    assert (
        main(["data", "detect", "--size", "small", "--n-test", "1", "--n-train", "1", "--out", str(tmp_path / "d")])
        == 0
    )
    assert main(["data", "preview", str(tmp_path / "d"), "--out", str(tmp_path / "p.png")]) == 0
    assert (tmp_path / "p.png").exists()
    assert main(["data", "phos", "-n", "5", "--objects", "2", "--out", str(tmp_path / "w")]) == 0
    assert main(["data", "preview", str(tmp_path / "missing"), "--out", str(tmp_path / "q.png")]) == 2
    assert "not a dataset" in capsys.readouterr().err
    assert main(["data", "detect", "--size", "small", "--out", str(tmp_path / "d")]) == 2  # exists
