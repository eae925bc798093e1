"""``alcn bench relight`` on a user's own scenes: the split's defaults, and weights trained on a test scene."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import cv2
import numpy as np
import pytest

from alcn_cv.bench import relight, relight_settings
from alcn_cv.cli import main as cli_main
from alcn_cv.errors import InputError
from alcn_cv.shared_data import ENV_VAR
from alcn_cv.weight_file import load_normalizer_file, save_normalizer_file
from scene_sets import texture

TINY = relight_settings.Settings(patch=16, patches=20, gallery=1, max_pairs=2, keypoint_protocols=False)
TINY_FLAGS = ["--patch", "16", "--patches", "20", "--gallery", "1", "--max-pairs", "2", "--no-keypoints"]
GAIN_WEIGHTS = Path(relight.__file__).parents[1] / "weights" / "alcn_normalizer_gain.npz"


def own_scenes(root: Path, names: tuple[str, ...] = ("one", "two", "three")) -> Path:
    """Under ``root``: one registered scene per name, 3 frames of 48x64, one texture under 3 gains."""
    for seed, name in enumerate(names):
        (root / name).mkdir(parents=True)
        base = 0.15 + 0.8 * texture(48, 64, seed=seed)
        for i, gain in enumerate((1.0, 0.5, 0.25)):
            cv2.imwrite(str(root / name / f"frame_{i}.png"), np.rint(base * gain * 255).astype(np.uint8))
    return root


def bench(tmp_path: Path, *args: str) -> dict:
    """The report of a tiny run with ``args``, replacing the last one's."""
    out = tmp_path / "out"
    argv = ["bench", "relight", "--out", str(out), "--overwrite", "--seeds", "0", "--no-progress", *TINY_FLAGS]
    assert cli_main([*argv, *args]) == 0
    return json.loads((out / "relight.json").read_text())


def test_own_scenes_without_tuning_need_no_training_scenes(tmp_path):
    """The default training scenes were looked up in the user's --data: "no scene or data set 'courbevoie'"."""
    data = own_scenes(tmp_path / "mine")
    saved = bench(tmp_path, "--data", str(data), "--test-scenes", "three", "--no-tune", "--methods", "none")
    assert saved["split"] == {"mode": "train/test", "train": [], "test": ["three"]}
    assert list(saved["scenes"]) == ["three"] and set(saved["methods"]["none"]["scenes"]) == {"three"}
    # --data without --test-scenes: every scene of it
    saved = bench(tmp_path, "--data", str(data), "--no-tune", "--methods", "none")
    assert saved["split"]["test"] == ["one", "three", "two"] and saved["split"]["train"] == []
    # a training scene named without tuning is evaluated; named as a test scene too, once, as a test scene
    saved = bench(tmp_path, "--data", str(data), "--test-scenes", "three", "--train-scenes", "one", "--no-tune")
    assert saved["split"]["train"] == ["one"] and "mean_train" in saved["methods"]["none"]
    saved = bench(tmp_path, "--data", str(data), "--test-scenes", "three", "--train-scenes", "three", "--no-tune")
    assert saved["split"] == {"mode": "train/test", "train": [], "test": ["three"]}


