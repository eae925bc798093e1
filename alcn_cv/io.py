"""Reading and writing images and videos with OpenCV, with errors that name the file."""

from __future__ import annotations

import contextlib
import functools
import inspect
import json
import logging
import os
import signal
import tempfile
import threading
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor
from itertools import islice
from pathlib import Path
from typing import IO, Any, ParamSpec, TypeVar, cast

import cv2
import numpy as np
from tqdm import tqdm

from alcn_cv.checks import FULL_SCALE, check_array
from alcn_cv.errors import DatasetError, InputError

__all__ = [
    "IMAGE_SUFFIXES",
    "INTERRUPTS",
    "VIDEO_SUFFIXES",
    "FrameReader",
    "VideoFileWriter",
    "VideoReader",
    "atomic_path",
    "atomic_paths",
    "atomic_write",
    "check_no_earlier_output",
    "check_output_kind",
    "check_writable",
    "count_frames",
    "eight_bits",
    "frame_progress",
    "held_folder",
    "holds_out_dir",
    "interrupts_blocked",
    "interrupts_deferred",
    "sigint_as_keyboard_interrupt",
    "is_short",
    "is_video",
    "iter_frames",
    "list_images",
    "make_folder",
    "map_batches",
    "map_video",
    "open_video_writer",
    "read_image",
    "read_json",
    "read_mask",
    "to_gray",
    "write_image",
    "write_json",
]

logger = logging.getLogger(__name__)
T = TypeVar("T")
R = TypeVar("R")
P = ParamSpec("P")

IMAGE_SUFFIXES = frozenset(
    {".png", ".jpg", ".jpeg", ".jpe", ".bmp", ".tif", ".tiff", ".webp", ".avif", ".jp2", ".pgm", ".ppm", ".pnm"}
)
#: The image formats of :data:`IMAGE_SUFFIXES` that hold 8 bits a channel (the others hold 16).
EIGHT_BIT_SUFFIXES = frozenset({".jpg", ".jpeg", ".jpe", ".bmp", ".webp", ".avif"})
#: The image formats of :data:`IMAGE_SUFFIXES` that hold float32 pixels.
FLOAT_SUFFIXES = frozenset({".tif", ".tiff"})
VIDEO_SUFFIXES = frozenset(
    {".mp4", ".avi", ".mov", ".mkv", ".m4v", ".webm", ".mpg", ".mpeg", ".wmv", ".3gp", ".flv", ".ts", ".mts", ".m2ts"}
)
# the codec of each container that does not take mp4v (WebM: VP8/VP9/AV1 only; FLV: its own MPEG-4 variant, by
# FLV's numeric tag 2: its four letters make OpenCV print that FLV has no such tag). WebM and MPEG program and
# transport streams have no tags at all: OpenCV prints "tag ... is not supported" for any codec there (opencv#8919).
_FOURCC = {
    ".avi": cv2.VideoWriter.fourcc(*"MJPG"),
    ".mkv": cv2.VideoWriter.fourcc(*"MJPG"),
    ".webm": cv2.VideoWriter.fourcc(*"VP80"),
    ".flv": 2,
}
#: The process's umask, read once: the permissions of what is made under a temporary name.
UMASK = os.umask(0)
os.umask(UMASK)


def is_video(path: str | Path) -> bool:
    return Path(path).suffix.lower() in VIDEO_SUFFIXES


