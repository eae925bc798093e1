"""alcn_cv.io: truncated images and videos, output paths under a file, alpha, interrupted writes."""

from __future__ import annotations

import contextlib
import logging
from pathlib import Path

import cv2
import numpy as np
import pytest

from alcn_cv import io
from alcn_cv.errors import InputError
from alcn_cv.io import (
    FrameReader,
    VideoReader,
    atomic_path,
    count_frames,
    eight_bits,
    held_folder,
    is_short,
    iter_frames,
    list_images,
    make_folder,
    map_video,
    new_folder,
    read_image,
    write_image,
)


@pytest.fixture
def image() -> np.ndarray:
    rng = np.random.default_rng(0)
    return cv2.GaussianBlur((rng.random((120, 160, 3)) * 255).astype(np.uint8), (0, 0), 2)


def _truncate(path, fraction=0.5):
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * fraction)])
    return path


@pytest.mark.parametrize("suffix", [".jpg", ".png"])
def test_truncated_image_is_an_error_naming_the_file(tmp_path, image, suffix):
    path = tmp_path / f"cut{suffix}"
    cv2.imwrite(str(path), image)
    assert read_image(path).shape == image.shape
    _truncate(path)
    with pytest.raises(InputError, match="cut" + suffix):
        read_image(path)


