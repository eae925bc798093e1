"""Writing benchmark results: Markdown tables, figures, the machine, the command and the log of a run."""

from __future__ import annotations

import contextlib
import datetime
import logging
import os
import platform
import shlex
import sys
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from alcn_cv.extras import is_installed
from alcn_cv.io import atomic_path
from alcn_cv.malloc import kept_freed_memory

logger = logging.getLogger(__name__)

__all__ = [
    "can_draw",
    "command_line",
    "describe_machine",
    "listed",
    "log_to",
    "machine",
    "machine_cores",
    "markdown_table",
    "nan_to_none",
    "new_figure",
    "provenance",
    "save_figure",
    "spread",
    "spread_cell",
    "typed_command",
]


def _cell(value: Any, digits: int) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.{digits}f}"
    return str(value).replace("|", "\\|")


def nan_to_none(obj: Any) -> Any:
    """``obj`` with every NaN or infinity (a metric with nothing to measure) as None, for JSON;
    dicts and lists are copied recursively, NumPy floats become floats."""
    if isinstance(obj, dict):
        return {k: nan_to_none(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [nan_to_none(v) for v in obj]
    if isinstance(obj, (float, np.floating)):
        return None if not np.isfinite(obj) else float(obj)
    return obj


def spread_cell(spread: dict[str, Any] | None, digits: int = 3, runs: int | None = None) -> str | None:
    """A table's cell of a :func:`spread`: ``"mean ± std"``, the mean alone for one run (``± 0`` would read as a
    measured zero variance), None for none; ``runs`` (default: its values) counts the runs.

    Example:
        >>> spread_cell(spread([0.5, 0.7])), spread_cell(spread([0.5]))
        ('0.600 ± 0.141', '0.500')
    """
    if spread is None:
        return None
    one = (len(spread["values"]) if runs is None else runs) <= 1
    return f"{spread['mean']:.{digits}f}" + ("" if one else f" ± {spread['std']:.{digits}f}")


def sample_std(values: Sequence[float]) -> float:
    """The sample standard deviation (``ddof=1``) of a few runs' values, one per seed (their population deviation
    understates the spread of so few); 0 for one value. What every benchmark's ``±`` means."""
    return float(np.std(values, ddof=1)) if len(values) > 1 else 0.0


def spread(values: list[float]) -> dict[str, Any] | None:
    """``{"mean", "std", "values"}`` of a benchmark's runs (one per seed; ``std``: :func:`sample_std`); None for
    none."""
    return {"mean": float(np.mean(values)), "std": sample_std(values), "values": values} if values else None


def listed(names: Sequence[str], most: int) -> str:
    """The first ``most`` of ``names`` joined by commas, and how many more there are (a message's list of files).

    Example:
        >>> listed(["a.png", "b.png", "c.png"], 2)
        'a.png, b.png and 1 more'
    """
    return ", ".join(names[:most]) + (f" and {len(names) - most} more" if len(names) > most else "")


def markdown_table(headers: Sequence[str], rows: Sequence[Sequence[Any]], digits: int = 3) -> str:
    """A GitHub Markdown table; floats with ``digits`` decimals, ``None`` as ``-``."""
    lines = ["| " + " | ".join(headers) + " |", "|" + "|".join("---" for _ in headers) + "|"]
    lines += ["| " + " | ".join(_cell(v, digits) for v in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def machine() -> dict[str, Any]:
    """The machine a benchmark ran on: CPU, cores, load, Python and library versions (alcn-cv's included)."""
    import cv2
    import numpy as np

    from alcn_cv import __version__  # the package itself, imported by now (here, not at the top: it imports this)

    info: dict[str, Any] = {
        "alcn_cv": __version__,
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "opencv": cv2.__version__,
    }
    with contextlib.suppress(AttributeError, OSError):  # Linux only
        info["cpus_available"] = len(os.sched_getaffinity(0))
    with contextlib.suppress(AttributeError, OSError):  # not on Windows
        info["load_average_1_5_15"] = [round(v, 2) for v in os.getloadavg()]
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            names = [line.split(":", 1)[1].strip() for line in f if line.startswith("model name")]
        if names:
            info["cpu_model"] = names[0]
    except OSError:
        pass
    kept = kept_freed_memory()
    if kept is not None:
        info["malloc_kept"] = {"mmap_threshold": kept[0], "trim_threshold": kept[1]}
    if (torch := sys.modules.get("torch")) is not None:  # None: an import of torch blocked, as tests do
        info["torch"] = torch.__version__
        info["torch_threads"] = torch.get_num_threads()
        info["cuda"] = torch.cuda.get_device_name(0) if torch.cuda.is_available() else None
    return info


def provenance(command: str, conf: str | None) -> dict[str, Any]:
    """How a weight file was made, for its header: the command line that makes it again, the preset's name (None: a
    configuration of the user's), the :func:`machine` and the date (UTC, as the reports' ``experiment.date``)."""
    date = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
    return {"command": command, "conf": conf, "machine": machine(), "date": date}


def machine_cores(info: dict[str, Any]) -> Any:
    """The CPU cores a run had, from its :func:`machine` record: those it could use, else the machine's (``"?"``:
    neither recorded)."""
    return info.get("cpus_available", info.get("cpu_count", "?"))


def describe_machine(info: dict[str, Any] | None = None, short: bool = False) -> str:
    """One line of :func:`machine`'s description (default: the machine now), for a report: CPU,
    cores, load, versions; ``short``: the compact form of a table's provenance (the versions by name, the GPU always
    said, no platform)."""
    info = machine() if info is None else info
    if short:
        return _short_description(info)
    cpu = info.get("cpu_model", info.get("processor"))
    parts = [f"{cpu}, {machine_cores(info)} CPUs available"]
    if "load_average_1_5_15" in info:
        parts.append(f"load average (1, 5, 15 min) {', '.join(map(str, info['load_average_1_5_15']))}")
    versions = f"Python {info.get('python')}, NumPy {info.get('numpy')}, OpenCV {info.get('opencv')}"
    if info.get("torch"):
        versions += f", torch {info['torch']} ({info.get('torch_threads')} threads), CUDA: {info.get('cuda') or 'none'}"
    if info.get("malloc_kept"):
        kept = info["malloc_kept"]
        versions += (
            f"; glibc malloc keeps freed memory (mmap threshold {kept['mmap_threshold'] >> 20} MiB, "
            f"trim threshold {kept['trim_threshold'] >> 20} MiB)"
        )
    return "; ".join(parts + [versions, info.get("platform", "")]).rstrip("; ")


def _short_description(info: dict[str, Any]) -> str:
    cpu = info.get("cpu_model", info.get("processor", "?"))
    parts = [f"{cpu}, {machine_cores(info)} CPUs"]
    if "load_average_1_5_15" in info:
        parts.append("load " + ", ".join(str(v) for v in info["load_average_1_5_15"]))
    parts.append(", ".join(f"{k} {info[k]}" for k in ("python", "numpy", "opencv", "torch") if info.get(k)))
    parts.append(f"GPU: {info.get('cuda') or 'none'}")
    if info.get("malloc_kept"):
        parts.append("glibc malloc keeps freed memory (alcn_cv.keep_freed_memory)")
    return "; ".join(parts)


def typed_command(argv: Sequence[str]) -> str:
    """The ``alcn`` command line ``argv`` (the words after ``alcn``: ``args.argv`` of the parser of
    :func:`alcn_cv.cli.build_parser`) for a report: what was measured, so without the options that change nothing of
    it (replacing an earlier report, the progress bars, the log's and the errors' detail)."""
    return shlex.join(["alcn", *(a for a in argv if a not in _NOT_MEASURED)])


#: The options of an ``alcn`` command line that change nothing of what a report measured (:func:`typed_command`).
_NOT_MEASURED = frozenset({"--overwrite", "--no-progress", "--debug", "-v", "--verbose"})


def command_line(words: Sequence[str], options: dict[str, Any]) -> str:
    """A shell command line: ``words`` then ``--option value`` for every option (None and
    False left out, True as a bare flag, lists joined by commas), quoted for a POSIX shell."""
    args = [str(w) for w in words]
    for flag, value in options.items():
        if value is None or value is False:
            continue
        args.append(flag)
        if value is not True:
            args.append(",".join(map(str, value)) if isinstance(value, (list, tuple)) else str(value))
    return shlex.join(args)


def can_draw(command: str) -> bool:
    """Whether matplotlib is installed, for a benchmark of the light install (``command``, named in the warning it
    logs when not) that writes its tables without it and its figures with it."""
    if is_installed("matplotlib"):
        return True
    logger.warning("%s: matplotlib is not installed, so the report has no figure (pip install matplotlib)", command)
    return False


def new_figure(nrows: int = 1, ncols: int = 1, **kwargs: Any) -> tuple[Any, Any, np.ndarray]:
    """``(plt, fig, axes)`` from matplotlib's Agg backend (no display needed)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(nrows, ncols, squeeze=False, **kwargs)
    return plt, fig, axes


def save_figure(plt: Any, fig: Any, path: str | os.PathLike, dpi: int = 100) -> Path:
    """Save a figure as PNG atomically and close it."""
    path = Path(path)
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, format="png", dpi=dpi)
    finally:  # closed on a failed write too: pyplot keeps every open figure
        plt.close(fig)
    return path


@contextlib.contextmanager
def log_to(path: str | os.PathLike | logging.Handler, append: bool = False) -> Iterator[None]:
    """Copy the ``alcn_cv`` loggers' records to the file ``path`` (a run's ``train.log``), or to the handler given,
    while the block runs, at INFO level at least; an earlier file is replaced, unless ``append`` (a resumed run)."""
    if isinstance(path, logging.Handler):
        handler = path
    else:
        handler = logging.FileHandler(path, mode="a" if append else "w")
        handler.setFormatter(logging.Formatter("[%(asctime)s %(name)s %(levelname)s] %(message)s", "%Y/%m/%d %H:%M:%S"))
    root = logging.getLogger("alcn_cv")
    previous = root.level
    root.addHandler(handler)
    if root.getEffectiveLevel() > logging.INFO:
        root.setLevel(logging.INFO)
    try:
        yield
    finally:
        root.removeHandler(handler)
        root.setLevel(previous)
        handler.close()
