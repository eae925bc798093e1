"""What `alcn bench ...` says about bad values: the option, in one line, before any run (a sweep of bad inputs found
Python's and torch's names, cv2 and MemoryError tracebacks, and values found bad only after every run had failed)."""

from __future__ import annotations

import argparse
import dataclasses
import json

import pytest

from alcn_cv.bench import detect_data, detect_settings, fewshot, invariance, speed
from alcn_cv.cli import build_parser, main
from alcn_cv.errors import DatasetError, InputError, WeightFileError
from scene_sets import make_sets


def _argparse_error(args: list[str], capsys) -> str:
    """The last line of argparse's error for ``alcn bench ARGS`` (exit code 2)."""
    with pytest.raises(SystemExit) as exit_:
        main(["bench", *args])
    assert exit_.value.code == 2
    return capsys.readouterr().err.strip().splitlines()[-1]


def _parsed(args: list[str]):
    return build_parser().parse_args(["bench", *args])


AT_LEAST_1 = "an integer at least 1"


@pytest.mark.parametrize(
    ("args", "said"),
    [
        # relight: "max_pairs must be positive", "max_frames must be at least 2", "need patch >= 4, ... keypoints >= 4"
        (["relight", "--max-pairs", "-1"], "argument --max-pairs: an integer at least 0, got '-1'"),
        (["relight", "--max-frames", "1"], "argument --max-frames: 0 (all) or an integer at least 2, got '1'"),
        (["relight", "--patch", "0"], "argument --patch: an integer at least 4, got '0'"),
        (["relight", "--patches", "0"], "argument --patches: an integer at least 2, got '0'"),
        (["relight", "--gallery", "0"], f"argument --gallery: {AT_LEAST_1}, got '0'"),
        (["relight", "--n-features", "0"], "argument --n-features: an integer at least 4, got '0'"),
        (["relight", "--tune-frames", "0"], "argument --tune-frames: an integer at least 2, got '0'"),
        # detect: "positives_per_object, epochs and batch_size must be >= 1 ...", "nms_iou ... match_iou", "real_images"
        (["detect", "--epochs", "0"], f"argument --epochs: {AT_LEAST_1}, got '0'"),
        (["detect", "--batch-size", "0"], f"argument --batch-size: {AT_LEAST_1}, got '0'"),
        (["detect", "--positives", "0"], f"argument --positives: {AT_LEAST_1}, got '0'"),
        (["detect", "--negatives-ratio", "-1"], "argument --negatives-ratio: a number at least 0, got '-1'"),
        (["detect", "--match-iou", "2"], "argument --match-iou: a number greater than 0 and at most 1, got '2'"),
        (["detect", "--nms-iou", "1"], "argument --nms-iou: a number at least 0 and less than 1, got '1'"),
        (["detect", "--real-images", "1,0"], f"argument --real-images: a comma-separated list, each item {AT_LEAST_1}"),
        # found only after all the runs had run and failed
        (["detect", "--lr", "-1"], "argument --lr: a number greater than 0, got '-1'"),
        (["detect", "--cnn-sweep", "0x0"], "argument --cnn-sweep: DEPTHxWIDTH,... of integers at least 1"),
        # silently all the images
        (["detect", "--max-test-images", "0"], f"argument --max-test-images: {AT_LEAST_1}, got '0'"),
        # "det/manifest.json: working_scale 0.0 must be in (0, 4]": the command line's value blamed on the data set
        (["detect", "--working-scale", "0"], "argument --working-scale: a number greater than 0 and at most 4, got"),
        (["detect", "--box-size", "-3"], "argument --box-size: a number greater than 0, got '-3'"),
        (["detect", "--box-size", "inf"], "argument --box-size: a number greater than 0, got 'inf'"),
        # invariance: "scale must be in (0, 1]", the Python keyword
        (["invariance", "--scale", "0"], "argument --scale: a number greater than 0 and at most 1, got '0'"),
        # fewshot: "n_objects, real_images, per_image, n_test, epochs and batch_size must be >= 1 and lr > 0"
        (["fewshot", "--objects", "0"], f"argument --objects: {AT_LEAST_1}, got '0'"),
        (["fewshot", "--real-images", "0"], f"argument --real-images: {AT_LEAST_1}, got '0'"),
        (["fewshot", "--per-image", "0"], f"argument --per-image: {AT_LEAST_1}, got '0'"),
        (["fewshot", "--n-test", "0"], f"argument --n-test: {AT_LEAST_1}, got '0'"),
        (["fewshot", "--epochs", "0"], f"argument --epochs: {AT_LEAST_1}, got '0'"),
        (["fewshot", "--batch-size", "0"], f"argument --batch-size: {AT_LEAST_1}, got '0'"),
        (["fewshot", "--lr", "0"], "argument --lr: a number greater than 0, got '0'"),
        # numpy's "expected non-negative integer"
        (["fewshot", "--object-seed", "-1"], "argument --object-seed: an integer at least 0, got '-1'"),
        # speed: "invalid <lambda> value", a cv2.error and a MemoryError traceback
        (["speed", "--sizes", "abc"], "argument --sizes: a comma-separated list, each item WIDTHxHEIGHT, each side"),
        (["speed", "--sizes", "0x0"], "each side at least 16 and at most 8192 pixels, got '0x0'"),
        (["speed", "--sizes", "100000x100000"], "each side at least 16 and at most 8192 pixels, got '100000x100000'"),
        (["speed", "--video-size", "0x0"], "argument --video-size: WIDTHxHEIGHT, each side at least 16 and at most"),
        # "max_repeats (--repeats) and target_repeats >= 1", "device_batches must be"; accepted and recorded
        (["speed", "--repeats", "0"], f"argument --repeats: {AT_LEAST_1}, got '0'"),
        (
            ["speed", "--device-batches", "0"],
            f"argument --device-batches: a comma-separated list, each item {AT_LEAST_1}",
        ),
        (["speed", "--budget", "-1"], "argument --budget: a number at least 0, got '-1'"),
        (["speed", "--video-frames", "-1"], "argument --video-frames: an integer at least 0, got '-1'"),
        # torch's "set_num_threads expects a positive integer"
        (["detect", "--threads", "-2"], f"argument --threads: {AT_LEAST_1}, got '-2'"),
        (["fewshot", "--threads", "-2"], f"argument --threads: {AT_LEAST_1}, got '-2'"),
        (["speed", "--threads", "-2"], f"argument --threads: {AT_LEAST_1}, got '-2'"),
        # "... give a smaller erode"
        (["invariance", "--erode", "-1"], "argument --erode: an integer at least 0, got '-1'"),
    ],
)
def test_a_value_out_of_range_names_its_option(args, said, tmp_path, capsys):
    """Were Python's or torch's names (max_pairs, keypoints, positives_per_object, nms_iou, n_objects, max_repeats,
    target_repeats, set_num_threads), a traceback, or a value taken."""
    needed = {"detect": ["--data", str(tmp_path)], "invariance": ["--data", str(tmp_path)]}.get(args[0], [])
    assert said in _argparse_error([*args, "--out", str(tmp_path / "o"), *needed], capsys)
    assert not (tmp_path / "o").exists()


