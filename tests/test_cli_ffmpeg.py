"""FFmpeg's notes on a stream: kept off the terminal while an ``alcn`` command runs (not with ``--verbose``, nor when
the caller set ``OPENCV_FFMPEG_LOGLEVEL``), and the environment left as it was for an app that calls the CLI."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from alcn_cv.cli import main

#: What FFmpeg's H.264 decoder says on every open of the cookie box video (a slice type it tolerates).
NOTE = "non-intra slice"


@pytest.mark.shared_data
def test_the_cookie_box_notes_are_printed_with_verbose_only(shared_data, tmp_path):
    video = shared_data / "cookie_box" / "box.mp4"
    if not video.is_file():
        pytest.skip(f"{video} not found")
    env = {k: v for k, v in os.environ.items() if k != "OPENCV_FFMPEG_LOGLEVEL"}
    args = ["normalize", str(video), str(tmp_path / "out.mp4"), "-m", "none", "--max-frames", "3", "--no-progress"]

    def run(*options: str, **extra: str) -> str:
        cmd = [sys.executable, "-m", "alcn_cv.cli", *options, *args, "--overwrite"]
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120, env={**env, **extra})
        assert proc.returncode == 0, proc.stderr[-2000:]
        return proc.stdout + proc.stderr  # OpenCV's log callback prints on stdout, FFmpeg's own on stderr

    assert NOTE not in run()
    assert NOTE in run("--verbose")  # the video does say it: the quiet run above was a test
    assert NOTE in run(OPENCV_FFMPEG_LOGLEVEL="16")  # the caller's level (AV_LOG_ERROR) is kept


def test_an_app_calling_the_cli_keeps_its_environment(tmp_path, monkeypatch):
    """The level is set while the command runs and removed after it: an OpenCV app that runs ``alcn`` in its
    process keeps its own FFmpeg logging for the videos it opens afterwards."""
    import cv2
    import numpy as np

    monkeypatch.delenv("OPENCV_FFMPEG_LOGLEVEL", raising=False)
    image = tmp_path / "in.png"
    cv2.imwrite(str(image), np.full((16, 16), 128, np.uint8))
    assert main(["normalize", str(image), str(tmp_path / "out.png"), "-m", "none"]) == 0
    assert "OPENCV_FFMPEG_LOGLEVEL" not in os.environ
