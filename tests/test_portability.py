"""alcn-cv off Linux: a portability review (emulating Windows' Python on Linux) found ``import alcn_cv`` failing on
Windows (``os.register_at_fork`` at import), every ``alcn`` command too (``import resource`` while the parser was
built), ``alcn bench speed`` failing at its end where there is no ``/proc`` (NaN in its JSON), reports printed to a
cp1252 console failing on a character it lacks, and text files read or written in the locale's encoding."""

from __future__ import annotations

import ast
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from alcn_cv import report
from alcn_cv.bench import speed

ROOT = Path(__file__).resolve().parents[1]

#: Python's modules and functions that Windows lacks, removed before the code under test runs.
WINDOWS = textwrap.dedent(
    """
    import importlib.abc, os, signal, sys

    POSIX_ONLY = {"resource", "fcntl", "termios", "pwd", "grp", "tty", "pty"}


    class _Windows(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path, target=None):
            if name in POSIX_ONLY:
                raise ModuleNotFoundError(f"No module named {name!r}", name=name)


    for name in POSIX_ONLY:
        sys.modules.pop(name, None)
    sys.meta_path.insert(0, _Windows())
    for name in ("register_at_fork", "fork", "sched_getaffinity", "getloadavg", "getuid", "killpg", "setsid"):
        if hasattr(os, name):
            delattr(os, name)
    for name in ("pthread_sigmask", "SIGKILL", "SIGALRM", "SIGHUP", "SIGQUIT", "alarm", "setitimer"):
        if hasattr(signal, name):
            delattr(signal, name)
    """
)


def _run(code: str, *args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", WINDOWS + textwrap.dedent(code), *args],
        capture_output=True,
        text=True,
        timeout=300,
        env={**os.environ, **(env or {})},
    )


def test_the_runtime_and_the_commands_import_without_posix_modules(tmp_path: Path) -> None:
    import cv2

    image = tmp_path / "in.png"
    cv2.imwrite(str(image), np.random.default_rng(0).integers(0, 256, (48, 64, 3), np.uint8))
    proc = _run(
        """
        import sys
        import numpy as np
        import alcn_cv, calib, pose
        from alcn_cv.cli import main
        out = alcn_cv.createALCN().apply(np.full((32, 32), 100, np.uint8))
        assert out.shape == (32, 32), out.shape
        assert main(["--help"]) == 0
        """,
    )
    assert proc.returncode == 0 and "normalize" in proc.stdout, proc.stderr
    proc = _run(
        "import sys; from alcn_cv.cli import main; sys.exit(main(sys.argv[1:]))",
        "normalize",
        str(image),
        str(tmp_path / "out.png"),
    )
    assert proc.returncode == 0 and (tmp_path / "out.png").is_file(), proc.stderr


def test_a_report_printed_to_a_legacy_console_escapes_what_it_cannot_spell() -> None:
    """fewshot.md's check marks, printed by `alcn bench fewshot` to a cp1252 console or a redirected stdout on
    Windows, ended the command (the report written) with "'charmap' codec can't encode"."""
    code = "from alcn_cv.cli import main; main(['normalize', '--list']); print('\\u2713 \\u2717')"
    proc = _run(code, env={"PYTHONIOENCODING": "cp1252"})
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.splitlines()[-1] == "\\u2713 \\u2717"


def test_the_speed_benchmarks_video_memory_without_proc_is_none_not_nan(monkeypatch: pytest.MonkeyPatch) -> None:
    """Where there is no /proc (macOS, Windows) the resident set was NaN, which the report's JSON refused after every
    measurement was made."""
    monkeypatch.setattr(speed, "_rss_kb", lambda field_name="VmRSS": None)
    result = speed.video_memory(speed.create("dog"), (64, 48), 3, 5.0)
    assert result["rss_mb"] == [] and result["rss_max_mb"] is None and result["growth_kb_per_frame"] is None
    assert result["frames"] == 3
    json.dumps(result, allow_nan=False)


def test_the_machine_keeps_the_load_average_without_the_cpu_affinity(monkeypatch: pytest.MonkeyPatch) -> None:
    """macOS has the load average and not sched_getaffinity: one missing dropped both from every report."""
    monkeypatch.delattr(os, "sched_getaffinity", raising=False)
    info = report.machine()
    assert "cpus_available" not in info and len(info["load_average_1_5_15"]) == 3


def _text_calls_without_encoding(path: Path) -> list[str]:
    """The built-in ``open`` in text mode and ``Path.read_text`` / ``write_text`` called without ``encoding=``."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if not isinstance(node, ast.Call) or any(k.arg == "encoding" for k in node.keywords):
            continue
        if isinstance(node.func, ast.Attribute) and node.func.attr in ("read_text", "write_text"):
            found.append(f"{path.relative_to(ROOT)}:{node.lineno}")
        elif isinstance(node.func, ast.Name) and node.func.id == "open":
            mode = (
                node.args[1] if len(node.args) > 1 else next((k.value for k in node.keywords if k.arg == "mode"), None)
            )
            if not (isinstance(mode, ast.Constant) and "b" in str(mode.value)):
                found.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    return found


def test_text_files_are_read_and_written_as_utf_8() -> None:
    """Windows reads and writes text in its code page (cp1252) unless told: a TOML preset with an accented path
    failed to load, and config.toml with a CJK data path failed to be written."""
    sources = [
        p for package in ("alcn_cv", "pose", "calib", "experiments", "examples") for p in (ROOT / package).rglob("*.py")
    ]
    found = [site for path in sources for site in _text_calls_without_encoding(path)]
    assert not found, found


def test_a_calibration_file_at_a_path_of_any_characters(tmp_path: Path) -> None:
    """OpenCV's FileStorage opens a path by a narrow string, which on Windows fails for characters outside the code
    page (a user folder with accents): the file is written and parsed in memory, the bytes as OpenCV's own."""
    import cv2

    from calib.camera import load_calibration, write_camera_yaml

    K = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
    folder = tmp_path / "José 田中"
    folder.mkdir()
    for suffix in (".yaml", ".xml", ".json"):
        path = write_camera_yaml(folder / f"camera{suffix}", K, np.zeros(5), (640, 480), rms=0.4)
        calibration = load_calibration(path)
        assert np.array_equal(calibration.K, K) and calibration.image_size == (640, 480) and calibration.rms == 0.4
        by_opencv = tmp_path / f"opencv{suffix}"
        fs = cv2.FileStorage(str(by_opencv), cv2.FILE_STORAGE_WRITE)
        for key, value in (("image_width", 640), ("image_height", 480), ("camera_matrix", K)):
            fs.write(key, value)
        fs.write("distortion_coefficients", np.zeros((1, 5)))
        fs.write("rms", 0.4)
        fs.release()
        assert path.read_bytes() == by_opencv.read_bytes()


def test_normalize_sees_an_output_that_is_its_input_by_another_name(tmp_path: Path) -> None:
    """On a case-insensitive disk (macOS, Windows) `alcn normalize imgs IMGS --overwrite` replaced the inputs without
    --in-place: the paths differed. A hard link is the same file by another name on any disk."""
    import cv2

    from alcn_cv.commands.normalize import main
    from alcn_cv.errors import InputError

    image = tmp_path / "a.png"
    cv2.imwrite(str(image), np.full((16, 16), 90, np.uint8))
    os.link(image, tmp_path / "b.png")
    with pytest.raises(InputError, match="is the input"):
        main(image, tmp_path / "b.png", overwrite=True)