def list_images(folder: str | Path) -> list[Path]:
    """Image files directly inside ``folder``, sorted by name; hidden files (``.name``) are skipped.

    Raises:
        InputError: ``folder`` is not a folder or holds no image.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"not a folder: {folder}")
    # Hidden files are skipped: among them the temporary files of an interrupted atomic write.
    files = sorted(
        p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and not p.name.startswith(".") and p.is_file()
    )
    if not files:
        subfolders = sum(1 for p in folder.iterdir() if p.is_dir() and not p.name.startswith("."))
        nested = f"; its {subfolders} subfolder(s) are not searched: give one of them" if subfolders else ""
        raise InputError(f"{folder}: no images ({', '.join(sorted(IMAGE_SUFFIXES))}) in this folder{nested}")
    return files


def _jpeg_is_complete(data: bytes) -> bool:
    """Whether a JPEG stream reaches its end-of-image marker (``FF D9``).

    libjpeg decodes a truncated file with the missing rows grey and only prints a warning, so
    the structure is checked here: the marker segments are skipped by their length up to the
    first scan (so an EXIF thumbnail's own ``FF D9`` does not count), then the entropy-coded
    data, in which ``FF`` is always followed by ``00`` or a marker, is searched for ``FF D9``
    (ITU-T T.81, Annex B).
    """
    pos = 2  # after SOI
    while pos + 4 <= len(data):
        if data[pos] != 0xFF:
            return False
        marker = data[pos + 1]
        if marker == 0xFF:  # fill byte
            pos += 1
            continue
        if marker == 0xDA:  # start of scan: the rest is entropy-coded data and markers
            return data.find(b"\xff\xd9", pos) >= 0
        pos += 2 + int.from_bytes(data[pos + 2 : pos + 4], "big")
    return False


def read_image(path: str | Path, alpha: bool = False, gray: bool = False) -> np.ndarray:
    """Read an image as OpenCV does, keeping 16-bit depth: a JPEG turned as its EXIF orientation says, as
    ``cv2.imread`` turns it (a phone's portrait photograph).

    Args:
        alpha: keep an alpha channel (``HxWx4`` BGRA); by default it is dropped.
        gray: decode it as an 8-bit gray image (``cv2.IMREAD_GRAYSCALE``, the codec's own conversion).

    Returns:
        ``HxW`` grayscale, ``HxWx3`` BGR or, with ``alpha``, ``HxWx4`` BGRA; uint8 or uint16 (uint8 ``HxW`` with
        ``gray``).

    Raises:
        InputError: the file is missing, unreadable, corrupt or truncated.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"image not found: {path}")
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise InputError(f"cannot read image {path}: {exc.strerror}") from None
    jpeg = data[:2] == b"\xff\xd8"
    if jpeg and not _jpeg_is_complete(data):
        raise InputError(f"{path}: truncated or corrupt JPEG (no end-of-image marker)")
    # IMREAD_UNCHANGED keeps an alpha channel and ignores the EXIF orientation, which a JPEG (no alpha) needs
    unchanged = cv2.IMREAD_ANYDEPTH | cv2.IMREAD_ANYCOLOR if jpeg else cv2.IMREAD_UNCHANGED
    flag = cv2.IMREAD_GRAYSCALE if gray else unchanged
    img = cv2.imdecode(np.frombuffer(data, np.uint8), flag) if data else None
    if img is None or img.size == 0:
        raise InputError(f"cannot read image {path}: corrupt, truncated or unsupported format")
    if img.ndim == 3 and img.shape[2] == 4 and not alpha:
        logger.debug("dropping the alpha channel of %s", path)
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2BGR)
    if img.dtype not in (np.uint8, np.uint16):
        raise InputError(f"{path}: unsupported pixel type {img.dtype} (8- or 16-bit images only)")
    return img


def read_mask(path: str | Path) -> np.ndarray:
    """Read a mask image, white on the object and black elsewhere, as ``(H, W)`` bool: True where its 8-bit gray
    level is above 127 (a 0/1 mask reads as empty).

    Raises:
        InputError: the file cannot be read (:func:`read_image`), or no pixel is above 127 (the message says what a
            mask is).
    """
    mask = read_image(path, gray=True) > 127
    if not mask.any():
        raise InputError(f"{path}: no pixel above 127; a mask is white (255) on the object, black elsewhere")
    return mask


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path`` (same suffix) that becomes ``path`` when the block ends.

    The one atomic writer of the package: whatever writes the temporary file (``cv2.imwrite``,
    ``torch.save``, a zip writer), a reader never sees a half-written ``path``. On an error or an
    interrupt the temporary file is removed and ``path`` is left as it was. The file gets the
    usual permissions (``0666`` less the umask), the folder is created when missing.
    """
    with atomic_paths(path) as (tmp,):
        yield tmp


@contextlib.contextmanager
def atomic_paths(*paths: str | os.PathLike, stale: Iterable[str | os.PathLike] = ()) -> Iterator[list[Path]]:
    """:func:`atomic_path` of several files that belong together (a report's tables and its figures): each becomes
    its path when the whole block ends, in order, with Ctrl-C and SIGTERM held meanwhile
    (:func:`interrupts_deferred`); on an error or an interrupt in the block none does, and every path is left as it
    was (a folder made for them removed again). ``stale``: files of an earlier output that this one does not write
    again (a figure of an object no longer shown), removed with the renames; those among ``paths`` are replaced."""
    finals = [Path(path) for path in paths]
    removed = {Path(path) for path in stale} - set(finals)
    folder = next((path for path in finals if path.is_dir()), None)
    if folder is not None:  # its rename would fail after the others': checked before the block
        raise OSError(f"cannot write {folder}: a folder is there")
    made: list[Path] = []  # the folders that make_folder will make, each below the next
    for path in finals:
        folder = path.parent
        while folder not in made and not folder.exists():
            made.append(folder)
            folder = folder.parent
    temps: list[Path] = []
    try:
        for path in finals:
            make_folder(path.parent)
            try:
                fd, name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.", suffix=f".tmp{path.suffix}")
            except OSError as exc:  # its message would name the temporary file, not the one the caller gave
                raise OSError(f"cannot write {path}: {exc.strerror}") from None
            os.close(fd)
            temps.append(Path(name))
        yield list(temps)
        with interrupts_deferred():  # an interrupt between two renames would leave the files in part
            for tmp, path in zip(temps, finals):
                os.chmod(tmp, 0o666 & ~UMASK)  # mkstemp makes 0600 files
                try:
                    os.replace(tmp, path)
                except OSError as exc:
                    raise OSError(f"cannot write {path}: {exc.strerror}") from None
            for path in removed:
                path.unlink(missing_ok=True)
    except BaseException:
        for tmp in temps:
            tmp.unlink(missing_ok=True)
        for made_folder in sorted(made, key=lambda p: len(p.parts), reverse=True):  # the deepest first
            with contextlib.suppress(OSError):  # not empty: another writer's file is there
                made_folder.rmdir()
        raise


def check_writable(path: str | os.PathLike) -> None:
    """Check, before the work, that the file ``path`` can be created: a temporary file is made and
    removed in its folder, or the nearest folder above it that exists (which a permission check
    would not tell for root or a read-only file system).

    Raises:
        InputError: ``path`` lies under a file or its folder is not writable (the message names ``path``).
    """
    path = Path(path)
    folder = next(p for p in (path.parent.absolute(), *path.parent.absolute().parents) if p.exists())
    if not folder.is_dir():
        raise InputError(f"cannot write {path}: {folder} is a file")
    try:
        fd, name = tempfile.mkstemp(dir=folder, prefix=".alcn_write_check.")
    except OSError as exc:
        raise InputError(f"cannot write {path}: {folder} is not writable ({exc.strerror})") from None
    os.close(fd)
    os.unlink(name)


def check_no_earlier_output(paths: Iterable[str | os.PathLike], overwrite: bool) -> None:
    """Check, before the work, that a command replaces no earlier output unasked: unless ``overwrite``, none of the
    files ``paths`` (those the command writes) may exist.

    Raises:
        InputError: some of ``paths`` exist and not ``overwrite``; one line naming the first, how many more, and
            ``--overwrite``.
    """
    existing = [path for path in map(Path, paths) if path.exists()]
    if overwrite or not existing:
        return
    if len(existing) > 1:
        raise InputError(f"{existing[0]} and {len(existing) - 1} more exist (--overwrite replaces them)")
    raise InputError(f"{existing[0]} exists (--overwrite replaces it)")


def check_output_kind(source: str | os.PathLike, output: str | os.PathLike) -> None:
    """Check, before the work, that ``output`` can hold what a command makes of the existing ``source``: a folder for
    a folder of images, a video file for a video (:data:`VIDEO_SUFFIXES`), an image file for an image
    (:data:`IMAGE_SUFFIXES`); an existing folder is no file.

    Raises:
        InputError: another kind of output; the message names ``output``.
    """
    source, output = Path(source), Path(output)
    if source.is_dir():
        if output.exists() and not output.is_dir():
            raise InputError(f"the output of a folder must be a folder, but {output} is a file")
        if not output.exists() and (output.suffix.lower() in IMAGE_SUFFIXES or is_video(output)):
            raise InputError(f"the output of a folder must be a folder, got the file name {output}")
    elif is_video(source):
        if output.is_dir() or not is_video(output):
            raise InputError(f"the output of a video must be a video file (.mp4, .avi, ...), got {output}")
    elif output.is_dir():
        raise InputError(f"the output of an image must be an image file, but {output} is a folder")
    elif output.suffix.lower() not in IMAGE_SUFFIXES:
        raise InputError(
            f"the output of an image must be an image file ({', '.join(sorted(IMAGE_SUFFIXES))}), got {output}"
        )


def with_suffix(path: str | os.PathLike, suffix: str, what: str) -> Path:
    """``path``, which must end in ``suffix`` (the files written beside it are named after it).

    Raises:
        InputError: another suffix (the message names ``what``, e.g. "a weight file").
    """
    path = Path(path)
    if path.suffix != suffix:
        raise InputError(f"{what} must end in {suffix}, got {path}")
    return path


def output_path(path: str | os.PathLike, suffix: str, what: str) -> Path:
    """``path`` as the path of a file to write, checked before the work: :func:`with_suffix`, and it can be written
    (:func:`check_writable`).

    Raises:
        InputError: another suffix, or a folder that cannot be written.
    """
    path = with_suffix(path, suffix, what)
    check_writable(path)
    return path


def make_folder(folder: str | os.PathLike) -> Path:
    """Create ``folder`` and its parents when missing.

    Raises:
        InputError: ``folder`` or one of its parents exists as a file (named in the message).
    """
    folder = Path(folder)
    for existing in (folder, *folder.parents):
        if existing.exists():
            if not existing.is_dir():
                raise InputError(f"cannot create the folder {folder}: {existing} is a file")
            break
    folder.mkdir(parents=True, exist_ok=True)
    return folder


@contextlib.contextmanager
def new_folder(folder: str | os.PathLike) -> Iterator[Path]:
    """Create ``folder`` and its missing parents (:func:`make_folder`) for the block; on an error or an interrupt, the
    folders it created that are still empty are removed, so that a command that fails leaves no empty folder behind.

    Raises:
        InputError: as :func:`make_folder`.
    """
    folder = Path(folder)
    created = [p for p in (folder, *folder.parents) if not p.exists()]  # the innermost first
    make_folder(folder)
    try:
        yield folder
    except BaseException:
        for path in created:
            try:
                path.rmdir()
            except OSError:  # not empty (the block wrote there) or gone: it and those above stay
                break
        raise


#: The file in a folder that :func:`held_folder` holds, naming the process that holds it; removed when the block ends.
HOLD_FILE = ".alcn.lock"


@contextlib.contextmanager
def held_folder(folder: str | os.PathLike) -> Iterator[Path]:
    """Create ``folder`` as :func:`new_folder` does and hold it for the block: another process asking to hold it
    meanwhile is refused, so two runs of a command never write into one folder at once (the last to finish would
    replace the other's files). The hold is an advisory lock (``flock``) on ``folder/.alcn.lock``, which the system
    releases when the process ends, however it ends; where ``fcntl`` is missing (Windows) the folder is not held.

    Raises:
        InputError: another process holds ``folder`` (the message gives its process id); ``folder`` cannot be
            written; as :func:`make_folder`.
    """
    with new_folder(folder) as folder:
        try:
            import fcntl
        except ImportError:
            yield folder
            return
        path = folder / HOLD_FILE
        while True:
            try:  # "a+": the holder's process id is read, not truncated; closed below or by "with hold" once held
                hold = open(path, "a+", encoding="utf-8")  # noqa: SIM115
            except OSError as exc:
                raise InputError(f"cannot write into {folder} ({exc.strerror})") from None
            try:
                fcntl.flock(hold, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                hold.seek(0)
                holder = hold.read().strip() or "unknown"
                hold.close()
                raise InputError(
                    f"{folder} is in use by another run (process {holder}): wait for it to end, or give another --out"
                ) from None
            # held, unless the holder before removed the file between our open and lock: then hold the new one
            with contextlib.suppress(FileNotFoundError):
                if os.path.samestat(os.fstat(hold.fileno()), os.stat(path)):
                    break
            hold.close()
        with hold:
            hold.seek(0)
            hold.truncate()
            hold.write(str(os.getpid()))
            hold.flush()
            try:
                yield folder
            finally:
                path.unlink(missing_ok=True)  # before new_folder's cleanup, which removes only empty folders


def holds_out_dir(run: Callable[P, R]) -> Callable[P, R]:
    """``run``, a function of an ``out_dir`` argument (a command's ``main``), holding that folder while it runs
    (:func:`held_folder`): a second run into it meanwhile, from another process or this one, is refused at once,
    where it would pass the earlier-report check and the last run to finish would replace the other's report."""
    signature = inspect.signature(run)

    @functools.wraps(run)
    def held(*args: P.args, **kwargs: P.kwargs) -> R:
        with held_folder(signature.bind(*args, **kwargs).arguments["out_dir"]):
            return run(*args, **kwargs)

    return held


def atomic_write(path: str | os.PathLike, data: bytes | str | Callable[[IO[bytes]], object]) -> Path:
    """Write ``data`` to ``path`` atomically (:func:`atomic_path`).

    Args:
        data: bytes, text (written as UTF-8), or a function that writes into a binary file object.
    """
    path = Path(path)
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        if callable(data):
            data(f)
        else:
            f.write(data.encode("utf-8") if isinstance(data, str) else data)
    return path


def write_json(path: str | os.PathLike, obj: Any, *, indent: int | None = 1) -> Path:
    """Write ``obj`` as JSON atomically; NaN and infinity are refused (they are not JSON)."""
    return atomic_write(path, json.dumps(obj, indent=indent, allow_nan=False) + "\n")


def read_json(path: str | os.PathLike) -> Any:
    """Read a JSON file; a missing, empty, truncated or malformed file raises DatasetError."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise DatasetError(f"{path}: file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise DatasetError(f"{path}: cannot read ({exc})") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise DatasetError(
            f"{path}: malformed or truncated JSON at line {exc.lineno} column {exc.colno}: {exc.msg}"
        ) from None


def to_gray(image: np.ndarray) -> np.ndarray:
    """A uint8 ``HxW`` grayscale image from a gray or BGR uint8 one (the gray input itself, not a copy)."""
    if check_array(image).size == 0:
        raise InputError("image must be a non-empty numpy array")
    if image.dtype != np.uint8:
        raise InputError(f"image must be uint8, got {image.dtype}")
    if image.ndim == 2:
        return image
    if image.ndim == 3 and image.shape[2] == 3:
        return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    raise InputError(f"image must be HxW or HxWx3, got shape {image.shape}")


def eight_bits(img: np.ndarray) -> np.ndarray:
    """A uint16 image as uint8, each value ``x`` as ``round(x / 257)``: 0 and 65535 become 0 and 255 exactly, a
    16-bit image made from 8 bits (``x * 257``) its 8 bits again, and a value between two levels the nearest (the
    top byte, ``x >> 8``, is up to one level lower); no ``x / 257`` is a tie. The one 16-to-8-bit conversion of
    :func:`write_image` and :func:`iter_frames`."""
    return cv2.convertScaleAbs(img, alpha=1 / 257)


def write_image(path: str | Path, img: np.ndarray) -> Path:
    """Write an image atomically (:func:`atomic_path`), creating the folder.

    A grayscale image with alpha (``HxWx2``, which OpenCV cannot encode) is written as BGRA; a 16-bit image in a
    format of 8 bits a channel (:data:`EIGHT_BIT_SUFFIXES`) is scaled to 8 bits, with a warning; a float32 image
    (intensities in [0, 1], as :meth:`Normalization.apply <alcn_cv.enhance.base.Normalization.apply>` gives it) is
    written as it is to TIFF, and elsewhere converted to the format's 8 or 16 bits, with a warning (OpenCV would
    saturate it to 0 and 1: a black image).

    Raises:
        InputError: ``path`` has no image extension (:data:`IMAGE_SUFFIXES`) or lies under a file.
        OSError: the image cannot be encoded in that format, or the file cannot be written (the message says why).
    """
    path = Path(path)
    if path.suffix.lower() not in IMAGE_SUFFIXES:
        kind = "a folder" if path.is_dir() else "a video" if is_video(path) else "not an image file name"
        raise InputError(f"cannot write an image to {path} ({kind}); use one of {', '.join(sorted(IMAGE_SUFFIXES))}")
    if img.ndim == 3 and img.shape[2] == 2:
        img = np.dstack([cv2.cvtColor(img[..., 0], cv2.COLOR_GRAY2BGR), img[..., 1]])
    if img.ndim == 3 and img.shape[2] == 4 and path.suffix.lower() in (".jpg", ".jpeg", ".jpe"):
        logger.warning("%s has no alpha channel: the image's alpha is not written", path)
    if img.dtype == np.float32 and path.suffix.lower() not in FLOAT_SUFFIXES:
        deep = np.dtype(np.uint8 if path.suffix.lower() in EIGHT_BIT_SUFFIXES else np.uint16)
        logger.warning("%s holds integers: the float32 image (in [0, 1]) is written as %s", path, deep.name)
        img = np.rint(np.clip(img, 0.0, 1.0) * np.float32(FULL_SCALE[deep])).astype(deep)
    if img.dtype == np.uint16 and path.suffix.lower() in EIGHT_BIT_SUFFIXES:
        # OpenCV would saturate every value above 255 (a white image); scaled, as image tools convert
        logger.warning("%s holds 8 bits a channel: the 16-bit image is scaled to 8 bits", path)
        img = eight_bits(img)
    try:
        encoded, data = cv2.imencode(path.suffix, img)
    except cv2.error as exc:
        raise OSError(f"cannot write image {path}: {exc.err}") from None
    if not encoded:
        raise OSError(f"cannot write image {path}: OpenCV cannot encode this image in {path.suffix}")
    with atomic_path(path) as tmp:
        try:  # written here, not by OpenCV, whose imwrite says nothing of why (a full disk, a folder not writable)
            tmp.write_bytes(data.tobytes())
        except OSError as exc:
            raise OSError(exc.errno, f"cannot write image {path}: {exc.strerror}") from None
    return path


#: The signals the command line turns into exceptions (Ctrl-C, and SIGTERM as Ctrl-C): those a worker thread blocks
#: (:func:`signals_to_main_thread`) and a training step or the renames of a report hold (:func:`interrupts_deferred`).
INTERRUPTS = (signal.SIGINT, signal.SIGTERM)


@contextlib.contextmanager
def interrupts_blocked() -> Iterator[None]:
    """SIGINT and SIGTERM (:data:`INTERRUPTS`) blocked in the calling thread while the block runs (POSIX; elsewhere
    nothing is blocked): one that arrives meanwhile is delivered when the block ends, and threads started inside
    inherit the mask."""
    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, INTERRUPTS)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


@contextlib.contextmanager
def _handlers_while(handlers: dict[signal.Signals, Any]) -> Iterator[None]:
    """``handlers`` (signal to handler) installed while the block runs, swapped in and back with the interrupts
    blocked (:func:`interrupts_blocked`) so that none arrives between two swaps, SIGINT put back last (Ctrl-C comes
    most often); none outside the main thread, where Python installs none."""
    try:
        with interrupts_blocked():
            previous = {s: signal.signal(s, handler) for s, handler in handlers.items()}
    except ValueError:  # not the main thread
        yield
        return
    try:
        yield
    finally:
        with interrupts_blocked():
            for s in sorted(previous, key=lambda s: s == signal.SIGINT):
                signal.signal(s, previous[s])


@contextlib.contextmanager
def interrupts_deferred() -> Iterator[None]:
    """Hold Ctrl-C and SIGTERM (:data:`INTERRUPTS`; the command line raises SIGTERM as Ctrl-C) until the
    block ends, then deliver them to the handlers of before: no signal cuts the block short (an optimisation step and
    its counter, which a checkpoint must see together). Python handles signals in the main thread only, so another
    thread's block has nothing to hold.

    The handlers are swapped with both signals blocked (``pthread_sigmask``, POSIX), so that no signal arrives between
    two swaps (a handler of before raising there would leave the other signal to the temporary one for good); the
    held signals are raised once all are back. Without ``pthread_sigmask`` SIGINT is put back last."""
    held: list[int] = []
    kept = [s for s in INTERRUPTS if signal.getsignal(s) is not None]  # None: set outside Python, not to be put back
    try:
        with _handlers_while({s: lambda signum, frame: held.append(signum) for s in kept}):
            yield
    finally:
        for signum in dict.fromkeys(held):
            signal.raise_signal(signum)


@contextlib.contextmanager
def sigint_as_keyboard_interrupt() -> Iterator[None]:
    """Make sure Ctrl-C raises KeyboardInterrupt while the block runs (a parent may have set SIGINT to be ignored)."""
    with _handlers_while({signal.SIGINT: signal.default_int_handler}):
        yield


@contextlib.contextmanager
def signals_to_main_thread() -> Iterator[None]:
    """Threads started inside (OpenCV's FFmpeg threads, the pipeline's workers) block SIGINT and
    SIGTERM, so that the main thread takes them, where Python raises: delivered to a decoder or an
    encoder thread, a signal interrupts FFmpeg mid-frame (seen: a crash instead of the cleanup)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    with interrupts_blocked():
        yield


def block_interrupts() -> None:
    """Block SIGINT and SIGTERM in the calling worker thread (a thread pool's ``initializer``): the
    main thread takes them (see :func:`signals_to_main_thread`)."""
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_BLOCK, INTERRUPTS)


class VideoReader:
    """Frames of a video file, as an iterator of BGR uint8 arrays.

    Example:
        >>> with VideoReader("box.mp4") as video:  # doctest: +SKIP
        ...     for frame in video: ...
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise InputError(f"video not found: {self.path}")
        with signals_to_main_thread():  # FFmpeg's decoder threads start here
            self._cap = cv2.VideoCapture(str(self.path))
        if not self._cap.isOpened():
            raise InputError(f"cannot open video {self.path}: corrupt or unsupported format")
        self.fps = self._cap.get(cv2.CAP_PROP_FPS) or 30.0
        self.frame_count = int(self._cap.get(cv2.CAP_PROP_FRAME_COUNT))
        self.size = (int(self._cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(self._cap.get(cv2.CAP_PROP_FRAME_HEIGHT)))

    def frames(self, step: int = 1) -> Iterator[tuple[int, np.ndarray]]:
        """``(index, frame)`` for every ``step``-th frame; the frames between are grabbed, not decoded."""
        index = 0
        while self._cap.grab():
            if index % step == 0:
                ok, frame = self._cap.retrieve()
                if not ok:
                    return
                yield index, frame
            index += 1

    def __iter__(self) -> Iterator[np.ndarray]:
        for _, frame in self.frames():
            yield frame

    def __len__(self) -> int:
        return self.frame_count

    def close(self) -> None:
        self._cap.release()

    def __enter__(self) -> VideoReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class FrameReader:
    """The frames of :func:`iter_frames` (same arguments, frames, names and errors), with the frame rate of a video:
    an iterator of ``(name, BGR uint8 frame)``, one pass. The source is opened and checked here, not at the first
    frame; close the reader (or use it as a context manager) to release a video.

    Attributes:
        fps: the video's frame rate (:attr:`VideoReader.fps`); None for a folder of images, which has none.

    Raises:
        InputError: what :func:`iter_frames` raises; a video that holds no decodable frame at the end of the pass.
    """

    def __init__(self, source: str | os.PathLike, step: int = 1, max_frames: int | None = None) -> None:
        source = Path(source)
        if isinstance(step, bool) or not isinstance(step, int) or step < 1:
            raise InputError(f"step must be a positive integer, got {step!r}")
        if max_frames is not None and max_frames < 1:
            raise InputError(f"max_frames must be a positive integer or None, got {max_frames!r}")
        self._video: VideoReader | None = None
        if source.is_dir():
            frames = self._images(list_images(source)[::step])
        elif not source.exists():
            raise InputError(f"no such video or folder: {source}")
        elif not is_video(source):
            raise InputError(f"{source}: not a video ({', '.join(sorted(VIDEO_SUFFIXES))}) or a folder of images")
        else:
            self._video = VideoReader(source)
            frames = self._video_frames(self._video, step)
        self.fps = None if self._video is None else self._video.fps
        # stops without reading past the last frame wanted
        self._frames = islice(frames, max_frames)

    @staticmethod
    def _images(paths: list[Path]) -> Iterator[tuple[str, np.ndarray]]:
        for path in paths:
            img = read_image(path)  # without alpha
            if img.dtype != np.uint8:
                img = eight_bits(img)
            yield path.stem, img if img.ndim == 3 else cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)

    @staticmethod
    def _video_frames(video: VideoReader, step: int) -> Iterator[tuple[str, np.ndarray]]:
        count = 0
        for index, frame in video.frames(step):
            count += 1
            yield f"frame_{index:06d}", frame
        if count == 0:
            raise InputError(f"{video.path}: the video holds no decodable frame")

    def __iter__(self) -> FrameReader:
        return self

    def __next__(self) -> tuple[str, np.ndarray]:
        return next(self._frames)

    def close(self) -> None:
        if self._video is not None:
            self._video.close()

    def __enter__(self) -> FrameReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def iter_frames(
    source: str | os.PathLike, step: int = 1, max_frames: int | None = None
) -> Iterator[tuple[str, np.ndarray]]:
    """``(name, BGR uint8 frame)`` for every ``step``-th frame of a video file or image of a folder.

    The one frame iterator of the package (a :class:`FrameReader`, which also gives a video's frame rate, as a
    generator: nothing is opened before the first frame is asked for). Images of a folder are read in name order
    (16-bit images are reduced to 8 bits, grayscale ones converted to BGR) and named by their stem; video frames are
    named ``frame_000000``, ``frame_000001``, ... by their index in the video.

    Args:
        source: a video file (:data:`VIDEO_SUFFIXES`) or a folder of images.
        step: keep every ``step``-th frame (frames in between are skipped without decoding).
        max_frames: stop after this many frames.

    Raises:
        InputError: no such file or folder, a folder without images, a video that cannot be
            opened or holds no decodable frame, ``step < 1``.
    """
    with FrameReader(source, step, max_frames) as frames:
        yield from frames


def count_frames(source: str | os.PathLike, step: int = 1, max_frames: int | None = None) -> int | None:
    """How many frames :func:`iter_frames` yields for the same arguments: a progress bar's total.

    ``None`` when that is unknown: a video whose container does not say, or a source or ``step``
    :func:`iter_frames` refuses (it says why when it is read).
    """
    if isinstance(step, bool) or not isinstance(step, int) or step < 1:
        return None
    source = Path(source)
    try:
        if source.is_dir():
            total = len(list_images(source))
        elif is_video(source):
            with VideoReader(source) as video:
                total = len(video)
        else:
            return None
    except InputError:
        return None
    if total <= 0:
        return None
    count = -(-total // step)
    return count if max_frames is None else min(count, max_frames)


def frame_progress(frames: Iterable[T], total: int | None, **bar: Any) -> Iterator[T]:
    """``frames`` under a tqdm progress bar (``bar``: tqdm's arguments, ``unit="frame"`` unless given) whose ``total``
    is an estimate, :func:`count_frames`'s: a video's header often counts one frame more than it holds (the shared
    ``cookie_box/box.mp4`` says 456 and decodes 455), so when the frames end the bar ends at those there were, not
    short of a total that never comes. A frame is counted once the loop's body has done it.

    Example:
        >>> sum(1 for _ in frame_progress(range(3), total=4, disable=True))
        3
    """
    with tqdm(total=total, **{"unit": "frame", **bar}) as progress:
        for frame in frames:
            yield frame
            progress.update()
        progress.total = progress.n


class VideoFileWriter:
    """A ``cv2.VideoWriter`` (:func:`open_video_writer`) that refuses frames of another size or colour than its own
    and counts the frames written, and, finished by :meth:`close`, checks that its file holds them: OpenCV's ``write``
    reports nothing when it drops a frame (another size) or FFmpeg cannot write (a full disk, a file size limit), and
    the file would be unreadable or short. As a context manager it is closed on the way out, or, on the way out of
    an error, released unchecked (the check's own error would replace the error; the caller discards the file).

    Attributes:
        path: the file written; name: the path an error names (the output's, when ``path`` is a temporary name for
            it); size: ``(width, height)`` of its frames; color: whether they are BGR (else gray); frames: the frames
            written.
    """

    def __init__(
        self, writer: cv2.VideoWriter, path: Path, name: str | Path, size: tuple[int, int], color: bool
    ) -> None:
        self._writer = writer
        self.path, self.name, self.size, self.color = path, name, size, color
        self.frames = 0

    def write(self, frame: np.ndarray) -> None:
        """Write a uint8 frame of :attr:`size`, BGR ``HxWx3`` where :attr:`color`, else gray ``HxW`` (or ``HxWx1``).

        Raises:
            InputError: a frame of another size or colour, which OpenCV would drop without a word.
        """
        color, gray = frame.ndim == 3 and frame.shape[2] == 3, frame.ndim == 2 or frame.shape[2:] == (1,)
        if frame.shape[1::-1] != self.size or color != self.color or not (gray or color):
            kind = "BGR" if self.color else "gray"
            raise InputError(
                f"{self.name}: frame {self.frames} is of shape {frame.shape}, the video's frames {kind} "
                f"{self.size[0]}x{self.size[1]}: a video's frames are of one size and colour"
            )
        self._writer.write(frame)
        self.frames += 1

    def release(self) -> None:
        """Finish the file (again: nothing), unchecked: the way out of an error."""
        self._writer.release()

    def close(self) -> None:
        """Finish the file, then check that it opens and holds the :attr:`frames` frames written: its last frame read
        where a seek puts it, or, where seeking is inexact (MPEG program streams), its frames counted.

        Raises:
            OSError: the file is unreadable or holds fewer frames: it could not be written.
        """
        self._writer.release()
        if self.frames == 0:
            return
        with signals_to_main_thread():  # FFmpeg's decoder threads start here
            capture = cv2.VideoCapture(str(self.path))
        try:
            if capture.isOpened():
                capture.set(cv2.CAP_PROP_POS_FRAMES, self.frames - 1)
                if capture.read()[0] and capture.get(cv2.CAP_PROP_POS_FRAMES) == self.frames:
                    return
                capture.set(cv2.CAP_PROP_POS_FRAMES, 0)
                if sum(1 for _ in iter(capture.grab, False)) >= self.frames:
                    return
        finally:
            capture.release()
        raise OSError(
            f"could not write video {self.name}: the encoder's file does not hold the {self.frames} frames written "
            "(a full disk, or a file size limit?)"
        )

    def __enter__(self) -> VideoFileWriter:
        return self

    def __exit__(self, error: type[BaseException] | None, *_: object) -> None:
        self.close() if error is None else self.release()


def open_video_writer(
    path: str | Path, fps: float, size: tuple[int, int], color: bool = True, *, name: str | Path | None = None
) -> VideoFileWriter:
    """A video writer for ``path``, its codec from the extension (:data:`_FOURCC`, else mp4v): OpenCV's, checked
    when closed (:class:`VideoFileWriter`).

    ``name``: the path an error names, when ``path`` is a temporary name for it (:func:`atomic_path`).

    Raises:
        OSError: OpenCV's FFmpeg cannot write that extension or codec.
    """
    path = Path(path)
    make_folder(path.parent)
    fourcc = _FOURCC.get(path.suffix.lower(), cv2.VideoWriter.fourcc(*"mp4v"))
    with signals_to_main_thread():  # FFmpeg's encoder threads start here
        writer = cv2.VideoWriter(str(path), fourcc, fps, size, color)
    if not writer.isOpened():
        raise OSError(f"cannot write video {name or path} (unsupported extension or codec)")
    return VideoFileWriter(writer, path, name or path, (int(size[0]), int(size[1])), color)


def map_batches(
    items: Iterable[T],
    fn: Callable[[list[T]], list[R]],
    write: Callable[[R], object],
    batch_size: int = 1,
    progress: tqdm | None = None,
) -> int:
    """``write(out)`` for every output of ``fn(batch)``, ``batch`` the next ``batch_size`` items (the last
    batch shorter), in order: the next batch is read from ``items`` and the previous one written in two
    threads while ``fn`` runs (OpenCV's decoding and encoding release the GIL). The one overlapped pipeline of
    the package (videos, folders, one frame or a batch at a time). An error in any of the three surfaces
    here, after the batch being read is finished.

    Returns:
        The number of items.
    """
    if batch_size < 1:
        raise InputError(f"batch size must be positive, got {batch_size}")
    source = iter(items)

    def read() -> list[T]:
        return list(islice(source, batch_size))

    def write_all(outs: list[R]) -> None:
        for out in outs:
            write(out)

    count = 0
    with (
        ThreadPoolExecutor(1, initializer=block_interrupts) as reading,
        ThreadPoolExecutor(1, initializer=block_interrupts) as writing,
    ):
        ahead = reading.submit(read)
        written = None
        while batch := ahead.result():
            ahead = reading.submit(read)
            outs = fn(batch)
            if written is not None:
                written.result()  # one batch in the encoder at a time; its error surfaces here
            written = writing.submit(write_all, outs)
            count += len(batch)
            if progress is not None:
                progress.update(len(batch))
        if written is not None:
            written.result()
    return count


def is_short(decoded: int, counted: int | None) -> bool:
    """Whether a video decoded fewer frames than ``counted`` (its header's count, or a part of it) by more than one:
    truncated or corrupt. A header's count is often one frame too high (the shared cookie_box/box.mp4 says 456, FFmpeg
    decodes 455), so a shortfall of one frame is not taken for truncation; ``counted`` None or 0: unknown."""
    return counted is not None and counted > 0 and decoded < counted - 1


def map_video(
    src: str | Path,
    dst: str | Path,
    fn: Callable[[np.ndarray], np.ndarray] | Callable[[list[np.ndarray]], list[np.ndarray]],
    desc: str | None = None,
    allow_partial: bool = False,
    batch_size: int | None = None,
    max_frames: int | None = None,
    progress: bool = True,
) -> int:
    """Write ``fn(frame)`` for every frame of the video ``src`` into the video ``dst``.

    The output is written under a temporary name and renamed when complete; its frame size and
    colour follow ``fn``'s first output, its frame rate the input's. A progress bar shows the
    frames. Decoding, ``fn`` and encoding overlap (:func:`map_batches`), the frames in order.

    Args:
        allow_partial: accept a video that ends more than one frame before the frame count of
            its header (a truncated file), with a warning; by default it is an error and ``dst``
            is not written.
        batch_size: ``fn`` takes a list of up to this many frames and returns their outputs (a GPU's
            batches); None: ``fn`` takes one frame.
        max_frames: stop after the first this many frames (None: every frame).
        progress: the progress bar.

    Returns:
        The number of frames written.

    Raises:
        InputError: ``src`` cannot be opened, holds no decodable frame, or (without
            ``allow_partial``) fewer frames than its header says.
    """
    if max_frames is not None and max_frames < 1:
        raise InputError(f"max_frames must be positive, got {max_frames}")
    src, dst = Path(src), Path(dst)
    writer = None
    per_frame = cast(Callable[[np.ndarray], np.ndarray], fn)
    batched = (
        cast(Callable[[list[np.ndarray]], list[np.ndarray]], fn)
        if batch_size is not None
        else (lambda frames: [per_frame(frames[0])])
    )
    with atomic_path(dst) as tmp:
        try:
            with VideoReader(src) as video:

                def write(out: np.ndarray) -> None:
                    nonlocal writer
                    if writer is None:
                        writer = open_video_writer(
                            tmp, video.fps, (out.shape[1], out.shape[0]), color=out.ndim == 3, name=dst
                        )
                    writer.write(out)

                # the frames wanted by the header's count (0: unknown) and max_frames
                limit = video.frame_count if max_frames is None else min(video.frame_count, max_frames)
                with tqdm(total=limit or max_frames, desc=desc or src.name, unit="frame", disable=not progress) as bar:
                    count = map_batches(islice(video, max_frames), batched, write, batch_size or 1, bar)
                    bar.total = count  # the header's count is an estimate: the bar ends at the frames decoded
                    bar.refresh()
        finally:
            if writer is not None:
                writer.release()
        if writer is None:
            raise InputError(f"no frame could be decoded from {src}")
        if is_short(count, limit):
            message = f"{src}: decoded {count} of {video.frame_count} frames (truncated or corrupt video)"
            if not allow_partial:
                raise InputError(f"{message}; nothing written (--allow-partial keeps the decoded frames)")
            logger.warning("%s; wrote the %d decoded frames", message, count)
        writer.close()  # checked before the rename
    return count
