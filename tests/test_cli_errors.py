"""``alcn normalize`` on bad files, paths and flags: exit status 2, one line that names the
problem, no traceback, and no output that looks complete."""

from __future__ import annotations

import io
import logging
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest

from alcn_cv.cli import main
from alcn_cv.runtime import MODELS


def _image(path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(0)
    cv2.imwrite(str(path), cv2.GaussianBlur((rng.random((60, 80, 3)) * 255).astype(np.uint8), (0, 0), 2))
    return path


def _truncated(path: Path, fraction: float = 0.5) -> Path:
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * fraction)])
    return path


def _video(path: Path, frames: int = 20, size: tuple[int, int] = (80, 60)) -> Path:
    img = cv2.resize(cv2.imread(str(_image(path.with_suffix(".png")))), size)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10, size)
    for i in range(frames):
        writer.write(np.roll(img, 3 * i, axis=1))
    writer.release()
    return path


def _weights(path: Path, poison: float) -> Path:
    with np.load(MODELS["lite"]) as data:
        arrays = {k: data[k] for k in data.files}
    key = next(k for k in arrays if k != "__meta__")
    arrays[key] = arrays[key].copy()
    arrays[key].flat[0] = poison
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    path.write_bytes(buffer.getvalue())
    return path


def _empty(path: Path) -> Path:
    path.write_bytes(b"")
    return path


def _file(path: Path) -> Path:
    path.write_text("not a folder")
    return path


# (arguments from tmp_path, words the message must hold, output that must not exist)
Case = tuple[Callable[[Path], list[str]], list[str], str]
CASES: dict[str, Case] = {
    "image to a name without extension": (
        lambda t: [_image(t / "in.png"), t / "out" / "noext"],
        ["noext", "image file"],
        "out/noext",
    ),
    "image to a video name": (
        lambda t: [_image(t / "in.png"), t / "out" / "x.mp4"],
        ["x.mp4", "image file"],
        "out/x.mp4",
    ),
    "image under a file": (
        lambda t: [_image(t / "in.png"), _file(t / "blocker") / "x.png"],
        ["blocker is a file"],
        "blocker/x.png",
    ),
    "folder to a file": (
        lambda t: [_image(t / "dir" / "a.png").parent, _file(t / "blocker")],
        ["blocker is a file"],
        "blocker/a.png",
    ),
    "truncated JPEG": (
        lambda t: [_truncated(_image(t / "cut.jpg")), t / "out.png"],
        ["cut.jpg", "truncated"],
        "out.png",
    ),
    "truncated PNG": (lambda t: [_truncated(_image(t / "cut.png")), t / "out.png"], ["cut.png"], "out.png"),
    "truncated video": (
        lambda t: [_truncated(_video(t / "v.avi"), 0.6), t / "out.avi", "-m", "none"],
        ["v.avi", "of 20 frames"],
        "out.avi",
    ),
    "empty weight file": (
        lambda t: [_image(t / "in.png"), t / "out.png", "-p", f"weights={_empty(t / 'w.npz')}"],
        ["w.npz", "empty"],
        "out.png",
    ),
    "random bytes weight file": (
        lambda t: [_image(t / "in.png"), t / "out.png", "-p", f"weights={_truncated(_image(t / 'w.png'), 1.0)}"],
        ["w.png", "not a .npz"],
        "out.png",
    ),
    "NaN weights": (
        lambda t: [_image(t / "in.png"), t / "out.png", "-p", f"weights={_weights(t / 'nan.npz', np.nan)}"],
        ["nan.npz", "NaN"],
        "out.png",
    ),
    "inf weights": (
        lambda t: [_image(t / "in.png"), t / "out.png", "-p", f"weights={_weights(t / 'inf.npz', np.inf)}"],
        ["inf.npz", "infinite"],
        "out.png",
    ),
    "parameter not a number": (
        lambda t: [_image(t / "in.png"), t / "out.png", "-p", "scale=abc"],
        ["'alcn'", "scale='abc'"],
        "out.png",
    ),
    "unknown parameter": (
        lambda t: [_image(t / "in.png"), t / "out.png", "-m", "dog", "-p", "sigma=2"],
        ["'dog'", "sigma1"],
        "out.png",
    ),
    "no input": (lambda t: [], ["INPUT"], "out.png"),
}


@pytest.mark.parametrize("case", CASES)
def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys, case):
    make_args, words, output = CASES[case]
    args = ["normalize", *map(str, make_args(tmp_path))]
    capsys.readouterr()
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    errors = [line for line in err.splitlines() if "error" in line.lower()]
    assert len(errors) == 1 and errors[0].startswith("alcn normalize: error:"), err
    for word in words:
        assert word in errors[0], (word, errors[0])
    assert not (tmp_path / output).exists()
    assert not [p for p in tmp_path.rglob(".*") if "tmp" in p.name], "temporary file left behind"


