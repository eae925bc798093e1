"""``alcn normalize`` on an image, a folder and a video, and its errors."""

import subprocess
import sys

import cv2
import numpy as np
import pytest

from alcn_cv import create
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
    # --gray on a colour image: the method on its gray conversion, written as one channel
    assert main(["normalize", str(src), str(tmp_path / "gray_out.png"), "-m", "dog", "--gray"]) == 0
    gray_out = cv2.imread(str(tmp_path / "gray_out.png"), cv2.IMREAD_UNCHANGED)
    assert gray_out.shape == frame.shape[:2] and gray_out.dtype == np.uint8
    np.testing.assert_array_equal(gray_out, create("dog").apply(cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)))
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


def test_folder_another_run_writes_is_refused(tmp_path, frame, capsys):
    from alcn_cv.io import held_folder

    (tmp_path / "in").mkdir()
    cv2.imwrite(str(tmp_path / "in" / "0.png"), frame)
    with held_folder(tmp_path / "out"):  # as another run would, while it writes
        assert main(["normalize", str(tmp_path / "in"), str(tmp_path / "out"), "-m", "dog"]) == 2
    assert "is in use by another run" in capsys.readouterr().err
    assert not list((tmp_path / "out").iterdir()), "the refused run wrote into the folder"
    # in place, the folder held is the input's; the hold's file is neither an output nor an image skipped
    assert main(["normalize", str(tmp_path / "in"), str(tmp_path / "in"), "-m", "dog", "--in-place"]) == 0
    assert sorted(p.name for p in (tmp_path / "in").iterdir()) == ["0.png"]


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
    assert main(["normalize", str(src), str(tmp_path / "first.avi"), "-m", "none", "--max-frames", "2"]) == 0
    with VideoReader(tmp_path / "first.avi") as video:
        assert len(list(video)) == 2


@pytest.mark.parametrize("count", ["0", "-2"])
def test_max_frames_out_of_range_names_the_option(tmp_path, count, capsys):
    """``--max-frames 0`` said "max_frames must be positive, got 0", a Python name, not the option."""
    with pytest.raises(SystemExit) as stop:
        main(["normalize", str(tmp_path / "in.avi"), str(tmp_path / "out.avi"), "--max-frames", count])
    assert stop.value.code == 2
    assert (
        capsys.readouterr()
        .err.strip()
        .splitlines()[-1]
        .endswith(f"argument --max-frames: an integer at least 1, got '{count}'")
    )


def test_no_progress_shows_no_bar(tmp_path, frame, capsys):
    """--no-progress, the one switch of the progress bars of every command that shows them."""
    src = tmp_path / "in.avi"
    writer = cv2.VideoWriter(str(src), cv2.VideoWriter_fourcc(*"MJPG"), 10, (80, 60))
    for _ in range(3):
        writer.write(frame)
    writer.release()
    assert main(["normalize", str(src), str(tmp_path / "a.avi"), "-m", "none"]) == 0
    assert "%|" in capsys.readouterr().err  # the bar: "normalize in.avi: 100%|...| 3/3 [..., ...frame/s]"
    assert main(["normalize", str(src), str(tmp_path / "b.avi"), "-m", "none", "--no-progress"]) == 0
    assert "%|" not in capsys.readouterr().err


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
    image = tmp_path / "image.png"
    cv2.imwrite(str(image), np.zeros((8, 8), np.uint8))
    for args, message in [
        ([str(tmp_path), str(tmp_path / "out.jpg")], "got the file name"),  # a folder's output
        ([str(image), str(tmp_path / "o.png"), "--max-frames", "3"], "not one"),
        ([str(image), str(tmp_path / "o.png"), "--batch-size", "8"], "without it each frame"),
    ]:
        assert main(["normalize", *args, "-m", "none"]) == 2
        assert message in capsys.readouterr().err.strip().splitlines()[-1]
    assert not (tmp_path / "out.jpg").exists()


