"""``alcn normalize`` on an image, a folder and a video, and its errors."""

import subprocess
import sys

import cv2
import numpy as np
import pytest

from alcn_cv.cli import main
from alcn_cv.io import VideoReader


@pytest.fixture
def frame():
    rng = np.random.default_rng(0)
    return cv2.GaussianBlur((rng.random((60, 80, 3)) * 255).astype(np.uint8), (0, 0), 2)


def test_image_keeps_size_channels_and_depth(tmp_path, frame):
    src = tmp_path / "in.png"
    cv2.imwrite(str(src), frame)
    assert main(["normalize", str(src), str(tmp_path / "out.png"), "-m", "dog"]) == 0
    out = cv2.imread(str(tmp_path / "out.png"), cv2.IMREAD_UNCHANGED)
    assert out.shape == frame.shape and out.dtype == np.uint8
    gray16 = tmp_path / "g16.png"
    cv2.imwrite(str(gray16), (frame[..., 0].astype(np.uint16) * 257))
    assert main(["normalize", str(gray16), str(tmp_path / "g16_out.png"), "-m", "clahe", "--gray"]) == 0
    assert cv2.imread(str(tmp_path / "g16_out.png"), cv2.IMREAD_UNCHANGED).dtype == np.uint16


def test_folder(tmp_path, frame):
    (tmp_path / "in").mkdir()
    for i in range(3):
        cv2.imwrite(str(tmp_path / "in" / f"{i}.jpg"), np.roll(frame, i, axis=1))
    (tmp_path / "in" / "notes.txt").write_text("not an image")
    assert main(["normalize", str(tmp_path / "in"), str(tmp_path / "out"), "-m", "alcn", "-p", "scale=1.0"]) == 0
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["0.jpg", "1.jpg", "2.jpg"]


def test_video(tmp_path, frame):
    src = tmp_path / "in.avi"
    writer = cv2.VideoWriter(str(src), cv2.VideoWriter_fourcc(*"MJPG"), 10, (80, 60))
    for i in range(5):
        writer.write(np.roll(frame, 3 * i, axis=1))
    writer.release()
    dst = tmp_path / "out.avi"
    assert main(["normalize", str(src), str(dst), "-m", "none"]) == 0
    with VideoReader(dst) as video:
        frames = list(video)
    assert len(frames) == 5 and frames[0].shape == (60, 80, 3)
    assert not list(tmp_path.glob(".*tmp*")), "temporary file left behind"
    assert main(["normalize", str(src), str(tmp_path / "out.png")]) == 2


def test_errors_are_one_line(tmp_path, capsys):
    corrupt = tmp_path / "corrupt.png"
    corrupt.write_bytes(b"\x89PNG not really")
    assert main(["normalize", str(corrupt), str(tmp_path / "o.png")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("alcn normalize: error:") and "corrupt" in err[-1]
    assert main(["normalize", str(tmp_path / "missing.png"), str(tmp_path / "o.png")]) == 2
    assert main(["normalize", str(corrupt), str(tmp_path / "o.png"), "-m", "nope"]) == 2
    assert "unknown normalization" in capsys.readouterr().err
    assert main(["normalize", str(corrupt), str(tmp_path / "o.png"), "-m", "none", "-p", "oops"]) == 2
    (tmp_path / "empty").mkdir()
    assert main(["normalize", str(tmp_path / "empty"), str(tmp_path / "o"), "-m", "none"]) == 2
    assert "no images" in capsys.readouterr().err


def test_debug_shows_the_traceback(tmp_path):
    cmd = [sys.executable, "-m", "alcn_cv.cli", "--debug", "normalize", str(tmp_path / "missing.png"), str(tmp_path / "o.png")]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    assert proc.returncode != 0 and "Traceback" in proc.stderr and "InputError" in proc.stderr
    proc = subprocess.run(cmd[:3] + cmd[4:], capture_output=True, text=True)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr


def test_every_subcommand_has_help():
    from alcn_cv.cli import build_parser

    parser = build_parser()
    commands = parser._subparsers._group_actions[0].choices
    assert {"normalize", "demo", "data", "train", "export", "bench", "pose", "calib"} <= set(commands)
    for name, sub in commands.items():
        assert sub.format_help().strip(), name


def test_alpha_is_kept(tmp_path, frame):
    alpha = np.tile(np.linspace(0, 255, frame.shape[1]).astype(np.uint8), (frame.shape[0], 1))
    cv2.imwrite(str(tmp_path / "rgba.png"), np.dstack([frame, alpha]))
    for flags, channels in (([], 4), (["--gray"], 4)):
        assert main(["normalize", str(tmp_path / "rgba.png"), str(tmp_path / "out.png"), "-m", "clahe", *flags]) == 0
        out = cv2.imread(str(tmp_path / "out.png"), cv2.IMREAD_UNCHANGED)
        assert out.shape == frame.shape[:2] + (channels,)
        np.testing.assert_array_equal(out[..., 3], alpha)


def test_list_explains_every_method(capsys):
    from alcn_cv.enhance import available

    assert main(["normalize", "--list"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert [line.split()[0] for line in lines] == available()
    assert any("Jarrett" in line for line in lines if line.startswith("dlcn"))