def test_the_limits_themselves_are_taken(tmp_path):
    """0 means all where the help says so; the bounds of the IoUs and sizes are in range."""
    out = ["--out", str(tmp_path)]
    relight = _parsed(["relight", *out, "--max-frames", "0", "--max-pairs", "0", "--n-features", "4"])
    assert (relight.max_frames, relight.max_pairs, relight.n_features) == (0, 0, 4)
    detect = _parsed(["detect", *out, "--data", ".", "--nms-iou", "0", "--match-iou", "1", "--cnn-sweep", "1x8,2x8"])
    assert (detect.nms_iou, detect.match_iou, detect.cnn_sweep) == (0.0, 1.0, [(1, 8), (2, 8)])
    sizes = _parsed(["speed", *out, "--sizes", "16x16, 8192x8192", "--video-frames", "0", "--budget", "0"])
    assert sizes.sizes == [(16, 16), (8192, 8192)] and sizes.video_frames == 0
    assert _parsed(["fewshot", *out, "--object-seed", "0"]).object_seed == 0


def test_relight_n_features_help_says_no_zero():
    """The help said "as the pose commands' --n-features", where 0 means all keypoints, and the benchmark refused 0
    (ORB keeps no keypoint with 0, and the matching score wants one budget for every method)."""
    parser = build_parser()
    for name in ("bench", "relight"):
        parser = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices[name]
    help_ = next(a.help for a in parser._actions if "--n-features" in a.option_strings)
    assert "no 0 for all" in help_ and "as the pose commands'" not in help_


def test_detect_settings_refuse_what_every_run_would_fail_on():
    """``--lr -1`` and ``--cnn-sweep 0x0`` were found by each of the runs, after their windows were made."""
    base = detect_settings.DetectSettings(methods=["none"])
    for bad, said in [
        ({"lr": -1.0}, "lr must be > 0"),
        ({"cnn_sweep": [(0, 0)]}, "cnn_sweep needs one or more"),
        ({"max_test_images": 0}, "max_test_images must be >= 1"),
        ({"threads": 0}, "threads must be >= 1"),
    ]:
        with pytest.raises(InputError, match=said):
            dataclasses.replace(base, **bad).check()


def test_detect_refuses_a_device_before_reading_the_data(tmp_path):
    """``--device bogus`` failed each of the 30 runs and wrote a report of failed cells (rc 1)."""
    pytest.importorskip("torch")
    from alcn_cv.bench import detect

    settings = detect_settings.DetectSettings(methods=["none"], device="bogus")
    with pytest.raises(InputError, match="--device is 'bogus', not a torch device"):
        detect.main(tmp_path / "no data", tmp_path / "out", settings)
    assert not (tmp_path / "out").exists()