def _frames(path: Path) -> int:
    """The frames OpenCV decodes from a video."""
    cap = cv2.VideoCapture(str(path))
    n = 0
    while cap.read()[0]:
        n += 1
    cap.release()
    return n


def test_partial_video_on_request(tmp_path, capsys, caplog):
    src = _truncated(_video(tmp_path / "v.avi"), 0.6)
    decoded = _frames(src)
    assert 1 < decoded < 20  # some of the header's 20 frames, not all
    with caplog.at_level(logging.WARNING, logger="alcn_cv.io"):
        assert main(["normalize", str(src), str(tmp_path / "out.avi"), "-m", "none", "--allow-partial"]) == 0
    assert (tmp_path / "out.avi").is_file()
    assert _frames(tmp_path / "out.avi") == decoded  # every decoded frame written
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert any(f"decoded {decoded} of 20 frames" in w and f"wrote the {decoded} decoded frames" in w for w in warnings)


def test_interrupted_folder_leaves_no_temporary_file(tmp_path, monkeypatch, capsys):
    for name in ("a.png", "b.png", "c.png"):
        _image(tmp_path / "in" / name)
    write_bytes = Path.write_bytes
    calls = []

    def interrupted_write(path: Path, data: bytes) -> int:
        calls.append(path)
        written = write_bytes(path, data)  # the temporary file is complete when the interrupt comes
        if len(calls) == 2:
            raise KeyboardInterrupt
        return written

    monkeypatch.setattr(Path, "write_bytes", interrupted_write)
    assert main(["normalize", str(tmp_path / "in"), str(tmp_path / "out"), "-m", "none"]) == 130
    monkeypatch.undo()
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["a.png"]  # no hidden .b.*.tmp.png
    assert main(["normalize", str(tmp_path / "out"), str(tmp_path / "again"), "-m", "none"]) == 0
    assert sorted(p.name for p in (tmp_path / "again").iterdir()) == ["a.png"]


def _read_only(monkeypatch):
    """A target folder where no file can be created (as on a read-only mount; root ignores chmod)."""
    import tempfile

    def refused(*args, **kwargs):
        raise PermissionError(13, "Permission denied", str(Path(kwargs.get("dir", ".")) / ".x.e6wwkm8s.tmp.png"))

    monkeypatch.setattr(tempfile, "mkstemp", refused)


def _folder(path: Path, *names: str) -> Path:
    for name in names:
        _image(path / name)
    return path


def _corrupt_folder(path: Path) -> Path:
    """Good images around a truncated one (in name order: a, c, e)."""
    _folder(path, "a.png", "e.png")
    _truncated(_image(path / "c.png"))
    return path


# Issue 41, part 2: (arguments from tmp_path, words the one-line error must hold, files of tmp_path that
# must be left byte for byte as they were, None: every file; a setup taking monkeypatch, or None)
Protect = tuple[Callable[[Path], list[object]], list[str], Callable | None]
PROTECT: dict[str, Protect] = {
    "image onto itself": (lambda t: [_image(t / "a.png"), t / "a.png"], ["a.png is the input", "--in-place"], None),
    "image onto itself by another path": (
        lambda t: [_image(t / "a.png"), t / ".." / t.name / "a.png"],
        ["is the input", "--in-place"],
        None,
    ),
    "video onto itself": (lambda t: [_video(t / "v.avi"), t / "v.avi", "-m", "none"], ["v.avi is the input"], None),
    "folder onto itself": (lambda t: [_folder(t / "in", "a.png", "b.png"), t / "in"], ["in is the input"], None),
    "existing image": (lambda t: [_image(t / "a.png"), _image(t / "b.png")], ["b.png exists", "--overwrite"], None),
    "existing video": (
        lambda t: [_video(t / "v.avi"), _video(t / "w.avi"), "-m", "none"],
        ["w.avi exists", "--overwrite"],
        None,
    ),
    "existing image in the output folder": (
        lambda t: [_folder(t / "in", "a.png", "b.png"), _folder(t / "out", "b.png")],
        ["b.png exists", "--overwrite"],
        None,
    ),
    "corrupt image in a folder": (lambda t: [_corrupt_folder(t / "in"), t / "out"], ["c.png"], None),
    "read-only target": (
        lambda t: [_image(t / "a.png"), t / "ro" / "out.png"],
        ["cannot write", "out.png"],
        _read_only,
    ),
}


