"""Optional extras: which extra of alcn-cv installs a package, and the one-line error naming it.

The base install (NumPy, SciPy, tqdm, and the OpenCV the app already has: :func:`require_opencv`)
runs every normalization; training, the data
engine, benchmarks and pose need extras (``pip install "alcn-cv[train]"``, ...). A command or
function that needs a package that is not installed raises
:class:`~alcn_cv.errors.MissingDependencyError`, whose message names the extra, read from the
installed metadata of the distribution.
"""

from __future__ import annotations

import importlib.util
import re
from collections.abc import Sequence
from importlib import metadata

from alcn_cv.errors import MissingDependencyError

__all__ = [
    "OPENCV_MINIMUM",
    "TORCH_CPU_INDEX",
    "extra_providing",
    "is_installed",
    "missing_dependency",
    "missing_extra",
    "require",
    "require_opencv",
]

DISTRIBUTION = "alcn-cv"

#: Import names whose distributions are named otherwise (the others are named as they import).
_DISTRIBUTIONS_OF = {
    "skimage": ("scikit-image",),
    "PIL": ("pillow",),
    "open3d": ("open3d", "open3d-cpu"),
    "cv2": ("opencv-contrib-python-headless", "opencv-python", "opencv-python-headless", "opencv-contrib-python"),
}
#: Extras that only gather others, or tools for developers: never the one to name.
_GATHERING_EXTRAS = ("all", "dev")


