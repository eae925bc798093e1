"""The OpenCV app's examples (``examples/``): the cookie box built from one preset, bad input that ends in one line
before the work, FFmpeg's stream notes kept off the terminal, and the helpers' edge cases (no homography, an empty
overlay, the model's normalization)."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path
from types import ModuleType, SimpleNamespace

import cv2
import numpy as np
import pytest

from alcn_cv.errors import ALCNError, DatasetError, InputError
from pose import build

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"


def _example(name: str) -> ModuleType:
    """The example script ``name`` imported as a module (its ``main`` not run)."""
    spec = importlib.util.spec_from_file_location(f"example_{name.removesuffix('.py')}", EXAMPLES / name)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _run(script: str, *args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, str(EXAMPLES / script), *args], capture_output=True, text=True, timeout=300, env=env
    )


class _StopError(Exception):
    """Raised by a stand-in to end an example's main where the test has seen what it needs."""


@pytest.mark.parametrize("script", ["track_cookie_box.py", "relit_cookie_box.py"])
def test_the_cookie_box_examples_build_with_the_preset(script, tmp_path, monkeypatch):
    """Both examples wrote the cookie box's build settings out themselves (the camera as K in one, K_TUTORIAL in the
    other): they build with build.COOKIE_BOX now, the box file from --data."""
    calls = []

    def record(*args, **kwargs):
        calls.append((args, kwargs))
        raise _StopError

    module = _example(script)
    (tmp_path / "data").mkdir()
    for name in ("box.mp4", "box.ply"):
        (tmp_path / "data" / name).write_bytes(b"not read: the build is a stand-in")
    monkeypatch.setattr(build, "main", record)
    monkeypatch.setattr(sys, "argv", [script, "--out", str(tmp_path), "--data", str(tmp_path / "data")])
    with pytest.raises(_StopError):
        module.main()
    (video, output), kwargs = calls[0]
    assert video == tmp_path / "data" / "box.mp4" and kwargs.pop("box_ply") == tmp_path / "data" / "box.ply"
    assert kwargs.pop("normalization", "none") == "none"
    assert kwargs.pop("overwrite") is True  # the examples rebuild what an earlier run left (a model, its .ply)
    assert kwargs == build.COOKIE_BOX


def test_the_cookie_box_preset_is_read_only_and_its_options_say_only_what_they_can():
    """The preset was a mutable dict under two names (VIDEO_CONFS["cookie_box"] and COOKIE_BOX), relit_cookie_box.py
    copied its step, and conf_options wrote a None or a list as an option's text: one read-only COOKIE_BOX, the
    example's registered build takes its step from it, and build_options refuses what no option can give."""
    import inspect

    with pytest.raises(TypeError):
        build.COOKIE_BOX["step"] = 5  # type: ignore[index]
    assert not hasattr(build, "VIDEO_CONFS")
    relit = _example("relit_cookie_box.py")
    assert inspect.signature(relit.registered_build).parameters["step"].default == build.COOKIE_BOX["step"]
    assert build.build_options({"step": 5, "motion_mask": False, "feature": "SIFT"}) == [
        "--step",
        "5",
        "--no-motion-mask",  # a preset's switch turned off
        "--feature",
        "SIFT",
    ]
    for bad in ({"max_frames": None}, {"box_size": [18.9, 25.8, 7.5]}):
        with pytest.raises(InputError, match="no option"):
            build.build_options(bad)


def test_relit_checks_its_methods_before_the_work(tmp_path):
    """`--methods none bogus` ran 91 s (the reference model built) before it failed; a negative --max-frames was
    taken as a number of frames."""
    out = tmp_path / "out"
    proc = _run("relit_cookie_box.py", "--out", str(out), "--methods", "none", "bogus")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    assert proc.stderr.strip().splitlines()[-1].startswith("relit_cookie_box.py: error: unknown normalization 'bogus'")
    assert not out.exists()  # nothing built
    proc = _run("relit_cookie_box.py", "--out", str(out), "--max-frames", "-5")
    assert proc.returncode == 2 and "--max-frames -5: a number of frames, 0 (all) or at least 60" in proc.stderr
    assert not out.exists()