def test_truncated_jpeg_with_a_thumbnail_end_marker(tmp_path, image):
    """An EXIF thumbnail holds its own end-of-image marker before the main image's scan: it
    must not make a truncated file pass."""
    ok, encoded = cv2.imencode(".jpg", image)
    data = encoded.tobytes()
    payload = b"Exif\x00\x00" + b"\xff\xd8 thumbnail \xff\xd9"
    app1 = b"\xff\xe1" + (len(payload) + 2).to_bytes(2, "big") + payload
    full = data[:2] + app1 + data[2:]
    path = tmp_path / "thumb.jpg"
    path.write_bytes(full)
    assert read_image(path).shape == image.shape
    path.write_bytes(full[: len(full) // 2])
    # the check's own message: this OpenCV refuses a truncated JPEG itself ("corrupt, truncated or unsupported"),
    # which a looser match let stand in for a check that passed every file; libjpeg builds that decode one with
    # grey rows do not
    with pytest.raises(InputError, match="truncated or corrupt JPEG"):
        read_image(path)


def test_a_jpeg_is_turned_as_its_exif_orientation_says(tmp_path, image):
    """`alcn normalize` read a phone's portrait photograph (EXIF orientation 6: turn 90 degrees clockwise) as stored,
    on its side, where cv2.imread and every viewer turn it; the output, without the tag, stayed on its side."""
    data = cv2.imencode(".jpg", image)[1].tobytes()
    # a big-endian TIFF header and one IFD entry: tag 0x0112 (orientation), SHORT, 1 value, 6
    tiff = b"MM\x00*\x00\x00\x00\x08\x00\x01" + bytes.fromhex("0112 0003 00000001 0006 0000") + bytes(4)
    payload = b"Exif\x00\x00" + tiff
    (tmp_path / "turned.jpg").write_bytes(
        data[:2] + b"\xff\xe1" + (len(payload) + 2).to_bytes(2, "big") + payload + data[2:]
    )
    expected = cv2.imread(str(tmp_path / "turned.jpg"))
    assert expected.shape == (160, 120, 3)  # turned
    np.testing.assert_array_equal(read_image(tmp_path / "turned.jpg"), expected)
    gray = cv2.cvtColor(expected, cv2.COLOR_BGR2GRAY).astype(int)  # the codec's own gray: within a level or two
    assert np.abs(read_image(tmp_path / "turned.jpg", gray=True) - gray).max() <= 2
    cv2.imwrite(str(tmp_path / "gray.jpg"), image[..., 0])
    assert read_image(tmp_path / "gray.jpg").shape == (120, 160)  # a gray JPEG stays one channel


def test_empty_image_file(tmp_path):
    (tmp_path / "empty.png").write_bytes(b"")
    with pytest.raises(InputError, match="empty.png"):
        read_image(tmp_path / "empty.png")


def test_alpha_is_kept_on_request(tmp_path, image):
    bgra = np.dstack([image, np.arange(image.size // 3, dtype=np.uint32).reshape(image.shape[:2]).astype(np.uint8)])
    cv2.imwrite(str(tmp_path / "a.png"), bgra)
    np.testing.assert_array_equal(read_image(tmp_path / "a.png", alpha=True), bgra)
    assert read_image(tmp_path / "a.png").shape == image.shape


def test_gray_and_alpha_are_written_as_bgra(tmp_path, image):
    gray_alpha = np.dstack([image[..., 0], image[..., 1]])
    written = cv2.imread(str(write_image(tmp_path / "ga.png", gray_alpha)), cv2.IMREAD_UNCHANGED)
    assert written.shape == image.shape[:2] + (4,)
    np.testing.assert_array_equal(written[..., 2], image[..., 0])
    np.testing.assert_array_equal(written[..., 3], image[..., 1])


def test_a_16_bit_image_is_scaled_for_an_8_bit_format(tmp_path, image, caplog):
    """OpenCV would write 255 for every value above it: a white JPEG."""
    deep = image.astype(np.uint16) * 257
    np.testing.assert_array_equal(cv2.imread(str(write_image(tmp_path / "a.bmp", deep)), cv2.IMREAD_UNCHANGED), image)
    assert "scaled to 8 bits" in caplog.text
    kept = cv2.imread(str(write_image(tmp_path / "a.png", deep)), cv2.IMREAD_UNCHANGED)
    assert kept.dtype == np.uint16
    np.testing.assert_array_equal(kept, deep)


def test_16_bit_frames_and_8_bit_writes_share_one_conversion(tmp_path):
    """Every 16-bit value to round(x / 257) on both paths: 0 and 65535 exactly, the nearest level between (the top
    byte, x >> 8, is a level lower for most values)."""
    every = np.arange(65536, dtype=np.uint16).reshape(256, 256)
    write_image(tmp_path / "frames" / "deep.png", every)
    ((_, frame),) = iter_frames(tmp_path / "frames")
    written = cv2.imread(str(write_image(tmp_path / "deep.bmp", every)), cv2.IMREAD_GRAYSCALE)
    np.testing.assert_array_equal(frame, cv2.cvtColor(written, cv2.COLOR_GRAY2BGR))
    np.testing.assert_array_equal(written, np.rint(every / 257).astype(np.uint8))
    assert eight_bits(every)[[0, -1], [0, -1]].tolist() == [0, 255]


@pytest.mark.parametrize("name", ["noext", "x.mp4", "x.txt"])
def test_write_image_needs_an_image_extension(tmp_path, image, name):
    with pytest.raises(InputError, match=name):
        write_image(tmp_path / name, image)
    assert not list(tmp_path.iterdir())


def test_a_parent_that_is_a_file_is_named(tmp_path, image):
    (tmp_path / "file").write_text("x")
    with pytest.raises(InputError, match=r"file is a file") as info:
        write_image(tmp_path / "file" / "sub" / "x.png", image)
    assert str(tmp_path / "file") in str(info.value)
    with pytest.raises(InputError, match="is a file"):
        make_folder(tmp_path / "file")
    assert make_folder(tmp_path / "new" / "deeper").is_dir()


def test_a_folder_of_folders_says_subfolders_are_not_searched(tmp_path, image):
    """On the shared data's psm/ (four scenes in subfolders) the error said only 'no images in this folder'."""
    for name in ("a", "b"):
        (tmp_path / name).mkdir()
        cv2.imwrite(str(tmp_path / name / "0.png"), image)
    with pytest.raises(InputError, match="no images .* its 2 subfolder\\(s\\) are not searched"):
        list_images(tmp_path)


def test_a_failed_block_removes_the_empty_folders_it_created(tmp_path):
    """A command that fails leaves no empty output folder behind (a failed `alcn pose build` did)."""
    with pytest.raises(KeyboardInterrupt), new_folder(tmp_path / "a" / "b") as folder:
        assert folder.is_dir()
        raise KeyboardInterrupt
    assert not list(tmp_path.iterdir())
    (tmp_path / "a").mkdir()
    with pytest.raises(ValueError), new_folder(tmp_path / "a" / "b" / "c"):
        (tmp_path / "a" / "b" / "kept.txt").write_text("x")  # written in a folder it created: that one stays
        raise ValueError
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["a", "b", "kept.txt"]
    with new_folder(tmp_path / "ok") as folder:
        pass
    assert folder.is_dir()  # kept when the block succeeds, even empty


def test_a_held_folder_is_refused_to_another_holder_until_released(tmp_path):
    """Two runs never write into one folder at once: a second holder is refused with the first's process id, in
    this process (another open file) as from another process; the system releases a killed holder's hold."""
    import os
    import subprocess
    import sys

    folder = tmp_path / "out"
    with held_folder(folder) as held:
        assert held == folder and (folder / io.HOLD_FILE).read_text() == str(os.getpid())
        refused = f"^{folder} is in use by another run \\(process {os.getpid()}\\): wait"
        with pytest.raises(InputError, match=refused), held_folder(folder):
            pass
        assert folder.is_dir()  # the refused holder removes nothing
    assert list(folder.iterdir()) == []  # the hold file goes with the hold
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            f"from alcn_cv.io import held_folder\nwith held_folder({str(folder)!r}):\n"
            "    print('held', flush=True)\n    input()",
        ],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout.readline() == "held\n"
        with pytest.raises(InputError, match=f"process {holder.pid}"), held_folder(folder):
            pass
    finally:
        holder.kill()
        holder.wait()
    with held_folder(folder):  # killed: its hold file remains, its lock does not
        pass
    with pytest.raises(ValueError), held_folder(tmp_path / "new"):
        raise ValueError
    (tmp_path / "odd" / io.HOLD_FILE).mkdir(parents=True)  # a folder where the hold file goes: not writable as one
    with pytest.raises(InputError, match="^cannot write into .*odd \\("), held_folder(tmp_path / "odd"):
        pass
    assert not (tmp_path / "new").exists()  # a failed block's new folder is removed, hold file and all


def test_interrupt_leaves_no_temporary_file_and_temporary_files_are_no_inputs(tmp_path, image):
    with pytest.raises(KeyboardInterrupt), atomic_path(tmp_path / "out.png") as tmp:
        cv2.imwrite(str(tmp), image)  # a complete image under the temporary name
        raise KeyboardInterrupt
    assert not list(tmp_path.iterdir())
    cv2.imwrite(str(tmp_path / ".out.abc.tmp.png"), image)  # left by an older version
    cv2.imwrite(str(tmp_path / "real.png"), image)
    assert [p.name for p in list_images(tmp_path)] == ["real.png"]


def _video(path, frames: int, image: np.ndarray):
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10, image.shape[1::-1])
    for i in range(frames):
        writer.write(np.roll(image, 4 * i, axis=1))
    writer.release()
    return path


@pytest.mark.parametrize(("step", "max_frames"), [(1, None), (2, None), (3, 2), (4, 10)])
def test_count_frames_is_what_iter_frames_yields(tmp_path, image, step, max_frames):
    video = _video(tmp_path / "in.avi", 7, image)
    folder = tmp_path / "frames"
    folder.mkdir()
    for i in range(5):
        cv2.imwrite(str(folder / f"{i:02d}.png"), image)
    for source in (video, folder):
        assert count_frames(source, step, max_frames) == sum(1 for _ in iter_frames(source, step, max_frames))


def test_a_frame_reader_gives_the_frames_of_iter_frames_and_a_videos_frame_rate(tmp_path, image):
    video = _video(tmp_path / "in.avi", 5, image)
    folder = tmp_path / "frames"
    folder.mkdir()
    for i in range(3):
        cv2.imwrite(str(folder / f"{i:02d}.png"), image)
    for source, fps in ((video, 10.0), (folder, None)):
        with FrameReader(source, 2, 2) as frames:
            assert frames.fps == fps
            read = list(frames)
        expected = list(iter_frames(source, 2, 2))
        assert [name for name, _ in read] == [name for name, _ in expected] and len(read) == 2
        for (_, a), (_, b) in zip(read, expected, strict=True):
            np.testing.assert_array_equal(a, b)


def test_count_frames_of_what_iter_frames_refuses_is_unknown(tmp_path, image):
    (tmp_path / "empty").mkdir()
    cv2.imwrite(str(tmp_path / "one.png"), image)
    (tmp_path / "broken.avi").write_bytes(b"not a video")
    for source in ("empty", "one.png", "broken.avi", "missing.avi"):
        assert count_frames(tmp_path / source) is None


def test_truncated_video_is_an_error_unless_partial_is_allowed(tmp_path, image, caplog):
    src = _truncate(_video(tmp_path / "in.avi", 20, image), 0.6)
    dst = tmp_path / "out.avi"
    with pytest.raises(InputError, match=r"decoded \d+ of 20 frames"):
        map_video(src, dst, lambda frame: frame)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.avi"]  # no output that looks complete
    with caplog.at_level(logging.WARNING, logger="alcn_cv.io"):
        count = map_video(src, dst, lambda frame: frame, allow_partial=True)
    assert 0 < count < 20 and dst.is_file()
    assert f"decoded {count} of 20 frames" in caplog.text


def test_complete_video(tmp_path, image):
    src = _video(tmp_path / "in.avi", 6, image)
    assert map_video(src, tmp_path / "out.avi", lambda frame: frame) == 6


@pytest.mark.parametrize("suffix", sorted(io.VIDEO_SUFFIXES))
def test_every_video_extension_is_written_and_read_back(tmp_path, image, suffix):
    """A .webm output always failed (mp4v is no WebM codec); .ts and .3gp inputs were read as images."""
    src = _video(tmp_path / "in.avi", 30, image)
    assert map_video(src, tmp_path / f"out{suffix}", lambda frame: frame, progress=False) == 30
    assert sum(1 for _ in iter_frames(tmp_path / f"out{suffix}")) == 30


#: The containers with no codec tags, where OpenCV prints its warning for any code.
UNTAGGED = {".webm", ".mpg", ".mpeg", ".ts", ".mts", ".m2ts"}


@pytest.mark.parametrize("suffix", sorted(io.VIDEO_SUFFIXES - UNTAGGED))
def test_a_video_is_written_without_opencvs_tag_warning(tmp_path, image, capfd, suffix):
    """OpenCV prints "tag ... is not supported" (with fprintf: no log level silences it) for a four-letter code the
    container has no tag for: FLV's codec is its numeric tag. WebM and MPEG streams have no tags at all."""
    with io.open_video_writer(tmp_path / f"out{suffix}", 25.0, image.shape[1::-1]) as writer:
        writer.write(image)
    assert "not supported" not in capfd.readouterr().err


def test_a_video_that_cannot_be_written_is_named_not_its_temporary_file(tmp_path, image, monkeypatch):
    monkeypatch.setattr(cv2.VideoWriter, "isOpened", lambda self: False)
    src = _video(tmp_path / "in.avi", 2, image)
    with pytest.raises(OSError, match=r"cannot write video .*out\.mp4 \(") as info:
        map_video(src, tmp_path / "out.mp4", lambda frame: frame, progress=False)
    assert ".tmp" not in str(info.value)


@contextlib.contextmanager
def _file_size_limit(size: int):
    """Files of the process limited to ``size`` bytes: a write beyond fails (EFBIG; Python ignores SIGXFSZ), as on
    a full disk."""
    resource = pytest.importorskip("resource")
    previous = resource.getrlimit(resource.RLIMIT_FSIZE)
    resource.setrlimit(resource.RLIMIT_FSIZE, (size, previous[1]))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, previous)


@pytest.mark.parametrize("suffix", [".mp4", ".avi", ".mkv"])
def test_a_video_the_disk_cannot_hold_is_an_error_and_nothing_is_left(tmp_path, image, suffix):
    """`alcn normalize` to a video under a file size limit (or onto a full disk) logged every frame written, exited 0
    and left an unreadable file (mp4: no index; avi: 11 of 455 frames): OpenCV's write reports nothing. The writer
    checks its file when closed, before the output's rename; the pose overlay's video likewise."""
    from pose.track import OverlayWriter

    src = _video(tmp_path / "in.avi", 12, image)
    noise = np.random.default_rng(0).integers(0, 256, (12, *image.shape), dtype=np.uint8)  # too much to compress
    frames = iter(noise)
    with _file_size_limit(100_000), pytest.raises(OSError, match=rf"could not write video .*out{suffix}: .*12 frames"):
        map_video(src, tmp_path / f"out{suffix}", lambda frame: next(frames), progress=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.avi"]
    error = rf"could not write video .*o{suffix}"
    with _file_size_limit(100_000), pytest.raises(OSError, match=error), OverlayWriter(tmp_path / f"o{suffix}") as out:
        for i, frame in enumerate(noise):
            out.write(str(i), frame)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.avi"]
    # without the limit: written, and its frames read back
    frames = iter(noise)
    assert map_video(src, tmp_path / f"out{suffix}", lambda frame: next(frames), progress=False) == 12
    with OverlayWriter(tmp_path / f"o{suffix}") as out:
        for i, frame in enumerate(noise):
            out.write(str(i), frame)
    assert io.count_frames(tmp_path / f"o{suffix}") == 12


def test_an_image_the_disk_cannot_hold_says_why(tmp_path):
    """A full disk read "cannot write image ... (format or folder not writable)": OpenCV's imwrite says nothing of
    why. The encoded image is written by Python, whose error is kept, with the path."""
    noise = np.random.default_rng(0).integers(0, 256, (200, 200, 3), dtype=np.uint8)
    with _file_size_limit(10_000), pytest.raises(OSError, match=r"cannot write image .*big\.png: File too large"):
        write_image(tmp_path / "big.png", noise)
    assert list(tmp_path.iterdir()) == []
    write_image(tmp_path / "big.png", noise)
    np.testing.assert_array_equal(read_image(tmp_path / "big.png"), noise)


def test_an_error_while_writing_a_video_is_not_replaced_by_the_files_check(tmp_path, image):
    """On the way out of an error the writer is released, not checked: the file is discarded, and the check's
    error would hide the one that stopped the writing."""
    with pytest.raises(KeyError, match="stop"), io.open_video_writer(tmp_path / "v.mp4", 10.0, (160, 120)) as writer:
        writer.write(image)
        raise KeyError("stop")


def test_the_first_frames_of_a_video(tmp_path, image):
    src = _video(tmp_path / "in.avi", 6, image)
    assert map_video(src, tmp_path / "out.avi", lambda frame: frame, max_frames=4) == 4
    with VideoReader(tmp_path / "out.avi") as video:
        assert sum(1 for _ in video) == 4
    assert map_video(src, tmp_path / "all.avi", lambda frame: frame, max_frames=10) == 6
    with pytest.raises(InputError, match="max_frames must be positive"):
        map_video(src, tmp_path / "none.avi", lambda frame: frame, max_frames=0)


def test_a_header_one_frame_too_high_is_no_truncation(shared_data, tmp_path):
    """cookie_box/box.mp4's header says 456 frames, FFmpeg decodes 455: not a truncated video."""
    src = shared_data / "cookie_box" / "box.mp4"
    if not src.is_file():
        pytest.skip(f"{src} not found")
    assert map_video(src, tmp_path / "out.avi", lambda frame: frame[::8, ::8]) >= 455


def test_a_float_image_is_converted_for_an_integer_format(tmp_path, image, caplog):
    """OpenCV would saturate float32 intensities in [0, 1] to 0 and 1: a black image."""
    unit = image.astype(np.float32) / np.float32(255)
    eight = cv2.imread(str(write_image(tmp_path / "a.bmp", unit)), cv2.IMREAD_UNCHANGED)
    np.testing.assert_array_equal(eight, image)
    assert "written as uint8" in caplog.text
    sixteen = cv2.imread(str(write_image(tmp_path / "a.png", unit)), cv2.IMREAD_UNCHANGED)
    np.testing.assert_array_equal(sixteen, image.astype(np.uint16) * 257)
    kept = cv2.imread(str(write_image(tmp_path / "a.tif", unit)), cv2.IMREAD_UNCHANGED)
    assert kept.dtype == np.float32
    np.testing.assert_array_equal(kept, unit)


def test_a_function_that_holds_its_out_dir_refuses_a_second_run_into_it(tmp_path):
    """A benchmark's main holds its out_dir whether the command line or a script calls it."""
    from alcn_cv.io import holds_out_dir

    calls = []

    @holds_out_dir
    def main(settings: str, out_dir: str, overwrite: bool = False) -> str:
        """The docstring stays."""
        calls.append((settings, out_dir))
        assert (Path(out_dir) / io.HOLD_FILE).is_file()
        return "done"

    assert main("s", out_dir=tmp_path / "a") == "done" and main.__doc__ == "The docstring stays."
    with held_folder(tmp_path / "b"), pytest.raises(InputError, match="is in use by another run"):
        main("s", str(tmp_path / "b"))
    assert calls == [("s", tmp_path / "a")]


def test_frame_progress_ends_at_the_frames_there_were(capsys):
    """The cookie box video's header says 456 frames and FFmpeg decodes 455: the bars of `pose track`, `overlay-error`,
    `calib register` and `calib camera` stopped at 455/456."""
    from alcn_cv.io import frame_progress

    assert list(frame_progress(iter(range(3)), 4, desc="frames", mininterval=0)) == [0, 1, 2]
    assert "3/3" in capsys.readouterr().err.rsplit("\r", 1)[-1]
    for _ in frame_progress(iter(range(5)), 5, desc="frames", mininterval=0):  # stopped: the bar says where
        break
    assert "0/5" in capsys.readouterr().err.rsplit("\r", 1)[-1]


def test_count_frames_leaves_a_bad_step_to_the_reader(tmp_path):
    """`calib register --step 0` (from Python) ended in count_frames' ZeroDivisionError before the reader's message."""
    from alcn_cv.io import count_frames, iter_frames

    cv2.imwrite(str(tmp_path / "a.png"), np.zeros((4, 4), np.uint8))
    assert count_frames(tmp_path, step=0) is None
    with pytest.raises(InputError, match="step must be a positive integer"):
        next(iter_frames(tmp_path, step=0))


def test_a_video_two_frames_short_of_its_header_is_truncated():
    assert not is_short(455, 456)  # a header one frame too high (cookie_box/box.mp4)
    assert is_short(454, 456)
    assert not is_short(3, None) and not is_short(3, 0)


def test_files_that_belong_together_are_replaced_together(tmp_path):
    """A report's tables and figure (io.atomic_paths): all replaced when the block ends, none on an interrupt."""
    names = ["r.json", "r.md", "r.png"]
    for name in names:
        (tmp_path / name).write_text("earlier")
    with pytest.raises(KeyboardInterrupt), io.atomic_paths(*(tmp_path / n for n in names)) as paths:
        paths[0].write_text("new")
        paths[1].write_text("new")
        raise KeyboardInterrupt  # while the figure is drawn
    assert sorted(p.name for p in tmp_path.iterdir()) == names
    assert all((tmp_path / n).read_text() == "earlier" for n in names)
    with io.atomic_paths(*(tmp_path / n for n in names)) as paths:
        for path in paths:
            path.write_text("new")
    assert all((tmp_path / n).read_text() == "new" for n in names) and len(list(tmp_path.iterdir())) == 3


def test_a_ctrl_c_between_the_renames_waits_for_the_last(tmp_path, monkeypatch):
    """The renames ran one after the other with Ctrl-C live: one between two left the new figure beside the old
    tables. It is held until every file is renamed, then raised. Ctrl-C raises KeyboardInterrupt here also when the
    suite was started with SIGINT ignored (a background job of a non-interactive shell, as a CI runner may start it;
    the held signal was then delivered to that disposition and the test failed)."""
    import os
    import signal

    names = ["r.json", "r.md", "r.png"]
    for name in names:
        (tmp_path / name).write_text("earlier")
    replace = os.replace
    renamed = []

    def interrupted_replace(src, dst):
        renamed.append(Path(dst).name)
        replace(src, dst)
        if len(renamed) == 1:
            signal.raise_signal(signal.SIGINT)  # Ctrl-C right after the first rename

    monkeypatch.setattr(io.os, "replace", interrupted_replace)
    with (
        io.sigint_as_keyboard_interrupt(),
        pytest.raises(KeyboardInterrupt),
        io.atomic_paths(*(tmp_path / n for n in names)) as paths,
    ):
        for path in paths:
            path.write_text("new")
    assert renamed == names and all((tmp_path / n).read_text() == "new" for n in names)


def test_a_frame_of_another_size_or_colour_is_named_not_dropped(tmp_path, image):
    """OpenCV drops a frame of another size (or a gray one in a colour video) without a word; the check of the file
    then blamed a full disk. The writer names the frame."""
    src = _video(tmp_path / "in.avi", 6, image)
    seen = []

    def shrinks(frame):
        seen.append(frame)
        return frame if len(seen) < 4 else cv2.resize(frame, (32, 24))

    with pytest.raises(InputError, match=r"out.mp4: frame 3 is of shape \(24, 32, 3\), the video's frames BGR 160x120"):
        map_video(src, tmp_path / "out.mp4", shrinks, progress=False)
    gray = r"frame 1 is of shape \(120, 160\), the video's frames BGR 160x120"
    with pytest.raises(InputError, match=gray), io.open_video_writer(tmp_path / "v.mp4", 10.0, (160, 120)) as writer:
        writer.write(image)
        writer.write(image[..., 0])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.avi", "v.mp4"]  # v.mp4: no atomic_path around it


def test_a_folder_where_a_file_goes_is_refused_before_any_is_replaced(tmp_path):
    """Its rename failed after the others', which had replaced an earlier report's files already."""
    (tmp_path / "r.json").write_text("earlier")
    (tmp_path / "r.png").mkdir()
    error = r"cannot write .*r.png: a folder is there"
    with pytest.raises(OSError, match=error), io.atomic_paths(tmp_path / "r.json", tmp_path / "r.png") as paths:
        paths[0].write_text("new")
    assert (tmp_path / "r.json").read_text() == "earlier"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.json", "r.png"]


def test_an_interrupted_write_removes_the_folders_it_made(tmp_path):
    """A first run stopped before its renames left the empty folders made for its files."""
    with pytest.raises(KeyboardInterrupt), io.atomic_paths(tmp_path / "a" / "b" / "r.json", tmp_path / "r.md"):
        raise KeyboardInterrupt
    assert list(tmp_path.iterdir()) == []


def test_files_an_output_no_longer_writes_go_with_its_renames(tmp_path):
    """A report's earlier figure of an object it no longer shows was removed after its renames, apart from them."""
    for name in ("r.json", "r_a.png", "r_b.png"):
        (tmp_path / name).write_text("earlier")
    stale = list(tmp_path.glob("r_*.png"))
    with pytest.raises(KeyboardInterrupt), io.atomic_paths(tmp_path / "r.json", tmp_path / "r_a.png", stale=stale):
        raise KeyboardInterrupt
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.json", "r_a.png", "r_b.png"]  # none removed
    with io.atomic_paths(tmp_path / "r.json", tmp_path / "r_a.png", stale=stale) as paths:
        for path in paths:
            path.write_text("new")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.json", "r_a.png"]
    assert (tmp_path / "r_a.png").read_text() == "new"


def test_image_suffixes_are_matched_whatever_their_case(tmp_path, image):
    """Cameras write ``IMG_0001.JPG``: a suffix compared as written found no image in their folders."""
    cv2.imwrite(str(tmp_path / "b.png"), image)
    (tmp_path / "b.png").rename(tmp_path / "B.PNG")
    cv2.imwrite(str(tmp_path / "a.jpg"), image)
    (tmp_path / "a.jpg").rename(tmp_path / "A.JPG")
    assert [p.name for p in list_images(tmp_path)] == ["A.JPG", "B.PNG"]


def test_a_float_image_written_as_integers_is_rounded_not_truncated(tmp_path):
    """A float32 image in [0, 1] written to an 8- or 16-bit format is ``rint(255 x)`` (``rint(65535 x)``): truncated,
    every level but the exact ones came out one lower (a value of 0.6 levels as 0)."""
    levels = np.array([[0.4, 0.6, 1.6, 254.6]], np.float32)
    img = levels / np.float32(255)
    write_image(tmp_path / "f.png", img)
    np.testing.assert_array_equal(read_image(tmp_path / "f.png"), np.rint(img * np.float32(65535)).astype(np.uint16))
    write_image(tmp_path / "f.bmp", img)
    np.testing.assert_array_equal(read_image(tmp_path / "f.bmp"), [[0, 1, 2, 255]])


def test_a_mask_is_what_lies_above_127(tmp_path):
    """``read_mask``: True where the gray level is *above* 127; a mask of 127 and below marks nothing."""
    from alcn_cv.io import read_mask

    mask = np.full((8, 10), 127, np.uint8)
    cv2.imwrite(str(tmp_path / "m.png"), mask)
    with pytest.raises(InputError, match="no pixel above 127"):
        read_mask(tmp_path / "m.png")
    mask[2:4, 3:6] = 128
    cv2.imwrite(str(tmp_path / "m.png"), mask)
    np.testing.assert_array_equal(read_mask(tmp_path / "m.png"), mask == 128)
