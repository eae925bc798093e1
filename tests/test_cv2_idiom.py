"""Issue 41, part 3 and 4: the cv2 idiom all the way (``apply(src, dst)``, ``createALCN``'s real
signature), the progress bar's count, and extras checked before the work."""

from __future__ import annotations

import inspect

import cv2
import numpy as np
import pytest

import alcn_cv
from alcn_cv import io


@pytest.fixture(scope="module")
def image():
    rng = np.random.default_rng(0)
    return cv2.GaussianBlur((rng.random((60, 80, 3)) * 255).astype(np.uint8), (0, 0), 2)


# (how apply is called with the image, the destination array made from the image's result; whether it is written)
DST_CASES = {
    "positional dst": (lambda m, img, dst: m.apply(img, dst), lambda out: np.empty_like(out), True),
    "keyword dst": (lambda m, img, dst: m.apply(img, dst=dst), lambda out: np.empty_like(out), True),
    "dst of another shape": (lambda m, img, dst: m.apply(img, dst), lambda out: np.zeros((3, 3), out.dtype), False),
    "dst of another dtype": (lambda m, img, dst: m.apply(img, dst), lambda out: np.zeros(out.shape, np.float32), False),
    "read-only dst": (lambda m, img, dst: m.apply(img, dst), lambda out: np.zeros_like(out).view(), False),
    "dst and out_dtype": (
        lambda m, img, dst: m.apply(img, dst, out_dtype=np.float32),
        lambda out: np.empty(out.shape, np.float32),
        True,
    ),
}


@pytest.mark.parametrize("method", ["alcn", "clahe", "dog"])
@pytest.mark.parametrize("case", DST_CASES)
def test_apply_takes_dst_as_opencv_does(image, method, case):
    call, make_dst, written = DST_CASES[case]
    normalization = alcn_cv.create(method)
    expected = normalization.apply(image, out_dtype=np.float32 if "out_dtype" in case else None)
    dst = make_dst(expected)
    if case == "read-only dst":
        dst.flags.writeable = False
    before = dst.copy()
    out = call(normalization, image, dst)
    np.testing.assert_array_equal(out, expected)
    assert (out is dst) == written
    if not written:
        np.testing.assert_array_equal(dst, before)


def test_apply_into_its_own_input(image):
    img = image.copy()
    expected = alcn_cv.create("dog").apply(img)
    assert alcn_cv.create("dog").apply(img, img) is img
    np.testing.assert_array_equal(img, expected)


def test_create_alcn_shows_alcns_parameters():
    signature = inspect.signature(alcn_cv.createALCN)
    assert list(signature.parameters) == list(inspect.signature(alcn_cv.ALCN.__init__).parameters)[1:]
    for name, parameter in signature.parameters.items():
        assert parameter.default == inspect.signature(alcn_cv.ALCN.__init__).parameters[name].default, name
    assert signature.parameters["model"].default is None  # the default model: alcn_cv.runtime.resolve_weights's
    assert repr(alcn_cv.createALCN(model="lite", scale=0.5)) == repr(alcn_cv.ALCN(model="lite", scale=0.5))


def test_video_progress_bar_ends_at_the_frames_decoded(tmp_path, image, monkeypatch, capsys):
    """The shared cookie-box video's header says 456 frames, FFmpeg decodes 455: the bar ended at 455/456."""
    src = tmp_path / "v.avi"
    writer = cv2.VideoWriter(str(src), cv2.VideoWriter_fourcc(*"MJPG"), 10, (80, 60))
    for i in range(5):
        writer.write(np.roll(image, i, axis=1))
    writer.release()
    monkeypatch.setattr(io.VideoReader, "__len__", lambda self: self.frame_count + 1)  # a header one too high
    capsys.readouterr()
    assert io.map_video(src, tmp_path / "out.avi", lambda frame: frame) == 5
    bar = capsys.readouterr().err.split("\r")[-1]
    assert "5/5" in bar and "100%" in bar, bar


def test_calib_report_needs_matplotlib_before_the_work(tmp_path, run_python):
    """`alcn calib camera` without matplotlib calibrated, wrote its files, then exited 2 asking for it."""
    folder = tmp_path / "images"
    folder.mkdir()
    cv2.imwrite(str(folder / "a.png"), np.zeros((60, 80), np.uint8))
    out = tmp_path / "out"
    code = "import sys\nfrom alcn_cv.cli import main\nsys.exit(main(sys.argv[1:]))\n"
    proc = run_python(code, "calib", "camera", "--images", folder, "--out", out, blocked=("matplotlib",))
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    assert proc.stderr.strip().splitlines()[-1] == (
        "alcn calib camera (its calibration.png; --no-report writes the rest without it): needs the [data] extra "
        '(matplotlib is not installed): pip install "alcn-cv[data]"'
    )
    assert not out.exists()
    proc = run_python(code, "calib", "camera", "--images", folder, "--out", out, "--no-report", blocked=("matplotlib",))
    assert "matplotlib" not in proc.stderr, proc.stderr  # it goes on to the calibration (which fails on a blank image)


@pytest.mark.parametrize(
    ("setting", "argument"),
    [
        ("scale", "scale"),
        ("sigmas", "scale"),
        ("backend", "backend"),
        ("grid_stride", "grid_stride"),
        ("mixture", "mixture"),
        ("threads", "threads"),
        ("weights_path", "weights"),
        ("model", "model"),  # createALCN's arguments, not attributes: as silently ignored
        ("weights", "weights"),
    ],
)
def test_a_setting_changed_after_creation_is_refused_not_ignored(image, setting, argument):
    """The runtime is built from the settings once: ``alcn.scale = 0.5`` would leave the output as it was (a user
    used to CLAHE's setters tried it), so setting or deleting one raises and names the argument that does it."""
    alcn = alcn_cv.createALCN()
    before = alcn.apply(image)
    with pytest.raises(AttributeError, match=rf"createALCN\({argument}=\.\.\.\)"):
        setattr(alcn, setting, getattr(alcn, setting, "lite"))
    if hasattr(alcn, setting):
        with pytest.raises(AttributeError, match=rf"createALCN\({argument}=\.\.\.\)"):
            delattr(alcn, setting)
    np.testing.assert_array_equal(alcn.apply(image), before)


def test_a_positional_setting_that_is_not_a_weight_file_is_named():
    """``cv2.createCLAHE(2.0)`` takes its clip limit first; ``createALCN``'s first argument is the weight file."""
    with pytest.raises(
        alcn_cv.InputError, match=r"weights must be the path of a weight file.*got float 1\.0.*keywords"
    ):
        alcn_cv.createALCN(1.0)
