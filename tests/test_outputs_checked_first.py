"""A command's output is checked before its work: a wrong suffix or a path under a file fails in the first
second, not after the training or the benchmark it would have lost."""

from __future__ import annotations

import numpy as np
import pytest

from alcn_cv.data.parallel import parallel_map
from alcn_cv.errors import InputError


def _square(x: int) -> int:
    return x * x


def test_a_progress_bar_is_complete_when_its_consumer_stops_at_the_last_item(monkeypatch):
    import alcn_cv.data.parallel as parallel

    bars = []

    class Bar:
        def __init__(self, total, **kwargs):
            self.total, self.n = total, 0
            bars.append(self)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

        def update(self, n=1):
            self.n += n

    monkeypatch.setattr(parallel, "tqdm", Bar)
    items = [1, 2, 3]
    # zip() stops as soon as `items` runs out, without asking the generator for more
    assert [r for _, r in zip(items, parallel_map(_square, items, progress=True))] == [1, 4, 9]
    assert bars[0].n == bars[0].total == 3


def test_a_weight_file_must_end_in_npz_before_the_distillation(tmp_path):
    from alcn_cv.train import distill
    from alcn_cv.train.config import DISTILL_CONFS
    from alcn_cv.weight_file import save_normalizer_file

    with pytest.raises(InputError, match=r"must end in \.npz"):
        distill.main(tmp_path / "student.onnx", DISTILL_CONFS["lite"], progress=False)
    with pytest.raises(InputError, match=r"must end in \.npz"):
        save_normalizer_file(tmp_path / "w.onnx", {}, {})
    assert not list(tmp_path.iterdir())


def test_pose_outputs_are_checked_before_the_work(tmp_path):
    from pose import build, track
    from pose.corner_train import train_corners

    blocker = tmp_path / "file"
    blocker.write_text("mine")
    corners = np.zeros((8, 3))
    with pytest.raises(InputError, match=r"must end in \.onnx"):  # not: the missing sequence
        train_corners(tmp_path / "missing_sequence", corners, tmp_path / "corners.pt")
    with pytest.raises(InputError, match="is a file"):
        train_corners(tmp_path / "missing_sequence", corners, blocker / "corners.onnx")
    with pytest.raises(InputError, match=r"a part model must end in \.npz"):  # not: the missing video
        build.main(tmp_path / "missing.mp4", tmp_path / "model.ply")
    with pytest.raises(InputError, match="is a file"):  # not: the missing part model
        track.main(tmp_path / "missing.npz", tmp_path / "missing.mp4", blocker / "poses.json")


@pytest.mark.shared_data
def test_a_benchmark_folder_is_checked_before_the_benchmark(tmp_path, shared_data, monkeypatch):
    from alcn_cv.bench import relight

    blocker = tmp_path / "file"
    blocker.write_text("mine")
    monkeypatch.setattr(relight, "evaluate_scene", lambda *args, **kwargs: pytest.fail("the benchmark ran"))
    data = [shared_data / "webcam", shared_data / "psm"]
    with pytest.raises(InputError, match="is a file"):
        relight.main(blocker, data=data, methods=["none"], tuning=False, max_frames=3)


def test_calib_output_folders_are_checked_before_the_work(tmp_path):
    """A calibration or registration into a folder under a file fails before the board search or the
    SfM (here: before the missing input is noticed), with the one-line "is a file"."""
    from calib.board import BoardSpec
    from calib.camera import Calibration
    from calib.camera import main as calibrate_camera
    from calib.register import register_charuco, register_colmap

    blocker = tmp_path / "file"
    blocker.write_text("mine")
    missing = tmp_path / "missing_images"
    calib = Calibration(np.array([[500.0, 0, 319.5], [0, 500, 239.5], [0, 0, 1]]), np.zeros(5), (640, 480), 0.0)
    with pytest.raises(InputError, match="is a file"):
        calibrate_camera(missing, blocker, BoardSpec())
    with pytest.raises(InputError, match="is a file"):
        calibrate_camera(missing, blocker / "calibration", BoardSpec())
    with pytest.raises(InputError, match="is a file"):  # not: mkdir's [Errno 17] File exists
        register_colmap(missing, blocker / "reg")
    with pytest.raises(InputError, match="is a file"):
        register_charuco(missing, blocker / "reg", calib, BoardSpec())
    assert blocker.read_text() == "mine"


def test_an_output_folder_under_a_file_is_a_one_line_error(tmp_path):
    from alcn_cv.data.manifest import atomic_output_dir
    from alcn_cv.errors import InputError

    (tmp_path / "f").write_text("mine")
    with pytest.raises(InputError, match="is a file"), atomic_output_dir(tmp_path / "f" / "d"):
        pass  # the data commands' output folder (mkdir's [Errno 17] before)
