"""pose.evaluate: report writing and the data-set check."""

from __future__ import annotations

import cv2
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


def test_middlebury_poses_every_view_once_from_a_model_without_it(tmp_path, monkeypatch):
    """Two folds: the even views' model poses the odd views and the reverse; a pose beyond 5 deg or 5 cm counts as
    posed, not correct (a wrong pose of the temple, 63 deg off, was counted as posed). A model too small to build
    poses none of its views, and the other normalizations are still compared (it ended the whole run)."""
    from types import SimpleNamespace

    from alcn_cv import io
    from alcn_cv.formats import middlebury

    views = [
        SimpleNamespace(
            name=f"v{i}.png",
            path=tmp_path / f"v{i}.png",
            K=np.eye(3),
            R_w2c=np.eye(3),
            t_w2c=np.zeros(3),
            center=np.zeros(3),
        )
        for i in range(6)
    ]
    # the pose found for each view: v1 4 deg off (correct), v2 6 cm off, v3 10 deg off, v4 3 cm off (correct: within
    # 5 cm, Middlebury's t in metres and its errors in mm), v5 none
    angles, shifts = {1: 4.0, 3: 10.0}, {2: 0.06, 4: 0.03}
    built, solved = [], []

    def build(seq, normalization, **_):
        names = sorted(v.name for v in seq.views)
        if normalization == "dog" and "v1.png" in names:
            raise DatasetError("only 8 3D points; the box fit needs at least 10")
        built.append(names)
        return SimpleNamespace(points3d=np.zeros((10 + len(built), 3))), None

    class Detector:
        def __init__(self, model, *_, **__):
            self.model = built[-1]

        def detect(self, image):
            return SimpleNamespace(object_points=self.model, image_points=int(image[0, 0]))

    class Solver:
        def __init__(self, *_, **__):
            pass

        def solve(self, model, index):
            name = f"v{index}.png"
            assert name not in model  # never posed from a model that holds it
            solved.append(name)
            R = cv2.Rodrigues(np.array([np.radians(angles.get(index, 0.0)), 0, 0]))[0]
            tvec = np.array([shifts.get(index, 0.0), 0, 0])
            return SimpleNamespace(ok=index != 5, R=R, tvec=tvec)

    monkeypatch.setattr(middlebury, "read_middlebury", lambda _: views)
    monkeypatch.setattr(evaluate, "load_sequence", lambda _: SimpleNamespace(views=list(views)))
    monkeypatch.setattr(evaluate, "build_model", build)
    monkeypatch.setattr(evaluate, "FeaturePartDetector", Detector)
    monkeypatch.setattr(evaluate, "PoseSolver", Solver)
    monkeypatch.setattr(io, "read_image", lambda path: np.full((4, 4), int(path.stem[1:]), np.uint8))
    monkeypatch.setattr(evaluate, "relight", lambda image, seed: image)
    results = evaluate.middlebury_main([tmp_path], tmp_path / "out", normalizations=["none", "dog"], progress=False)

    even, odd = ["v0.png", "v2.png", "v4.png"], ["v1.png", "v3.png", "v5.png"]
    assert built == [even, odd, even]
    assert sorted(solved) == sorted(f"v{i}.png" for i in [*range(6), 1, 3, 5] for _ in ("original", "relit"))
    for light in ("original", "relit"):
        result = results[f"{tmp_path.name}/none/{light}"]
        assert (result["posed"], result["correct"], result["views"]) == (5, 3, 6)  # v0, v1, v4 correct
        assert result["model_points"] == [11, 12]
        broken = results[f"{tmp_path.name}/dog/{light}"]
        assert (broken["posed"], broken["correct"], broken["model_points"]) == (2, 1, [13, None])  # v1, v3
    report = (tmp_path / "out" / "middlebury.md").read_text()
    assert "| 3/6 | 5/6 |" in report and "| 11 / 12 |" in report and "posed: any pose RANSAC found" in report
    assert "| 1/6 | 2/6 |" in report and "| 13 / none |" in report


def test_pose_eval_refuses_an_earlier_report_and_a_folder_another_run_writes(tmp_path, capsys):
    """As `alcn bench`: an earlier evaluation's report only with --overwrite, a folder in use never (two runs into
    one folder both ran and the last replaced the other's report)."""
    from alcn_cv.cli import main
    from alcn_cv.errors import InputError
    from alcn_cv.io import held_folder

    out = tmp_path / "out"
    out.mkdir()
    (out / "middlebury.md").write_text("earlier\n")
    assert main(["pose", "eval", "--middlebury", str(tmp_path / "set"), "--out", str(out)]) == 2
    assert capsys.readouterr().err.strip().endswith(f"{out / 'middlebury.md'} exists (--overwrite replaces it)")
    with held_folder(out), pytest.raises(InputError, match="is in use by another run"):
        evaluate.middlebury_main([tmp_path / "set"], out, progress=False)
    with held_folder(out), pytest.raises(InputError, match="is in use by another run"):
        evaluate.main(tmp_path / "data", out, progress=False)
    assert (out / "middlebury.md").read_text() == "earlier\n"