def test_detect_says_a_phos_set_is_not_a_detection_set(tmp_path):
    """A set of `alcn data phos` was asked for 'working_scale' and 'box_size' (or --working-scale and --box-size)."""
    manifest = {"generator": "alcn_cv.data", "generator_version": "1", "kind": "phos", "seed": 0, "parameters": {}}
    (tmp_path / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(
        DatasetError, match=r"not a detection set \(its manifest.json says kind 'phos'\).*alcn data detect"
    ):
        detect_data.load_data(tmp_path)


def test_fewshot_object_seed_zero_is_refused_only_where_tuning_draws_seed_minus_one():
    """The validation draw of --tune uses --object-seed - 1: numpy's "expected non-negative integer" for 0."""
    settings = fewshot.FewShotSettings(methods=["dog"], object_seed=0)
    assert settings.check() is settings
    with pytest.raises(InputError, match=r"--object-seed must be at least 0, and at least 1 with --tune"):
        dataclasses.replace(settings, tune=True).check()
    with pytest.raises(InputError, match="threads must be >= 1"):
        dataclasses.replace(settings, threads=0).check()


@pytest.mark.parametrize(
    ("bad", "said"),
    [
        ({"min_repeats": 10, "max_repeats": 2}, "--min-repeats 10 is more than --repeats 2"),
        ({"budget_s": -1.0}, r"budget_s \(--budget\)"),
        ({"video_frames": -1}, r"video_frames \(--video-frames\)"),
        ({"sizes": [(0, 0)]}, r"frame sides \(--sizes, --video-size\) must be from 16 to 8192 pixels, got 0x0"),
        ({"video_size": (100000, 10)}, "got 100000x10"),
        ({"threads": 0}, "threads must be >= 1"),
    ],
)
def test_speed_settings_refuse_what_was_taken(bad, said):
    """--min-repeats 10 --repeats 2, --budget -1 and --video-frames -1 were taken ("video test -1 frames"); sizes of
    0 or 100000 pixels ended in a cv2.error or a MemoryError."""
    with pytest.raises(InputError, match=said):
        dataclasses.replace(speed.CONFS["quick"], **bad).check()


def test_speed_refuses_a_missing_weight_file_before_measuring(tmp_path):
    """``--weights nope.npz`` logged a WARNING, every variant failed, and the report was written with rc 0."""
    settings = dataclasses.replace(speed.CONFS["quick"], methods=["alcn exact"], weights=str(tmp_path / "nope.npz"))
    with pytest.raises(WeightFileError, match="--weights: weight file not found"):
        speed.main(tmp_path / "out", settings)
    assert not (tmp_path / "out").exists()


def test_invariance_refuses_an_erosion_wider_than_the_photographs(tmp_path):
    """``--erode 100000`` ended in a cv2.error traceback (a 40 GB kernel); 300 said "give a smaller erode"."""
    data = make_sets(tmp_path / "data") / "psm"
    with pytest.raises(InputError, match=r"--erode 100000 removes a disc wider than the photographs .*give at most"):
        invariance.main(data, tmp_path / "out", ["none"], erode=100000, progress=False)
    assert not (tmp_path / "out").exists()


def test_speed_repeats_alone_caps_the_presets_minimum(tmp_path, monkeypatch):
    """``--repeats 1`` ("at most this many timed runs") was refused against the preset's minimum of 2; given alone it
    caps the minimum, and both given out of order are still refused."""
    from pathlib import Path

    taken = []

    def measured(out: Path, settings: speed.SpeedSettings, **kwargs: object) -> dict:
        taken.append(settings)
        Path(out).mkdir(parents=True, exist_ok=True)
        (Path(out) / "speed.md").write_text("")
        return {"rows": []}

    monkeypatch.setattr(speed, "main", measured)
    main(["bench", "speed", "--conf", "quick", "--repeats", "1", "--out", str(tmp_path / "o")])
    assert (taken[0].min_repeats, taken[0].max_repeats) == (1, 1)
    main(["bench", "speed", "--conf", "quick", "--repeats", "5", "--out", str(tmp_path / "o")])
    assert (taken[1].min_repeats, taken[1].max_repeats) == (speed.CONFS["quick"].min_repeats, 5)


def test_a_tuned_spec_as_the_reports_print_it_is_one_method() -> None:
    """The reports print a tuned setting with a tuple (`sqi:sigmas=(0.5, 1.0, 2.0):eps=0.01`); --methods split it at
    every comma, and the method could not be given back to a benchmark."""
    from alcn_cv.bench.cli import _list

    specs = _list()("none,sqi:sigmas=(0.5, 1.0, 2.0):eps=0.01,clahe:clipLimit=8.0:tileGridSize=(8, 8),dog")
    assert specs == ["none", "sqi:sigmas=(0.5, 1.0, 2.0):eps=0.01", "clahe:clipLimit=8.0:tileGridSize=(8, 8)", "dog"]
    assert _list(int)("1,10") == [1, 10]
