"""What a newcomer's walk of ``examples/`` found: relit_cookie_box.py compared ``none`` on the reference model (the
whole video's 46 views) with the other methods on models of the first frames' 6 views, and pnp_methods.py drew an
empty progress bar before it said that the video was missing."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType, SimpleNamespace

import numpy as np
import pytest

from alcn_cv.errors import InputError
from pose import build

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def _example(name: str) -> ModuleType:
    """The example script ``name`` imported as a module (its ``main`` not run)."""
    spec = importlib.util.spec_from_file_location(f"example_walk_{name.removesuffix('.py')}", EXAMPLES / name)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


class _StopError(Exception):
    """Raised by a stand-in to end an example's main where the test has seen what it needs."""


def test_relit_builds_every_method_none_included_alike_and_reuses_only_models_built_so(tmp_path, monkeypatch):
    """Every method's model, none's included, comes from the registered build of the same frames; a model left by an
    earlier run is reused only when built from them: an earlier run's reference model (once ``model_none.npz``) or a
    model of other frames is built again."""
    relit = _example("relit_cookie_box.py")
    out = tmp_path / "out"
    out.mkdir()
    frames_60 = {"max_frames": 60, "step": build.COOKIE_BOX["step"]}
    extras = {
        "reference_model.npz": {"K": np.eye(3).tolist()},
        "model_none.npz": {"K": np.eye(3).tolist()},  # an earlier run's reference model, built from the whole video
        "model_clahe.npz": {"registered_frames": frames_60},  # built before from the default frames
    }
    for name in extras:
        (out / name).write_bytes(b"not read: the loading is a stand-in")
    monkeypatch.setattr(relit.part_model, "load", lambda path: SimpleNamespace(extra=extras[Path(path).name]))
    built = []

    def registered_build(video, ref, K, normalization, path, max_frames=None):
        built.append((normalization, path.name, max_frames))
        extras[path.name] = {"registered_frames": {**frames_60, "max_frames": max_frames}}

    def open_tracker(*args, **kwargs):  # the tracking starts once every model is there
        raise _StopError

    monkeypatch.setattr(relit, "registered_build", registered_build)
    monkeypatch.setattr(relit.track, "open_tracker", open_tracker)
    methods = ["--methods", "none", "clahe", "tantriggs"]
    monkeypatch.setattr(sys, "argv", ["relit_cookie_box.py", "--out", str(out), *methods])
    with pytest.raises(_StopError):
        relit.main()
    assert built == [("none", "model_none.npz", 60), ("tantriggs", "model_tantriggs.npz", 60)]
    built.clear()
    monkeypatch.setattr(sys, "argv", ["relit_cookie_box.py", "--out", str(out), *methods, "--max-frames", "0"])
    with pytest.raises(_StopError):
        relit.main()
    assert [(name, frames) for name, _, frames in built] == [("none", None), ("clahe", None), ("tantriggs", None)]


def test_pnp_methods_checks_the_video_before_any_progress_bar(tmp_path, monkeypatch, capsys):
    """A missing video printed `features: 0frame [00:00, ?frame/s]` before its error."""
    pnp = _example("pnp_methods.py")
    model = SimpleNamespace(normalization="none", extra={"K": np.eye(3).tolist()})
    monkeypatch.setattr(pnp.part_model, "load", lambda path: model)
    monkeypatch.setattr(pnp, "FeaturePartDetector", lambda model, normalization: None)
    video = tmp_path / "missing.mp4"
    monkeypatch.setattr(sys, "argv", ["pnp_methods.py", "model.npz", str(video), "--max-frames", "2"])
    with pytest.raises(InputError, match=f"no such video or folder: {video}"):
        pnp.main()
    assert "frame" not in capsys.readouterr().err
