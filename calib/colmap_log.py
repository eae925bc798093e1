"""pycolmap's own log (glog) sent to a Python logger: the one place that redirects it, for ``alcn calib register
--method sfm`` (:mod:`calib.register`) and ``alcn pose build`` (:mod:`pose.triangulate`).

Left alone, glog writes every message into log files of its own under the temporary folder
(``/tmp/<program>.<host>.<user>.log.<SEVERITY>.<date>.<pid>``, two or three per run, never removed) and its
warnings and errors to stderr (pycolmap's SIFT extraction with every thread warned in six lines on each run).
"""

from __future__ import annotations

import contextlib
import logging
import tempfile
from collections.abc import Iterator, Mapping
from pathlib import Path

__all__ = ["GLOG_LEVELS", "pycolmap_log"]

#: glog's first letter of a line -> the level it is logged at (pycolmap's warnings are routine:
#: "Discarding reconstruction due to insufficient size", "Your current options use the maximum number of threads").
GLOG_LEVELS: Mapping[str, int] = {"I": logging.DEBUG, "W": logging.DEBUG, "E": logging.WARNING, "F": logging.ERROR}


@contextlib.contextmanager
def pycolmap_log(target: logging.Logger) -> Iterator[None]:
    """Send pycolmap's log (glog) of the block to ``target`` instead of stderr and glog's own files.

    glog writes into a temporary file (``pycolmap.logging.set_log_destination``), read back and
    logged line by line when the block ends, at the level :data:`GLOG_LEVELS` gives its severity
    (info and warnings at debug level, errors as warnings), prefixed ``pycolmap:``. glog's separate
    warning and error files are turned off (the info file holds every severity).
    """
    import pycolmap

    glog = pycolmap.logging
    saved = glog.logtostderr, glog.alsologtostderr, glog.stderrthreshold
    with tempfile.TemporaryDirectory(prefix="alcn_pycolmap_log_") as tmp:
        glog.logtostderr, glog.alsologtostderr, glog.stderrthreshold = False, False, int(glog.FATAL)
        for severity in (glog.WARNING, glog.ERROR):
            glog.set_log_destination(severity, "")
        glog.set_log_destination(glog.INFO, str(Path(tmp) / "pycolmap."))
        try:
            yield
        finally:
            glog.set_log_destination(glog.INFO, "")  # closes (flushes) the file
            glog.logtostderr, glog.alsologtostderr, glog.stderrthreshold = saved
            for path in sorted(Path(tmp).iterdir()):
                for line in path.read_text(encoding="utf-8", errors="replace").splitlines():
                    level = GLOG_LEVELS.get(line[:1])
                    if level is not None and line[1:2].isdigit():  # skips the file's header lines
                        target.log(level, "pycolmap: %s", line.split("] ", 1)[-1])