def test_an_example_ends_bad_input_as_alcn_does(tmp_path):
    """The examples exited with 1 where `alcn` exits with 2: one line, `SCRIPT: error: ...`, exit code 2, the same
    helper as the command's (alcn_cv.cli.run_script)."""
    proc = _run("feature_matching.py", "--video", str(tmp_path / "nope.mp4"), "--out", str(tmp_path / "out"))
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert proc.stderr.strip().splitlines() == [
        f"feature_matching.py: error: no such video or folder: {tmp_path}/nope.mp4"
    ]
    for script in EXAMPLES.glob("*.py"):
        assert 'if __name__ == "__main__":\n    run_script(main)' in script.read_text(), script.name


@pytest.mark.parametrize(
    ("script", "args"),
    [("track_cookie_box.py", []), ("relit_cookie_box.py", ["--methods", "none"]), ("feature_matching.py", [])],
)
def test_an_out_that_cannot_be_written_ends_in_one_line(script, args, tmp_path, request):
    """A folder that cannot be made (an OSError, here under a file) ended in a traceback: the examples caught
    ALCNError only. Only feature_matching.py reads the video before its output folder: it alone needs the data."""
    if (
        script == "feature_matching.py"
        and not (request.getfixturevalue("shared_data") / "cookie_box" / "box.mp4").is_file()
    ):
        pytest.skip("the cookie box video not found")
    (tmp_path / "a_file").write_text("")
    proc = _run(script, "--out", str(tmp_path / "a_file" / "out"), *args)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    last = proc.stderr.strip().splitlines()[-1]
    assert last.startswith(f"{script}: error: ") and str(tmp_path / "a_file") in last, proc.stderr[-2000:]


@pytest.mark.shared_data
def test_ffmpeg_notes_on_the_cookie_box_are_not_printed(shared_data, tmp_path):
    """Every open of the cookie box printed `[h264 @ ...] A non-intra slice in an IDR NAL unit.`: the examples set
    OPENCV_FFMPEG_LOGLEVEL before the video opens, unless the caller set it (its level is kept)."""
    video = shared_data / "cookie_box" / "box.mp4"
    if not video.is_file():
        pytest.skip(f"{video} not found")
    env = {k: v for k, v in os.environ.items() if k != "OPENCV_FFMPEG_LOGLEVEL"}
    args = ("--video", str(video), "--methods", "none", "--out", str(tmp_path))
    quiet = _run("feature_matching.py", *args, env=env)
    assert quiet.returncode == 0 and "non-intra slice" not in quiet.stdout + quiet.stderr, quiet.stderr[-2000:]
    # AV_LOG_ERROR: the note is printed (by OpenCV's FFmpeg log callback, on stdout), so the run above was a test
    told = _run("feature_matching.py", *args, env={**env, "OPENCV_FFMPEG_LOGLEVEL": "16"})
    assert told.returncode == 0 and "non-intra slice" in told.stdout + told.stderr, told.stdout[-2000:]


def test_no_homography_is_no_match_that_agrees(monkeypatch):
    """cv2.findHomography gives no mask when RANSAC finds no homography: the matching ended in a TypeError."""
    fm = _example("feature_matching.py")
    image = cv2.resize(np.random.default_rng(0).integers(0, 256, (60, 80), np.uint8), (320, 240))
    monkeypatch.setattr(fm.cv2, "findHomography", lambda *args: (None, None))
    kp1, kp2, agreeing = fm.match(image, image, cv2.ORB.create(500))
    assert len(kp1) > 4 and len(kp2) > 4 and agreeing == []


def _video(path: Path, frames: int) -> Path:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"MJPG"), 30, (64, 48))
    for i in range(frames):
        writer.write(np.full((48, 64, 3), 40 * i, np.uint8))
    writer.release()
    return path


def test_the_contact_sheet_of_a_short_or_empty_overlay(tmp_path):
    """An overlay without any of the sheet's frames ended in an IndexError; a short one fills its row with black."""
    sheet = _example("track_cookie_box.py").contact_sheet
    short = _video(tmp_path / "short.avi", 3)
    written = cv2.imread(str(sheet(short, tmp_path / "sheet.png", frames=(0, 2))))
    assert written.shape == (240, 4 * 320, 3) and written[:, 2 * 320 :].max() == 0
    with pytest.raises(DatasetError, match="none of the frames 5, 9"):
        sheet(short, tmp_path / "none.png", frames=(5, 9))
    (tmp_path / "empty.avi").write_bytes(b"")
    with pytest.raises(InputError, match="cannot open video"):
        sheet(tmp_path / "empty.avi", tmp_path / "empty.png")


