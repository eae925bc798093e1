"""Weight files that are archives with a good header but the wrong contents: one line naming the file and what is
wrong, not a traceback, torch's lines on every array or NumPy's advice."""

from __future__ import annotations

import io
import json
import shutil

import numpy as np
import pytest

import alcn_cv
from alcn_cv.errors import WeightFileError
from alcn_cv.nn import ALCN2d
from alcn_cv.runtime import MODELS
from alcn_cv.weight_file import load_normalizer_file


def _write_npz(path, arrays, meta):
    buffer = io.BytesIO()
    np.savez(buffer, **arrays, __meta__=np.array(json.dumps(meta)))
    path.write_bytes(buffer.getvalue())
    return path


@pytest.fixture(scope="module")
def lite():
    return load_normalizer_file(MODELS["lite"])


@pytest.mark.parametrize("model", ["lite", "paper"])
def test_a_gain_export_beside_other_weights_is_refused_as_not_their_export(tmp_path, model):
    """A paper or lite weight file with a gain model's .onnx beside it ended in a traceback (KeyError: 'stride'):
    the export's graph was read with the weight file's config before the export was checked."""
    weights = tmp_path / "w.npz"
    shutil.copyfile(MODELS[model], weights)
    shutil.copyfile(MODELS["gain"].with_suffix(".onnx"), tmp_path / "w.onnx")
    with pytest.raises(WeightFileError, match=r"w\.onnx is not the export of w\.npz .*export it again"):
        alcn_cv.createALCN(weights=weights, backend="opencv")


def _mismatched(lite, case):
    arrays, meta = dict(lite.arrays), lite.meta
    if case == "shape":
        arrays["fc.weight"] = np.zeros((16, 16, 5, 5), np.float32)
    elif case == "missing":
        del arrays["head.bias"]
    elif case == "extra":
        arrays["extra"] = np.zeros(3, np.float32)
    else:  # the header's num_kernels changed: its head is another shape
        meta = {**meta, "config": {**meta["config"], "num_kernels": 9}, "sigmas": meta["sigmas"][:9]}
    return arrays, meta


@pytest.mark.parametrize(
    ("case", "problem"),
    [
        ("shape", r"array 'fc\.weight' has shape \(16, 16, 5, 5\), the header's network needs \(16, 16, 3, 3\)"),
        ("missing", r"array 'head\.bias' missing"),
        ("extra", r"array 'extra' is not in the header's network"),
        ("num_kernels", r"array 'head\.weight' has shape \(10, 16, 1, 1\), the header's network needs \(9, 16, 1, 1\)"),
    ],
)
def test_arrays_that_do_not_fit_the_header_are_named_in_one_line(tmp_path, lite, case, problem):
    """Arrays not fitting their header gave torch's several lines ("Error(s) in loading state_dict ... size mismatch
    for ..."), in createALCN and ALCN2d alike."""
    path = _write_npz(tmp_path / "w.npz", *_mismatched(lite, case))
    for make in (lambda: alcn_cv.createALCN(weights=path, backend="fast"), lambda: ALCN2d(weights=path)):
        with pytest.raises(WeightFileError, match=problem) as info:
            make()
        message = str(info.value)
        assert message.startswith(str(path)) and "\n" not in message and "state_dict" not in message


def test_a_pickled_array_is_named_not_called_corrupt(tmp_path, lite):
    """An object (pickled) array was reported as "corrupt or truncated" with NumPy's advice to allow pickles."""
    arrays = {**lite.arrays, "head.bias": np.array([None] * 10, dtype=object)}
    path = _write_npz(tmp_path / "w.npz", arrays, lite.meta)
    with pytest.raises(WeightFileError, match=r"array 'head\.bias' holds pickled Python objects") as info:
        load_normalizer_file(path)
    assert "allow_pickle" not in str(info.value) and "corrupt" not in str(info.value)