def test_debug_shows_the_traceback(tmp_path):
    cmd = [
        sys.executable,
        "-m",
        "alcn_cv.cli",
        "--debug",
        "normalize",
        str(tmp_path / "missing.png"),
        str(tmp_path / "o.png"),
    ]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    assert proc.returncode == 2 and "Traceback" in proc.stderr and "InputError" in proc.stderr
    assert proc.stderr.rstrip().splitlines()[-1].startswith("alcn normalize: error:")
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
        assert (
            main(
                [
                    "normalize",
                    str(tmp_path / "rgba.png"),
                    str(tmp_path / "out.png"),
                    "-m",
                    "clahe",
                    "--overwrite",
                    *flags,
                ]
            )
            == 0
        )
        out = cv2.imread(str(tmp_path / "out.png"), cv2.IMREAD_UNCHANGED)
        assert out.shape == frame.shape[:2] + (channels,)
        np.testing.assert_array_equal(out[..., 3], alpha)
        if flags == ["--gray"]:  # gray and alpha, written as BGRA: B == G == R, CLAHE of the gray conversion
            np.testing.assert_array_equal(out[..., 0], out[..., 1])
            np.testing.assert_array_equal(out[..., 0], out[..., 2])
            np.testing.assert_array_equal(out[..., 0], create("clahe").apply(cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)))
        else:  # the colour kept
            assert not np.array_equal(out[..., 0], out[..., 2])