def _normalized(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def _extras_table() -> dict[str, list[str]]:
    """Each extra's requirements, from the installed metadata of alcn-cv."""
    try:
        requirements = metadata.requires(DISTRIBUTION) or []
    except metadata.PackageNotFoundError:
        return {}
    table: dict[str, list[str]] = {}
    for requirement in requirements:
        marker = re.search(r"""extra\s*==\s*["']([\w.-]+)["']""", requirement)
        if marker:
            table.setdefault(marker.group(1), []).append(requirement)
    return table


def _extras_requirements() -> dict[str, set[str]]:
    """Each extra and the distributions it installs (``alcn-cv[a,b]`` within it expanded)."""
    direct: dict[str, set[str]] = {}
    for extra, requirements in _extras_table().items():
        for requirement in requirements:
            name = re.match(r"\s*([A-Za-z0-9][\w.-]*)(?:\[([^\]]*)\])?", requirement)
            if name and _normalized(name.group(1)) == DISTRIBUTION:
                direct.setdefault(extra, set()).update(
                    f"[{e.strip()}]" for e in (name.group(2) or "").split(",") if e.strip()
                )
            elif name:
                direct.setdefault(extra, set()).add(_normalized(name.group(1)))

    def expand(extra: str, seen: frozenset[str] = frozenset()) -> set[str]:
        found: set[str] = set()
        for entry in direct.get(extra, ()):
            if entry.startswith("["):
                if entry[1:-1] not in seen:
                    found |= expand(entry[1:-1], seen | {extra})
            else:
                found.add(entry)
        return found

    return {extra: expand(extra) for extra in direct}


def extra_providing(module: str, preferred: str | None = None) -> str | None:
    """The extra of alcn-cv that installs the package of ``module`` (an import name).

    Read from the installed metadata. ``preferred`` (for instance the command that failed) wins when
    it installs the package; otherwise the extra that installs the fewest packages. None when no
    extra installs it or alcn-cv is not installed.
    """
    top = module.split(".")[0]
    wanted = {_normalized(name) for name in _DISTRIBUTIONS_OF.get(top, (top,))}
    candidates = {
        extra: dists
        for extra, dists in _extras_requirements().items()
        if wanted & dists and extra not in _GATHERING_EXTRAS
    }
    if not candidates:
        return None
    if preferred in candidates:
        return preferred
    return min(candidates, key=lambda extra: (len(candidates[extra]), extra))


def missing_dependency(module: str | Sequence[str], what: str, preferred: str | None = None) -> MissingDependencyError:
    """The error for ``what`` (a command or function) needing ``module`` (or several modules), not installed.

    Its message is one line naming the extra to install, e.g.
    ``alcn data phos: needs the [data] extra (skimage is not installed): pip install "alcn-cv[data]"``; for modules
    of several extras, all of them at once (``needs the [train,data] extras (torch, skimage are not installed):
    ... pip install "alcn-cv[train,data]"``). Where the install brings torch and torch is not installed, the line says
    to install torch's CPU build first when no GPU is wanted (:data:`TORCH_CPU_INDEX`). ``pip install
    "alcn-cv[EXTRA]"`` needs no index that has alcn-cv (it is not on PyPI): pip reads the extra's requirements from the
    alcn-cv installed (from a clone or a wheel) and keeps it.
    """
    modules = [module] if isinstance(module, str) else list(module)
    tops = list(dict.fromkeys(name.split(".")[0] for name in modules))
    extras = [extra_providing(name, preferred) for name in tops]
    if None in extras:
        top = tops[extras.index(None)]
        install = f"pip install {_DISTRIBUTIONS_OF.get(top, (top,))[0]}"
        if top == "torch":
            install += f" (without a GPU: --index-url {TORCH_CPU_INDEX})"
        return MissingDependencyError(f"{what}: needs {top}, which is not installed: {install}")
    unique = list(dict.fromkeys(e for e in extras if e is not None))
    named = ",".join(unique)
    installs_torch = any("torch" in _extras_requirements().get(extra, set()) for extra in unique)
    error = MissingDependencyError(
        f"{what}: needs the [{named}] extra{'s' if len(unique) > 1 else ''} ({', '.join(tops)} "
        f"{'are' if len(tops) > 1 else 'is'} not installed): {_torch_first(installs_torch)}pip install "
        f'"{DISTRIBUTION}[{named}]"'
    )
    error.extra = named
    return error


#: PyTorch's index of its CPU builds: on Linux, an unpinned ``pip install torch`` installs the CUDA build from PyPI
#: (several GB of nvidia-* packages).
TORCH_CPU_INDEX = "https://download.pytorch.org/whl/cpu"


def _torch_first(installs_torch: bool) -> str:
    """Where an install brings torch and torch is not installed, the command that installs its CPU build first (pip
    then keeps the torch it finds installed); else nothing."""
    if not installs_torch or is_installed("torch"):
        return ""
    return f"without a GPU, first pip install torch --index-url {TORCH_CPU_INDEX}; then "


#: The oldest OpenCV the runtime is tested with (every method; ALCN's gain Normalizers run by
#: ``cv2.dnn`` need OpenCV 4.8, or torch for ``backend="fast"``); calibration's ChArUco boards need 4.7.
OPENCV_MINIMUM = (4, 5, 5)
_INSTALL_OPENCV = (
    f'pip install "{DISTRIBUTION}[opencv]" (or any one of opencv-python, opencv-python-headless, '
    "opencv-contrib-python, opencv-contrib-python-headless)"
)


def opencv_version() -> tuple[int, int, int]:
    """The installed OpenCV's ``(major, minor, patch)``, from ``cv2.__version__`` (``"4.10.0"``, ``"5.0.0-alpha"``,
    ``"4.8.0-dev"``: the numbers before any suffix)."""
    import cv2

    major, minor, patch = ([int(part) for part in re.findall(r"\d+", cv2.__version__)] + [0, 0, 0])[:3]
    return major, minor, patch


def require_opencv() -> None:
    """Raise one line saying how to install OpenCV when ``cv2`` is missing or older than
    :data:`OPENCV_MINIMUM`. alcn-cv requires no OpenCV wheel: it uses whichever of the four the
    app has (requiring one would install it beside the app's and take over the ``cv2`` module).

    Raises:
        MissingDependencyError: no ``cv2`` module, one that fails to import (an OpenCV before 4.10, built for NumPy 1,
            under NumPy 2), or one too old (``extra`` is ``"opencv"``).
    """
    if not is_installed("cv2"):
        error = MissingDependencyError(
            f"alcn-cv needs OpenCV (the cv2 module), which is not installed: {_INSTALL_OPENCV}"
        )
    else:
        try:
            version = opencv_version()
        except ImportError as exc:
            import numpy

            hint = "reinstall it"
            if int(numpy.__version__.split(".")[0]) >= 2:
                hint = f'OpenCV before 4.10 was built for NumPy 1, found {numpy.__version__}: pip install "numpy<2"'
            error = MissingDependencyError(
                f"OpenCV (the cv2 module) fails to import ({exc}): {hint}, or {_INSTALL_OPENCV}"
            )
            error.extra = "opencv"
            raise error from None
        if version >= OPENCV_MINIMUM:
            return
        import cv2

        minimum = ".".join(map(str, OPENCV_MINIMUM))
        error = MissingDependencyError(
            f"alcn-cv needs OpenCV >= {minimum}, found {cv2.__version__}: upgrade it, or {_INSTALL_OPENCV}"
        )
    error.extra = "opencv"
    raise error


def is_installed(module: str) -> bool:
    """Whether ``module`` can be imported (found on the path), without importing it."""
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):  # a parent package missing or blocked, or a broken spec
        return False


def require(*modules: str, what: str, preferred: str | None = None) -> None:
    """Raise :func:`missing_dependency`'s error for every one of ``modules`` that is not installed (their extras
    named together), if any."""
    missing = [module for module in modules if not is_installed(module)]
    if missing:
        raise missing_dependency(missing, what, preferred)


def missing_extra(exc: ModuleNotFoundError, what: str, preferred: str | None = None) -> MissingDependencyError | None:
    """:func:`missing_dependency`'s error for the module ``exc`` did not find, when an extra of
    alcn-cv installs that module; None otherwise (a module of no extra missing is a bug)."""
    if exc.name is None or extra_providing(exc.name) is None:
        return None
    return missing_dependency(exc.name, what, preferred)
