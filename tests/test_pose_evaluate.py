"""pose.evaluate: report writing and the data-set check."""

from __future__ import annotations

import numpy as np
import pytest

from alcn_cv.errors import DatasetError
from pose import evaluate, plots


def test_report_table_and_plot(tmp_path):
    table = {"none / orb": {"#1": 100.0, "#2": 12.5}, "alcn / orb": {"#1": 100.0, "#2": float("nan")}}
    md = evaluate.table_markdown(table, ["#1", "#2"])
    assert "| none / orb | 100.0 | 12.5 |" in md and "| alcn / orb | 100.0 | - |" in md
    png = plots.plot_table(table, ["#1", "#2"], tmp_path / "t.png", "test")
    assert png.stat().st_size > 1000


def test_missing_dataset(tmp_path):
    with pytest.raises(DatasetError, match="train/000001"):
        evaluate.main(tmp_path, tmp_path / "out", normalizations=["none"])


def test_normalizer_specs_name_parameters_and_files():
    from alcn_cv.enhance.registry import from_spec

    fast = from_spec("alcn:model=lite:mixture=pyramid")
    assert fast.mixture == "pyramid" and fast.weights_path.name == "alcn_normalizer_lite.npz"
    assert from_spec("alcn:model=paper:mixture=exact").weights_path.name == "alcn_normalizer.npz"
    assert evaluate.file_stem("alcn:model=lite:mixture=pyramid") == "alcn_model-lite_mixture-pyramid"
    assert evaluate.file_stem("none") == "none"


def test_overlay_colours_follow_the_paper_for_specs_too():
    from pose.track import COLORS, OTHER_COLOR, color_for

    assert color_for("alcn:model=lite:mixture=pyramid") == color_for("alcn") == COLORS["alcn"]
    assert color_for("none") == COLORS["none"] != COLORS["alcn"]
    assert color_for("clahe:clipLimit=2") == OTHER_COLOR


class _NoParts:
    """A part detector that finds nothing (every frame lost)."""

    uses_prior = False
    refine_search_scale = 0.0

    def detect(self, image, prior=None, *, search_scale=1.0):
        from pose.parts import Correspondences

        return Correspondences(np.zeros((0, 3), np.float32), np.zeros((0, 2), np.float32))

    def verify(self, image, rvec, tvec, K, *, proposed=False):
        return ""

    def propose(self, image, K):
        return None


def test_a_test_sequence_without_the_object_is_a_dataset_error(tmp_path):
    from alcn_cv.data import pose
    from pose.model import read_box_corners

    data = pose.generate(
        tmp_path / "data", conf="small", n_frames=2, n_test=1, clutter=False, train_sweeps=(1,), progress=False
    )
    corners = read_box_corners(data / "models" / "obj_000001.ply")
    scores, _ = evaluate.evaluate_sequence(_NoParts(), data / "test" / "000001", 1, corners, "mm")
    assert len(scores) == 2 and all(s.proj_px is None for s in scores)  # lost frames count as wrong
    with pytest.raises(DatasetError, match="object 99 is not annotated in frame 0"):
        evaluate.evaluate_sequence(_NoParts(), data / "test" / "000001", 99, corners, "mm")