def test_tuning_without_training_scenes_is_one_clear_line(tmp_path, capsys):
    data = own_scenes(tmp_path / "mine")
    args = ["bench", "relight", "--out", str(tmp_path / "out"), "--data", str(data), "--test-scenes", "three"]
    assert cli_main([*args, "--methods", "none,dog", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "tuning (dog) needs training scenes" in err and "courbevoie, frankfurt, panorama" in err
    assert str(data) in err and "--train-scenes" in err and "--no-tune" in err
    # tuning on a test scene: refused, the scene named
    with pytest.raises(InputError, match="three: both a training and a test scene; tuning on a test scene"):
        relight.main(tmp_path / "o", [data], ["dog"], ["three"], ["three"], seeds=[0], settings=TINY, progress=False)
    # training scenes named: tuned on them, as before
    result = relight.main(
        tmp_path / "o", [data], ["dog"], ["one"], ["three"], seeds=[0], settings=TINY, tune_frames=3, progress=False
    )
    assert result["split"]["train"] == ["one"] and "dog (tuned)" in result["methods"]


def test_the_shared_default_split_is_kept_and_test_scenes_alone_are_alone(tmp_path, monkeypatch):
    """Without --data: the published split (also with --no-tune); --test-scenes alone evaluated only those."""
    shared = tmp_path / "shared"
    own_scenes(shared / "webcam", ("courbevoie", "frankfurt", "panorama", "mexico"))
    own_scenes(shared / "psm", ("ball",))
    monkeypatch.setenv(ENV_VAR, str(shared))
    split = bench(tmp_path, "--no-tune", "--methods", "none")["split"]
    assert split == {"mode": "train/test", "train": ["courbevoie", "frankfurt", "panorama"], "test": ["mexico", "ball"]}
    saved = bench(tmp_path, "--test-scenes", "mexico", "--no-tune", "--methods", "none")
    assert saved["split"]["train"] == [] and list(saved["scenes"]) == ["mexico"]
    # tuning: on the default training scenes, evaluated too, as before
    split = bench(tmp_path, "--test-scenes", "mexico", "--methods", "none,dog", "--tune-frames", "3")["split"]
    assert split["train"] == ["courbevoie", "frankfurt", "panorama"] and split["test"] == ["mexico"]


def weights_trained_on(path: Path, **records: list[str]) -> str:
    """A copy of the shipped gain weights whose header records ``training.config`` (``scenes``, ``rendered``) or
    ``distillation.settings`` (``distilled``) scenes."""
    shipped = load_normalizer_file(GAIN_WEIGHTS)
    meta = json.loads(json.dumps(shipped.meta))
    meta["training"]["config"].update({k: v for k, v in records.items() if k != "distilled"})
    if "distilled" in records:
        meta["distillation"] = {"settings": {"scenes": records["distilled"]}}
    return f"alcn:weights={save_normalizer_file(path, shipped.arrays, meta)}"


@pytest.mark.filterwarnings("ignore:Tight layout not applied")  # the figure's labels: long weight paths
@pytest.mark.parametrize("record", ["name", "folder", "distilled"])
def test_weights_trained_on_a_test_scene_are_flagged(tmp_path, caplog, record):
    data = own_scenes(tmp_path / "mine")
    recorded = {
        "name": {"scenes": ["one", "three"]},
        "folder": {"scenes": [str(data / "three")]},
        "distilled": {"distilled": ["three"]},
    }[record]
    leaky = weights_trained_on(tmp_path / "leaky.npz", **recorded)
    clean = weights_trained_on(tmp_path / "clean.npz", scenes=["one"])
    with caplog.at_level(logging.WARNING, logger="alcn_cv.bench.relight"):
        result = relight.main(
            tmp_path / "out",
            [data],
            ["none", leaky, clean],
            train_scenes=["one"],  # evaluated too: weights trained on a training scene are not flagged
            test_scenes=["three"],
            seeds=[0],
            settings=TINY,
            tuning=False,
            progress=False,
        )
    saved = json.loads((tmp_path / "out" / "relight.json").read_text())
    row = saved["methods"][leaky]
    assert row["trained_on"] == ["three"] and row["note"] == "trained on: three"
    assert "three" in row["scenes"] and result["methods"][leaky]["note"] == "trained on: three"
    assert "note" not in saved["methods"][clean] and "note" not in saved["methods"]["none"]
    assert f"| {leaky} (trained on: three) |" in (tmp_path / "out" / "relight.md").read_text()
    warned = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert any(leaky in m and "trained on the test scene(s) three" in m for m in warned)
    assert not any(clean in m for m in warned)


def test_the_shipped_weights_record_no_test_scene():
    for spec in ("alcn", "alcn:model=lite", "alcn:model=paper", "none"):
        assert relight.trained_scenes(spec) & {"mexico", "buddha", "cat", "horse", "owl"} == set()


def test_trained_scenes_are_named_as_the_loader_names_them(tmp_path):
    """Hidden files and one-frame scenes of a recorded folder were counted as scenes it was trained on."""
    data = own_scenes(tmp_path / "mine")
    blank = np.zeros((48, 64), np.uint8)
    for name in (".ghost.0.png", ".ghost.1.png", "lone.0.png"):
        cv2.imwrite(str(data / "one" / name), blank)
    spec = weights_trained_on(tmp_path / "w.npz", scenes=[str(data)])
    assert relight.trained_scenes(spec) == {"mine", "one", "two", "three"}


def test_trained_scenes_of_photos_and_windows_paths(tmp_path):
    """A test scene's folder relit as photos was not flagged; a path recorded on Windows was one name."""
    data = own_scenes(tmp_path / "mine")
    (data / "three" / "sub").mkdir()  # photos reads a folder's own images: its subfolders are no scene of it
    for i in range(2):
        cv2.imwrite(str(data / "three" / "sub" / f"{i}.png"), np.zeros((48, 64), np.uint8))
    photos = weights_trained_on(tmp_path / "p.npz", photos=[str(data / "three"), "C:\\photos\\mexico"])
    assert relight.trained_scenes(photos) == {"three", "mexico"}
    windows = weights_trained_on(tmp_path / "w.npz", scenes=["D:\\data\\webcam\\mexico", "frankfurt"])
    assert relight.trained_scenes(windows) == {"mexico", "frankfurt"}


def test_trained_scenes_of_a_built_method_read_no_file(tmp_path):
    """The bench built each method (reading its weight file), then read the file again for the scenes it records:
    the header the method read is the one checked."""
    spec = weights_trained_on(tmp_path / "w.npz", scenes=["mexico"])
    norm = relight.build_method(spec)
    (tmp_path / "w.npz").unlink()
    assert relight.trained_scenes(spec, norm) == {"mexico"}


def test_a_folder_that_cannot_be_listed_is_logged_not_fatal(tmp_path, monkeypatch, caplog):
    data = own_scenes(tmp_path / "mine")
    spec = weights_trained_on(tmp_path / "w.npz", scenes=[str(data), "mexico"])
    listed = Path.iterdir

    def iterdir(self):
        if self == data:
            raise PermissionError(13, "Permission denied", str(self))
        return listed(self)

    monkeypatch.setattr(Path, "iterdir", iterdir)
    with caplog.at_level(logging.WARNING, logger="alcn_cv.bench.relight"):
        assert relight.trained_scenes(spec) == {"mine", "mexico"}
    assert f"{data}: cannot list" in caplog.text and "Permission denied" in caplog.text


def test_a_researchers_mistakes_are_refused_before_any_work(tmp_path, capsys, monkeypatch):
    """An empty --methods wrote an empty report and exited 1 without a word; frames smaller than the patches were
    refused after the tuning's minutes, without naming the scene; --leave-one-out dropped --test-scenes silently."""
    data = own_scenes(tmp_path / "mine")
    out = tmp_path / "out"
    argv = ["bench", "relight", "--out", str(out), "--data", str(data), "--seeds", "0", "--no-progress", *TINY_FLAGS]
    assert cli_main([*argv, "--methods", ",", "--no-tune"]) == 2
    assert capsys.readouterr().err.strip().endswith("no method to compare: give --methods, e.g. none,alcn")
    assert not out.exists()
    assert cli_main([*argv, "--leave-one-out", "one", "two", "--test-scenes", "three"]) == 2
    assert "leave-one-out replaces the split: give no --train-scenes or --test-scenes" in capsys.readouterr().err
    small = tmp_path / "small" / "tiny"
    small.mkdir(parents=True)
    for i in range(2):
        cv2.imwrite(str(small / f"{i}.png"), np.rint(255 * texture(12, 20, seed=i)).astype(np.uint8))
    tuned = []
    monkeypatch.setattr(relight, "tune", lambda *args, **kwargs: tuned.append(args))
    assert cli_main([*argv[:4], "--data", str(data), str(tmp_path / "small"), "--train-scenes", "one", "two"]) == 2
    assert "scene 'tiny': frames of 20x12 are smaller than the 32x32 patches" in capsys.readouterr().err
    assert not tuned and not out.exists()


def test_leave_one_out_on_own_data_takes_every_scene_of_it(tmp_path):
    """With --data and no scene named, --leave-one-out looked for the shared webcam scenes: "no scene or data set
    'courbevoie'"."""
    saved = bench(tmp_path, "--data", str(own_scenes(tmp_path / "mine")), "--leave-one-out", "--no-tune")
    assert saved["split"]["mode"] == "leave-one-out" and sorted(saved["split"]["test"]) == ["one", "three", "two"]


def test_a_one_frame_scene_is_said_to_be_skipped(tmp_path, caplog):
    data = own_scenes(tmp_path / "mine")
    (data / "alone").mkdir()
    cv2.imwrite(str(data / "alone" / "only.png"), np.full((48, 64), 128, np.uint8))
    with caplog.at_level(logging.WARNING):
        saved = bench(tmp_path, "--data", str(data), "--no-tune", "--methods", "none")
    assert "only.png is scene 'alone''s only frame, skipped: a scene needs two" in caplog.text
    assert "alone" not in saved["scenes"]


def test_an_interrupted_report_leaves_the_earlier_one_whole(tmp_path, monkeypatch):
    """Ctrl-C while the figure was drawn left the new relight.json and relight.md beside the earlier run's figure
    (or with --overwrite into a fresh folder, a report without its figure): the three files replace the earlier ones
    together, or none does."""
    from alcn_cv.bench import relight_report

    data = own_scenes(tmp_path / "mine")
    bench(tmp_path, "--data", str(data), "--no-tune", "--methods", "none,dog")
    out = tmp_path / "out"
    before = {name: (out / name).read_bytes() for name in ("relight.json", "relight.md", "relight.png")}

    def interrupted(result, path):
        raise KeyboardInterrupt

    monkeypatch.setattr(relight_report, "_figure", interrupted)
    argv = ["bench", "relight", "--out", str(out), "--overwrite", "--seeds", "0", "--no-progress", *TINY_FLAGS]
    assert cli_main([*argv, "--data", str(data), "--no-tune", "--methods", "none"]) == 130
    assert {name: (out / name).read_bytes() for name in before} == before
    assert sorted(p.name for p in out.iterdir()) == sorted(before)  # no temporary file left