@pytest.mark.parametrize(("given", "used"), [(None, "clahe:clip_limit=2.0"), ("none", "none")])
def test_pnp_methods_normalizes_as_the_model_was_built(given, used, monkeypatch, tmp_path):
    """--normalization defaulted to none whatever the model was built after; the default is the model's, as
    `alcn pose track` uses."""
    pnp = _example("pnp_methods.py")
    model = type("Model", (), {"normalization": "clahe:clip_limit=2.0", "extra": {"K": np.eye(3).tolist()}})()
    seen = []

    def detector(model, normalization):
        seen.append(normalization)
        raise _StopError

    monkeypatch.setattr(pnp.part_model, "load", lambda path: model)
    monkeypatch.setattr(pnp, "FeaturePartDetector", detector)
    argv = ["pnp_methods.py", "model.npz", "video.mp4", *(["--normalization", given] if given else [])]
    monkeypatch.setattr(sys, "argv", argv)
    with pytest.raises(_StopError):
        pnp.main()
    assert seen == [used]


@pytest.mark.parametrize("argv", [["--normalization", "bogus"], ["--data", "missing"]])
def test_track_cookie_box_checks_its_input_before_it_makes_its_folder(argv, tmp_path, monkeypatch):
    """A typo in --normalization or a missing --data left an empty output folder behind."""
    module = _example("track_cookie_box.py")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "argv", ["track_cookie_box.py", "--out", str(tmp_path / "out"), *argv])
    with pytest.raises(ALCNError, match="unknown normalization 'bogus'|missing/box.mp4: no such video"):
        module.main()
    assert not (tmp_path / "out").exists()


def test_relit_builds_every_method_none_included_alike_and_reuses_only_models_built_so(tmp_path, monkeypatch):
    """Every method's model, none's included, comes from the registered build of the same frames; a model left by an
    earlier run is reused only when built from them: an earlier run's reference model (once ``model_none.npz``) or a
    model of other frames is built again."""
    relit = _example("relit_cookie_box.py")
    out = tmp_path / "out"
    out.mkdir()
    frames_60 = {"max_frames": 60, "step": build.COOKIE_BOX["step"]}
    extras = {
        "reference_model.npz": {"K": np.eye(3).tolist()},
        "model_none.npz": {"K": np.eye(3).tolist()},  # an earlier run's reference model, built from the whole video
        "model_clahe.npz": {"registered_frames": frames_60},  # built before from the default frames
    }
    for name in extras:
        (out / name).write_bytes(b"not read: the loading is a stand-in")
    monkeypatch.setattr(relit.part_model, "load", lambda path: SimpleNamespace(extra=extras[Path(path).name]))
    built = []

    def registered_build(video, ref, K, normalization, path, max_frames=None):
        built.append((normalization, path.name, max_frames))
        extras[path.name] = {"registered_frames": {**frames_60, "max_frames": max_frames}}

    def open_tracker(*args, **kwargs):  # the tracking starts once every model is there
        raise _StopError

    monkeypatch.setattr(relit, "registered_build", registered_build)
    monkeypatch.setattr(relit.track, "open_tracker", open_tracker)
    methods = ["--methods", "none", "clahe", "tantriggs"]
    monkeypatch.setattr(sys, "argv", ["relit_cookie_box.py", "--out", str(out), *methods])
    with pytest.raises(_StopError):
        relit.main()
    assert built == [("none", "model_none.npz", 60), ("tantriggs", "model_tantriggs.npz", 60)]
    built.clear()
    monkeypatch.setattr(sys, "argv", ["relit_cookie_box.py", "--out", str(out), *methods, "--max-frames", "0"])
    with pytest.raises(_StopError):
        relit.main()
    assert [(name, frames) for name, _, frames in built] == [("none", None), ("clahe", None), ("tantriggs", None)]


def test_pnp_methods_checks_the_video_before_any_progress_bar(tmp_path, monkeypatch, capsys):
    """A missing video printed `features: 0frame [00:00, ?frame/s]` before its error."""
    pnp = _example("pnp_methods.py")
    model = SimpleNamespace(normalization="none", extra={"K": np.eye(3).tolist()})
    monkeypatch.setattr(pnp.part_model, "load", lambda path: model)
    monkeypatch.setattr(pnp, "FeaturePartDetector", lambda model, normalization: None)
    video = tmp_path / "missing.mp4"
    monkeypatch.setattr(sys, "argv", ["pnp_methods.py", "model.npz", str(video), "--max-frames", "2"])
    with pytest.raises(InputError, match=f"no such video or folder: {video}"):
        pnp.main()
    assert "frame" not in capsys.readouterr().err