def test_list_explains_every_method(capsys):
    from alcn_cv.enhance import available

    assert main(["normalize", "--list"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert [line.split()[0] for line in lines[::2]] == available()
    assert any("Jarrett" in line for line in lines if line.startswith("dlcn"))
    # each method's parameters with their defaults (issue 41, part 3)
    params = dict(
        zip((line.split()[0] for line in lines[::2]), (line.split("parameters:")[1].split() for line in lines[1::2]))
    )
    assert params["dog"] == ["sigma1=0.5", "sigma2=1.5"]
    assert params["clahe"] == ["clipLimit=2.0", "tileGridSize=(8,8)"]
    assert "model=None" in params["alcn"] and "backend=None" in params["alcn"]  # None: the default model
    assert params["none"] == ["none"]


def test_help_shows_the_methods_parameters(capsys):
    with pytest.raises(SystemExit):
        main(["normalize", "--help"])
    out = capsys.readouterr().out
    assert (
        "dog:sigma1=1:sigma2=2" in out
        and "sigma1=0.5 sigma2=1.5" in out
        and "--overwrite" in out
        and "--in-place" in out
    )


@pytest.mark.parametrize("kind", ["image", "video", "folder"])
def test_in_place_and_overwrite_on_request(tmp_path, frame, kind):
    if kind == "video":
        src = tmp_path / "v.avi"
        writer = cv2.VideoWriter(str(src), cv2.VideoWriter_fourcc(*"MJPG"), 10, (80, 60))
        for i in range(3):
            writer.write(np.roll(frame, 3 * i, axis=1))
        writer.release()
    else:
        src = tmp_path / "in" / "a.png" if kind == "folder" else tmp_path / "a.png"
        src.parent.mkdir(exist_ok=True)
        cv2.imwrite(str(src), frame)
    before = src.read_bytes()
    target = src.parent if kind == "folder" else src
    assert main(["normalize", str(target), str(target), "-m", "dog"]) == 2
    assert src.read_bytes() == before
    assert main(["normalize", str(target), str(target), "-m", "dog", "--in-place"]) == 0
    assert src.read_bytes() != before
    out = tmp_path / "out" / ("v.avi" if kind == "video" else "a.png")
    dst = out.parent if kind == "folder" else out
    assert main(["normalize", str(target), str(dst), "-m", "none"]) == 0
    assert main(["normalize", str(target), str(dst), "-m", "dog"]) == 2
    written = out.read_bytes()
    assert main(["normalize", str(target), str(dst), "-m", "dog", "--overwrite"]) == 0
    assert out.read_bytes() != written
    assert not list(tmp_path.rglob(".*")), "temporary file left behind"


def test_folder_with_bad_files_skip_bad_and_the_count(tmp_path, frame, caplog):
    src = tmp_path / "in"
    src.mkdir()
    for name in ("a.png", "c.png"):
        cv2.imwrite(str(src / name), frame)
    (src / "b.jpg").write_bytes(b"\xff\xd8 not a JPEG")
    (src / "notes.txt").write_text("not an image")
    assert main(["normalize", str(src), str(tmp_path / "out"), "-m", "none"]) == 2
    assert not (tmp_path / "out").exists()  # stopped before anything was written
    caplog.set_level("INFO")
    assert main(["normalize", str(src), str(tmp_path / "out"), "-m", "none", "--skip-bad"]) == 0
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["a.png", "c.png"]
    assert "wrote 2 images to" in caplog.text and "skipped 2 (1 not an image, 1 unreadable)" in caplog.text


SPECS = {  # issue 41, part 3: one spec syntax wherever a method is named; snake_case for OpenCV's camelCase
    "create": lambda spec: __import__("alcn_cv").create(spec),
    "from_spec": lambda spec: __import__("alcn_cv.enhance.registry", fromlist=["from_spec"]).from_spec(spec),
    "pose parts": lambda spec: __import__("pose.parts", fromlist=["x"]).from_spec(spec),
}


@pytest.mark.parametrize("where", SPECS)
@pytest.mark.parametrize(
    "spec, attrs",
    [
        ("dog:sigma1=1:sigma2=2", {"sigma1": 1.0, "sigma2": 2.0}),
        ("clahe:clip_limit=3:tile_grid_size=(4, 4)", {"clipLimit": 3.0, "tileGridSize": (4, 4)}),
        ("clahe:clipLimit=3", {"clipLimit": 3.0}),
    ],
)
def test_spec_strings_everywhere(where, spec, attrs):
    method = SPECS[where](spec)
    for key, value in attrs.items():
        assert getattr(method, key) == value, (where, spec, key)


def test_spec_strings_in_normalize(tmp_path, frame):
    src = tmp_path / "in.png"
    cv2.imwrite(str(src), frame)
    for name, args in {
        "spec.png": ["-m", "dog:sigma1=1:sigma2=2"],
        "params.png": ["-m", "dog", "-p", "sigma1=1", "-p", "sigma2=2"],
        "clahe_snake.png": ["-m", "clahe:clip_limit=3"],
        "clahe_camel.png": ["-m", "clahe", "-p", "clipLimit=3"],
    }.items():
        assert main(["normalize", str(src), str(tmp_path / name), *args]) == 0
    read = {p.name: cv2.imread(str(p)) for p in tmp_path.glob("*.png")}
    np.testing.assert_array_equal(read["spec.png"], read["params.png"])
    np.testing.assert_array_equal(read["clahe_snake.png"], read["clahe_camel.png"])
    assert main(["normalize", str(src), str(tmp_path / "x.png"), "-m", "dog:sigma1=1", "-p", "sigma1=2"]) == 2


def _cuda() -> bool:
    torch = pytest.importorskip("torch")
    return torch.cuda.is_available()


def _mixed_folder(folder, frame):
    """Colour, gray, 16-bit, alpha and two sizes: every kind the batched path groups and reassembles."""
    folder.mkdir()
    for i in range(5):
        cv2.imwrite(str(folder / f"c{i}.png"), np.roll(frame, 3 * i, axis=1))
    cv2.imwrite(str(folder / "gray.png"), frame[..., 1])
    cv2.imwrite(str(folder / "gray16.png"), frame[..., 1].astype(np.uint16) * 257)
    cv2.imwrite(str(folder / "rgba.png"), np.dstack([frame, frame[..., 0]]))
    cv2.imwrite(str(folder / "wide.png"), np.hstack([frame, frame]))
    return sorted(p.name for p in folder.iterdir())


@pytest.mark.parametrize("batch_size", [3, None])
@pytest.mark.parametrize("device", ["cpu", "cuda"])
def test_device_batches_give_the_per_frame_output(tmp_path, frame, device, batch_size, caplog):
    """``--device``: ALCN's apply_batch on the device, the output within a grey level of apply() on each frame; in
    one batch too (the default 32), where the 8- and 16-bit images of one size must still be batched apart."""
    if device == "cuda" and not _cuda():
        pytest.skip("no CUDA device: the CUDA path is checked on a GPU machine")
    names = _mixed_folder(tmp_path / "in", frame)
    caplog.set_level("INFO")
    assert main(["normalize", str(tmp_path / "in"), str(tmp_path / "each")]) == 0
    args = ["normalize", str(tmp_path / "in"), str(tmp_path / "batched"), "--device", device]
    assert main(args + ([] if batch_size is None else ["--batch-size", str(batch_size)])) == 0
    assert sorted(p.name for p in (tmp_path / "batched").iterdir()) == names
    for name in names:
        each = cv2.imread(str(tmp_path / "each" / name), cv2.IMREAD_UNCHANGED)
        batched = cv2.imread(str(tmp_path / "batched" / name), cv2.IMREAD_UNCHANGED)
        assert batched.shape == each.shape and batched.dtype == each.dtype, name
        one_level = 257 if each.dtype == np.uint16 else 1
        assert np.abs(batched.astype(int) - each.astype(int)).max() <= one_level, name
    assert "frames/s (9 frames in" in caplog.text and f"batches of {batch_size or 32} on {device}" in caplog.text


def test_device_on_a_video_keeps_order_and_count(tmp_path, frame, caplog):
    src = tmp_path / "in.avi"
    writer = cv2.VideoWriter(str(src), cv2.VideoWriter_fourcc(*"MJPG"), 10, (80, 60))
    for i in range(7):
        writer.write(np.roll(frame, 5 * i, axis=1))
    writer.release()
    caplog.set_level("INFO")
    assert main(["normalize", str(src), str(tmp_path / "each.avi")]) == 0
    assert main(["normalize", str(src), str(tmp_path / "batched.avi"), "--device", "cpu", "--batch-size", "3"]) == 0
    assert "7 frames in" in caplog.text and "batches of 3 on cpu" in caplog.text
    with VideoReader(tmp_path / "each.avi") as each, VideoReader(tmp_path / "batched.avi") as batched:
        pairs = list(zip(each, batched, strict=True))
    assert len(pairs) == 7
    for a, b in pairs:  # within a grey level before encoding; MJPG's quantization spreads a level a little
        diff = np.abs(a.astype(int) - b.astype(int))
        assert diff.mean() < 0.5 and diff.max() <= 8


def test_device_says_when_it_runs_another_mixture_than_the_frame_by_frame_path(tmp_path, frame, caplog):
    """`--device` runs the lite and paper models' Eq. 3 exactly, where their per-frame default is the pyramid (a few
    grey levels apart): it said nothing, and the help promised the same output within a grey level."""
    src = tmp_path / "in.png"
    cv2.imwrite(str(src), frame)
    caplog.set_level("INFO")
    cases = [("alcn:model=lite", True), ("alcn:model=paper", True), ("alcn:model=lite:mixture=exact", False)]
    for spec, told in [*cases, ("alcn", False)]:  # the paper file's header names no architecture
        caplog.clear()
        assert main(["normalize", str(src), str(tmp_path / f"{len(spec)}.png"), "-m", spec, "--device", "cpu"]) == 0
        assert ("--device runs Eq. 3 exactly" in caplog.text) is told, spec


def test_device_errors_are_one_line(tmp_path, frame, capsys):
    src = tmp_path / "in.png"
    cv2.imwrite(str(src), frame)
    for args, message in [
        (["-m", "dog", "--device", "cpu"], "--device runs ALCN's batched torch path"),
        (["-p", "backend=fast", "--device", "cpu"], "backend='torch'"),
        (["-p", "device=cuda", "--device", "cpu"], "--device cpu and the device parameter 'cuda' differ"),
        (["--device", "cpu", "--batch-size", "0"], "--batch-size must be positive"),
    ]:
        assert main(["normalize", str(src), str(tmp_path / "out.png"), *args]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0], (args, err)
    assert not (tmp_path / "out.png").exists()
    if not _cuda():
        assert main(["normalize", str(src), str(tmp_path / "out.png"), "--device", "cuda"]) == 2
        assert "torch sees no CUDA device" in capsys.readouterr().err


def test_help_explains_the_device(capsys):
    with pytest.raises(SystemExit):
        main(["normalize", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "--device DEV" in out and "--batch-size N" in out and "ALCN only" in out and "frames per second" in out


def test_a_missing_input_is_named_whatever_its_output(tmp_path, capsys):
    """A missing folder was judged by its name as an image, and the error blamed the output folder's name."""
    for src, dst in [("missing", "out"), ("missing.png", "o.png"), ("missing.mp4", "o.mp4")]:
        assert main(["normalize", str(tmp_path / src), str(tmp_path / dst), "-m", "none"]) == 2
        assert capsys.readouterr().err.strip().endswith(f"no such image, folder or video: {tmp_path / src}")
    assert not list(tmp_path.iterdir())


def test_counts_and_messages_read_as_sentences(tmp_path, frame, caplog, capsys):
    """`wrote 1 images`, `(1 frames in ...)`, `... and 12 more exist (--overwrite replaces it)`, `skipped cannot read
    image ...`: singular for one, `them` for several, the skipped image's reason after a colon."""
    src = tmp_path / "in"
    src.mkdir()
    cv2.imwrite(str(src / "a.png"), frame)
    (src / "b.png").write_bytes(b"\x89PNG not a PNG")
    caplog.set_level("INFO")
    assert main(["normalize", str(src), str(tmp_path / "out"), "-m", "none", "--skip-bad", "--no-progress"]) == 0
    assert "wrote 1 image to" in caplog.text and "(1 frame in" in caplog.text
    assert f"skipped an image: cannot read image {src / 'b.png'}: " in caplog.text
    cv2.imwrite(str(src / "b.png"), frame)
    cv2.imwrite(str(src / "c.png"), frame)
    (tmp_path / "out" / "c.png").write_bytes(b"")
    capsys.readouterr()
    assert main(["normalize", str(src), str(tmp_path / "out"), "-m", "none", "--no-progress"]) == 2
    assert (
        capsys.readouterr()
        .err.strip()
        .endswith(f": {tmp_path / 'out' / 'a.png'} and 1 more exist (--overwrite replaces them)")
    )
    assert main(["normalize", str(src / "a.png"), str(tmp_path / "out" / "a.png"), "-m", "none"]) == 2
    assert capsys.readouterr().err.strip().endswith("a.png exists (--overwrite replaces it)")


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (
            ["-m", "dog:sigma1=1", "-p", "sigma1=2"],
            "sigma1 given in the spec 'dog:sigma1=1' and again on its own (-p on the command line, a keyword in "
            "Python); give each once",
        ),
        (["-m", "clahe:tileGridSize=4"], "tileGridSize=4 must be a tuple, e.g. tileGridSize=(8,8)"),
        (["-m", "clahe", "-p", "clipLimit=abc"], "clipLimit='abc' must be a number, e.g. clipLimit=2.0"),
    ],
)
def test_a_bad_parameter_says_where_it_was_given_and_its_syntax(tmp_path, frame, capsys, args, says):
    cv2.imwrite(str(tmp_path / "a.png"), frame)
    assert main(["normalize", str(tmp_path / "a.png"), str(tmp_path / "out.png"), *args]) == 2
    assert capsys.readouterr().err.strip().endswith(says)


def test_device_runs_batches_of_batch_size(tmp_path, frame, monkeypatch):
    """``--batch-size 3`` on 5 frames of one size: apply_batch gets 3 frames, then 2."""
    pytest.importorskip("torch")
    from alcn_cv.enhance.alcn import ALCN

    sizes = []
    apply_batch = ALCN.apply_batch

    def recording(self, frames, *args, **kwargs):
        sizes.append(len(frames))
        return apply_batch(self, frames, *args, **kwargs)

    monkeypatch.setattr(ALCN, "apply_batch", recording)
    (tmp_path / "in").mkdir()
    for i in range(5):
        cv2.imwrite(str(tmp_path / "in" / f"{i}.png"), np.roll(frame, 3 * i, axis=1))
    args = ["normalize", str(tmp_path / "in"), str(tmp_path / "out"), "--device", "cpu", "--batch-size", "3"]
    assert main(args) == 0
    assert sizes == [3, 2]
