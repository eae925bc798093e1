"""Weight files that are empty, not archives, or hold NaN/inf: a WeightFileError naming the file."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest

import alcn_cv
from alcn_cv.enhance.alcn import MODELS
from alcn_cv.errors import WeightFileError
from alcn_cv.weight_file import load_normalizer_file, save_normalizer_file


def _write_npz(path, arrays, meta):
    buffer = io.BytesIO()
    np.savez(buffer, **arrays, __meta__=np.array(json.dumps(meta)))
    path.write_bytes(buffer.getvalue())
    return path


@pytest.fixture(scope="module")
def lite():
    return load_normalizer_file(MODELS["lite"])


def _bad_files(tmp_path, lite):
    key = next(iter(lite.arrays))
    poisoned = {}
    for label, value in (("nan", np.nan), ("inf", np.inf)):
        arrays = dict(lite.arrays)
        arrays[key] = arrays[key].copy()
        arrays[key].flat[0] = value
        poisoned[label] = _write_npz(tmp_path / f"{label}.npz", arrays, lite.meta)
    (tmp_path / "empty.npz").write_bytes(b"")
    (tmp_path / "random.npz").write_bytes(np.random.default_rng(0).bytes(4096))
    (tmp_path / "cut.npz").write_bytes(MODELS["lite"].read_bytes()[:5000])
    return {
        "empty": (tmp_path / "empty.npz", "empty"),
        "random bytes": (tmp_path / "random.npz", "not a .npz archive"),
        "truncated": (tmp_path / "cut.npz", "not a .npz archive|corrupt or truncated"),
        "nan": (poisoned["nan"], f"{key}.*NaN or infinite"),
        "inf": (poisoned["inf"], f"{key}.*NaN or infinite"),
        "header list": (_write_npz(tmp_path / "list.npz", lite.arrays, ["a"]), "not a JSON object"),
        "nan range": (
            _write_npz(tmp_path / "range.npz", lite.arrays, {**lite.meta, "output_range": [float("nan"), 1.0]}),
            "finite",
        ),
    }


@pytest.mark.parametrize("case", ["empty", "random bytes", "truncated", "nan", "inf", "header list", "nan range"])
def test_bad_weight_files_name_the_file_and_the_problem(tmp_path, lite, case):
    path, problem = _bad_files(tmp_path, lite)[case]
    with pytest.raises(WeightFileError, match=problem) as info:
        load_normalizer_file(path)
    assert str(path) in str(info.value) and "allow_pickle" not in str(info.value)


@pytest.mark.parametrize("case", ["empty", "nan"])
def test_createALCN_raises_it(tmp_path, lite, case):
    path, problem = _bad_files(tmp_path, lite)[case]
    with pytest.raises(WeightFileError, match=problem):
        alcn_cv.createALCN(weights=path)


def test_nan_weights_are_not_saved(tmp_path, lite):
    arrays = {k: np.full_like(v, np.nan) for k, v in lite.arrays.items()}
    with pytest.raises(WeightFileError, match="NaN"):
        save_normalizer_file(tmp_path / "w.npz", arrays, lite.meta)
    assert not list(tmp_path.iterdir())
    assert load_normalizer_file(save_normalizer_file(tmp_path / "ok.npz", lite.arrays, lite.meta)).meta["trained"]


def test_saving_weights_removes_the_export_of_the_old_ones(tmp_path, lite, caplog):
    """backend="opencv" runs the .onnx beside a weight file: one made from the weights it held before would run
    silently (a retrained model in the folder of its old export)."""
    weights = save_normalizer_file(tmp_path / "w.npz", lite.arrays, lite.meta)
    (tmp_path / "w.onnx").write_bytes(b"an old export")
    (tmp_path / "other.onnx").write_bytes(b"another model's")
    with caplog.at_level("WARNING", logger="alcn_cv.weight_file"):
        save_normalizer_file(weights, lite.arrays, lite.meta)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["other.onnx", "w.npz"]
    assert "w.onnx" in caplog.text


@pytest.mark.parametrize(("field", "value"), [("sigmas", [0.5, -1.0]), ("sigmas", [0.0]), ("working_scale", 0)])
def test_a_header_of_widths_that_are_not_positive_is_refused_on_loading(tmp_path, lite, field, value):
    """A sigma or a working scale of zero or less described no method: refused when the file is read, not by the
    first apply() (InputError) or the constructor (a scale out of range)."""
    path = _write_npz(tmp_path / "w.npz", lite.arrays, {**lite.meta, field: value})
    with pytest.raises(WeightFileError, match="must be positive") as info:
        load_normalizer_file(path)
    assert str(path) in str(info.value)