@pytest.mark.parametrize("case", PROTECT)
def test_no_file_is_replaced_or_half_written(tmp_path, capsys, monkeypatch, case):
    make_args, words, setup = PROTECT[case]
    args = ["normalize", *map(str, make_args(tmp_path))]
    before = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    if setup is not None:
        setup(monkeypatch)
    capsys.readouterr()
    assert main(args) == 2
    monkeypatch.undo()
    err = capsys.readouterr().err
    errors = [line for line in err.splitlines() if "error" in line.lower()]
    assert "Traceback" not in err and len(errors) == 1 and errors[0].startswith("alcn normalize: error:"), err
    for word in words:
        assert word in errors[0], (word, errors[0])
    assert ".tmp" not in errors[0] and "alcn_write_check" not in errors[0]
    after = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    assert after == before, "a file was written, replaced or removed"


#: Issue 41, part 2: commands ended by SIGTERM (`timeout`, a job scheduler): (arguments from tmp_path and the
#: shared data, the glob under tmp_path (also TMPDIR) whose appearance says the work is under way).
SIGTERM_CASES: dict[str, tuple[Callable[[Path, Path], list[object]], str]] = {
    "normalize a video": (
        lambda t, data: [
            "normalize",
            _video(t / "v.avi", frames=300, size=(640, 480)),
            t / "out.avi",
            "-m",
            "tantriggs",
        ],
        ".out.*.tmp.avi",
    ),
    "pose build (pycolmap)": (
        lambda t, data: [
            "pose",
            "build",
            data / "cookie_box" / "box.mp4",
            t / "model.npz",
            "--box-ply",
            data / "cookie_box" / "box.ply",
            "--K",
            1578.5,
            1771.8,
            320,
            240,
            "--motion-mask",
            "--refine-focal",
            "--step",
            10,
        ],
        "alcn_pycolmap_log_*",
    ),
}


@pytest.mark.slow
@pytest.mark.parametrize("case", SIGTERM_CASES)
def test_sigterm_cleans_up_as_ctrl_c(tmp_path, case, request):
    import os
    import signal
    import subprocess
    import sys
    import time

    make_args, started = SIGTERM_CASES[case]
    data = None
    if "pose" in case:
        data = request.getfixturevalue("shared_data")
    work = tmp_path / "work"
    work.mkdir()
    # faulthandler: a crash while unwinding (seen once in many runs: a segmentation fault) shows its Python stack
    env = {
        **os.environ,
        "TMPDIR": str(work),
        "PYTHONPATH": str(Path(__file__).resolve().parents[1]),
        "PYTHONFAULTHANDLER": "1",
    }
    proc = subprocess.Popen(
        [sys.executable, "-m", "alcn_cv.cli", *map(str, make_args(work, data))],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    deadline = time.monotonic() + 240
    while not list(work.rglob(started)) and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    assert proc.poll() is None, f"ended before {started} appeared: {proc.communicate()[1][-2000:]}"
    assert list(work.rglob(started)), f"{started} did not appear"
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=240)
    assert proc.returncode == 128 + signal.SIGTERM, err[-2000:]
    assert "Traceback" not in err and "stack trace" not in err and err.strip().splitlines()[-1] == "alcn: terminated"
    left = sorted(p.name for p in work.rglob("*") if p.name.startswith((".", "alcn_")))
    assert not left, f"left behind: {left}"


@pytest.mark.parametrize(
    ("option", "value", "says"),
    [
        ("--min-inliers", "2", "an integer at least 4, got '2'"),
        ("--n-features", "-1", "an integer at least 0, got '-1'"),
        ("--reprojection-error", "0", "a number greater than 0, got '0'"),
        ("--reprojection-error", "nan", "a number greater than 0, got 'nan'"),  # NaN compares false: it passed
    ],
)
def test_an_option_out_of_range_is_named(capsys, option, value, says):
    """`alcn pose track` named the settings as the Python keywords (min_inliers) where a user typed an option."""
    with pytest.raises(SystemExit) as stop:
        main(["pose", "track", "model.npz", "video.mp4", "poses.json", option, value])
    assert stop.value.code == 2
    assert capsys.readouterr().err.strip().splitlines()[-1].endswith(f"error: argument {option}: {says}")


def test_opencv_warnings_are_left_out_unless_debug_or_verbose(tmp_path, capfd, monkeypatch):
    """OpenCV's `[ WARN:0@0.99] global grfmt_png.cpp:793 ... PNG input buffer is incomplete` came before the command's
    own line about the same file; with --debug or --verbose it is printed, as where the caller set OPENCV_LOG_LEVEL, and
    the level is restored after main."""
    from alcn_cv.cli import _opencv_log_setter

    monkeypatch.delenv("OPENCV_LOG_LEVEL", raising=False)
    broken = _truncated(_image(tmp_path / "in" / "broken.png"), 0.3)
    cv2.imdecode(np.fromfile(broken, np.uint8), cv2.IMREAD_UNCHANGED)
    opencv_warns = "WARN" in capfd.readouterr().err  # this OpenCV's decoder warns on a truncated PNG
    assert main(["normalize", str(broken.parent), str(tmp_path / "out"), "--no-progress"]) == 2
    err = capfd.readouterr().err
    assert "WARN" not in err and err.strip().splitlines() == [
        f"alcn normalize: error: cannot read image {broken}: corrupt, truncated or unsupported format"
    ], err
    for flag in ("--debug", "--verbose"):
        assert main([flag, "normalize", str(broken.parent), str(tmp_path / "out"), "--no-progress"]) == 2
        assert ("WARN" in capfd.readouterr().err) == opencv_warns
    monkeypatch.setenv("OPENCV_LOG_LEVEL", "WARNING")  # the caller's level is kept
    assert main(["normalize", str(broken.parent), str(tmp_path / "out"), "--no-progress"]) == 2
    assert ("WARN" in capfd.readouterr().err) == opencv_warns
    set_level = _opencv_log_setter()
    if set_level is not None:
        level = set_level(0)
        set_level(level)
        assert level > 2, "the command left OpenCV's log level at errors only"


def test_out_of_memory_is_one_line(tmp_path, capsys, monkeypatch):
    """Whitening a 12000x12000 image ended in NumPy's MemoryError traceback ("Unable to allocate 4.29 GiB for an array
    with shape (24000, 24000)"): one line, which keeps NumPy's account of the size."""
    from alcn_cv.enhance.registry import from_spec

    def too_large(self, *args, **kwargs):
        raise MemoryError("Unable to allocate 4.29 GiB for an array with shape (24000, 24000) and data type float64")

    image = tmp_path / "a.png"
    cv2.imwrite(str(image), np.zeros((8, 8), np.uint8))
    monkeypatch.setattr(type(from_spec("whitening")), "apply", too_large)
    assert main(["normalize", str(image), str(tmp_path / "o.png"), "-m", "whitening"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith(
        "alcn normalize: error: out of memory (Unable to allocate 4.29 GiB for an array with shape "
        "(24000, 24000) and data type float64)"
    )
    assert "\n" not in err and "Traceback" not in err


@pytest.mark.parametrize(
    ("argv", "named"),
    [
        (["normalize", "in.png", "--out", "x"], "alcn normalize: error: unrecognized arguments: --out x"),
        (["bench", "fewshot", "--out", "o", "--methods", "none", "dog"], "alcn bench fewshot: error: unrecognized"),
        (["normalize", "in.png", "o.png", "--debug"], "unrecognized arguments: --debug (--debug: before the command"),
    ],
)
def test_an_unknown_argument_names_the_command_and_its_usage(argv, named, capsys):
    """argparse reported it from the top-level parser: "usage: alcn [-h] [--debug] [-v] COMMAND ..." and "alcn:
    error: unrecognized arguments", naming neither the command nor its options."""
    with pytest.raises(SystemExit) as info:
        main(argv)
    err = capsys.readouterr().err
    assert info.value.code == 2 and named in err
    assert f"usage: alcn {' '.join(argv[: 2 if argv[0] == 'bench' else 1])} [-h]" in err


def test_an_error_of_a_grouped_command_names_the_command(tmp_path, capsys):
    """`alcn bench detect --data MISSING` printed "alcn bench: error:" where its argument errors print "alcn bench
    detect: error:"."""
    assert main(["bench", "detect", "--data", str(tmp_path / "missing"), "--out", str(tmp_path / "o")]) == 2
    assert capsys.readouterr().err.startswith(f"alcn bench detect: error: {tmp_path / 'missing'}: not a folder")


@pytest.mark.parametrize(
    ("module", "function", "argv"),
    [
        ("alcn_cv.bench.relight", "main", ["bench", "relight", "--seeds", "3", "--out", "OUT"]),
        ("pose.planar", "main", ["pose", "planar", "--feature", "ORB", "--out", "OUT"]),
    ],
)
def test_a_report_records_the_command_main_was_given(module, function, argv, monkeypatch, capsys, tmp_path):
    """The command a report records: main's argv (an experiment calls main in its own process, with its own
    sys.argv), without the options that change nothing of what was measured; bench relight recorded
    --no-progress, pose recorded sys.argv."""
    import importlib

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr("sys.argv", ["experiment.py", "--part", "x"])
    recorded = []

    def record(*args, command, **kwargs):
        recorded.append(command)
        raise KeyboardInterrupt  # stop before any work

    monkeypatch.setattr(importlib.import_module(module), function, record)
    assert main(["--debug", "-v", *argv, "--overwrite", "--no-progress"]) == 130
    assert recorded == ["alcn " + " ".join(argv)]
