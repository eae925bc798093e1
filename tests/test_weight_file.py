"""Weight files that are empty, not archives, hold NaN/inf, or are archives with a good header but the wrong
contents: a WeightFileError of one line naming the file and what is wrong (not a traceback, torch's lines on every
array or NumPy's advice)."""

from __future__ import annotations

import io
import json
import shutil

import numpy as np
import pytest

import alcn_cv
from alcn_cv.errors import WeightFileError
from alcn_cv.runtime import MODELS
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
        "newer version": (
            _write_npz(tmp_path / "v9.npz", lite.arrays, {**lite.meta, "version": 9}),
            r"weight file format version 9 but this alcn-cv reads version \d+; read it with the alcn-cv that wrote",
        ),
        "version true": (  # True == 1 in Python: not a version
            _write_npz(tmp_path / "true.npz", lite.arrays, {**lite.meta, "version": True}),
            "format version True",
        ),
        "nan range": (
            _write_npz(tmp_path / "range.npz", lite.arrays, {**lite.meta, "output_range": [float("nan"), 1.0]}),
            "finite",
        ),
    }


@pytest.mark.parametrize(
    "case",
    ["empty", "random bytes", "truncated", "nan", "inf", "header list", "newer version", "version true", "nan range"],
)
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


@pytest.mark.parametrize("model", ["gain", "lite"])
def test_an_export_of_other_weights_beside_a_weight_file_is_refused(tmp_path, model):
    """A retrained file's stale export copied beside it ran silently (up to 74 levels from the torch backend)."""
    shipped = load_normalizer_file(MODELS[model])
    arrays = {k: v.copy() for k, v in shipped.arrays.items()}
    name = next(k for k, v in arrays.items() if v.ndim)
    arrays[name].flat[0] += 0.5  # a retrained network
    weights = save_normalizer_file(tmp_path / "w.npz", arrays, shipped.meta)
    (tmp_path / "w.onnx").write_bytes(MODELS[model].with_suffix(".onnx").read_bytes())  # the shipped file's export
    with pytest.raises(WeightFileError, match=rf"w\.onnx is not the export of w\.npz .*{name}.*alcn export --weights"):
        alcn_cv.createALCN(weights=weights, backend="opencv")
    save_normalizer_file(weights, shipped.arrays, shipped.meta)  # its own weights again: the export is theirs
    (tmp_path / "w.onnx").write_bytes(MODELS[model].with_suffix(".onnx").read_bytes())
    alcn = alcn_cv.createALCN(weights=weights, backend="opencv")
    assert alcn.apply(np.zeros((120, 160), np.uint8)).shape == (120, 160)


@pytest.mark.parametrize(("field", "value"), [("sigmas", [0.5, -1.0]), ("sigmas", [0.0]), ("working_scale", 0)])
def test_a_header_of_widths_that_are_not_positive_is_refused_on_loading(tmp_path, lite, field, value):
    """A sigma or a working scale of zero or less described no method: refused when the file is read, not by the
    first apply() (InputError) or the constructor (a scale out of range)."""
    path = _write_npz(tmp_path / "w.npz", lite.arrays, {**lite.meta, field: value})
    with pytest.raises(WeightFileError, match="must be positive") as info:
        load_normalizer_file(path)
    assert str(path) in str(info.value)


@pytest.fixture(scope="module")
def gain():
    return load_normalizer_file(MODELS["gain"])


def _edited(meta, name, value):
    """``meta`` with the header field ``name`` (``table.key``) set to ``value``, or removed for None."""
    table, key = name.split(".")
    entry = {k: v for k, v in meta[table].items() if k != key}
    return {**meta, table: entry if value is None else {**entry, key: value}}


@pytest.mark.parametrize(
    ("field", "value", "problem"),
    [
        ("config.stride", None, "missing"),
        ("config.stride", 8.0, "must be a positive integer"),
        ("config.stride", 0, "must be a positive integer"),
        ("config.stride", True, "must be a positive integer"),  # a bool is an int to Python, and True == 1
        ("config.mean_sigma", None, "missing"),
        ("config.context_sigma", "wide", "must be a positive number"),
        ("config.dilations", None, "missing"),
        ("config.dilations", [1, "2"], "must be a list of positive integers"),
        ("config.dilations", [1, 0], "must be a list of positive integers"),
        ("equalization.tau", None, "missing"),
        ("equalization.tau", -3.0, "must be a positive number"),
        ("divisive.sigma", None, "missing"),
        ("divisive.scale", None, "missing"),
        ("divisive.scale", True, "must be a positive number"),
    ],
)
def test_a_gain_header_field_missing_or_mistyped_names_the_file_and_the_field(tmp_path, gain, field, value, problem):
    path = _write_npz(tmp_path / "w.npz", gain.arrays, _edited(gain.meta, field, value))
    for load in (load_normalizer_file, alcn_cv.createALCN):
        with pytest.raises(WeightFileError, match=f"header field '{field}' {problem}") as info:
            load(path)
        assert str(path) in str(info.value)
    with pytest.raises(WeightFileError, match=field):
        save_normalizer_file(tmp_path / "saved.npz", gain.arrays, _edited(gain.meta, field, value))


def test_a_gain_header_restating_tau_a_thousandth_off_is_refused(tmp_path, gain):
    """The header restates tau to float32 rounding (1e-6), not roughly: 0.1 % off is a damaged file."""
    meta = _edited(gain.meta, "equalization.tau", gain.meta["equalization"]["tau"] * 1.001)
    with pytest.raises(WeightFileError, match=r"header field 'equalization.tau' is .*, its array 'log_tau' holds"):
        load_normalizer_file(_write_npz(tmp_path / "w.npz", gain.arrays, meta))


@pytest.mark.parametrize(("field", "array"), [("equalization.tau", "log_tau"), ("divisive.scale", "log_floor_scale")])
def test_a_gain_header_restating_tau_or_c_otherwise_than_its_arrays_is_refused(tmp_path, gain, field, array):
    """The arrays are the parameters, which both backends use; a header that says otherwise is a damaged file."""
    path = _write_npz(tmp_path / "w.npz", gain.arrays, _edited(gain.meta, field, 1.5))
    with pytest.raises(WeightFileError, match=f"header field '{field}' is 1.5, its array '{array}' holds") as info:
        alcn_cv.createALCN(weights=path)
    assert str(path) in str(info.value)
    missing = {k: v for k, v in gain.arrays.items() if k != array}
    with pytest.raises(WeightFileError, match=f"array '{array}' missing"):
        load_normalizer_file(_write_npz(tmp_path / "no_array.npz", missing, gain.meta))


def test_the_backends_take_tau_and_c_from_the_arrays(tmp_path):
    """A gain model that learnt tau and c: its config holds their initial values, the arrays (and the header's
    restatement) the learnt ones, which the OpenCV runtime and the torch module both use."""
    torch = pytest.importorskip("torch")
    from alcn_cv.nets.gain import GainNormalizer

    net = GainNormalizer(learn_scales=True)
    with torch.no_grad():
        net.log_tau.fill_(np.log(2.0))
        net.log_floor_scale.fill_(np.log(0.5))
        net.head.bias.add_(0.1)
    path = save_normalizer_file(tmp_path / "w.npz", net.state_arrays(), net.file_meta(trained=True))
    meta = load_normalizer_file(path).meta
    assert meta["config"]["tau"] == 3.0 and meta["equalization"]["tau"] == pytest.approx(2.0)
    image = np.random.default_rng(0).random((64, 80)).astype(np.float32)
    fast, torch_backend = (alcn_cv.createALCN(weights=path, backend=b) for b in ("fast", "torch"))
    assert fast.spec.tau == pytest.approx(2.0) and fast.spec.divisive[1] == pytest.approx(0.5)
    assert fast.spec == torch_backend.spec
    np.testing.assert_allclose(fast.normalize(image), torch_backend.normalize(image), atol=1e-4)


def test_a_training_checkpoint_names_the_runs_weight_file(tmp_path):
    """It said `no header; a torch state_dict or module? ALCN2d.save(path) writes a weight file`."""
    torch = pytest.importorskip("torch")
    run = tmp_path / "run"
    run.mkdir()
    checkpoint = run / "checkpoint.pt"
    torch.save({"step": 2}, checkpoint)
    what = f"{checkpoint} is a training run's checkpoint (what --resume goes on from), not a weight file"
    with pytest.raises(WeightFileError) as info:
        alcn_cv.createALCN(weights=str(checkpoint))
    assert str(info.value) == f"{what}; its run has written no weight file yet (one at every save and one at its end)"
    for step in (2, 10):
        (run / f"gain_normalizer_step{step}.npz").write_bytes(MODELS["gain"].read_bytes())
    with pytest.raises(WeightFileError) as info:
        load_normalizer_file(checkpoint)
    assert (
        str(info.value)
        == f"{what}; did you mean {run / 'gain_normalizer_step10.npz'} (the run's latest step snapshot)?"
    )
    (run / "gain_normalizer.npz").write_bytes(MODELS["gain"].read_bytes())
    renamed = run / "mine.pt"  # any .pt beside a run's weight files
    checkpoint.rename(renamed)
    with pytest.raises(
        WeightFileError,
        match=f"{renamed} is a training run's checkpoint.*did you mean {run / 'gain_normalizer.npz'}\\?$",
    ):
        load_normalizer_file(renamed)
    other = tmp_path / "model.pt"  # a .pt of its own: no run's
    torch.save({}, other)
    with pytest.raises(WeightFileError, match="no header; a torch state_dict or module"):
        load_normalizer_file(other)


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
    from alcn_cv.nn import ALCN2d

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


def test_an_onnx_file_opencv_cannot_parse_is_one_line_without_opencvs_source(tmp_path):
    """OpenCV's error text began with its build's source path and line (``OpenCV(5.0.0) /io/opencv/modules/dnn/...:
    error: (-2:Unspecified error)``); the message keeps OpenCV's own words only."""
    from alcn_cv.nets.opencv_runtime import OpenCVNormalizer

    path = tmp_path / "x.onnx"
    path.write_bytes(b"garbage" * 10)
    with pytest.raises(WeightFileError) as info:
        OpenCVNormalizer(path)
    message = str(info.value)
    assert message.startswith(f"OpenCV cannot read the ONNX model {path}: ") and len(message.splitlines()) == 1
    assert "/modules/" not in message and "OpenCV(" not in message  # its build's source path and version


def test_a_weight_file_without_its_export_says_how_to_make_it_or_run_without_it(tmp_path):
    """createALCN(weights=a copied .npz alone) pointed to `alcn export` only, which the light install lacks."""
    shutil.copy(MODELS["gain"], tmp_path / "mine.npz")
    with pytest.raises(WeightFileError) as info:
        alcn_cv.createALCN(weights=tmp_path / "mine.npz", backend="opencv")
    assert str(info.value) == (
        f"ONNX model not found: {tmp_path / 'mine.onnx'} (backend='opencv' runs the export beside the weight file: "
        f"`alcn export --weights {tmp_path / 'mine.npz'} --onnx {tmp_path / 'mine.onnx'}`, with the [train] extra; or "
        "backend='fast', the network in torch)"
    )


@pytest.mark.parametrize("output_range", [[0.5, 0.5], [1.0, 0.0]])
def test_an_empty_output_range_is_refused(tmp_path, lite, output_range):
    """``to_unit`` divides by ``hi - lo``: an empty range would make every output inf or NaN."""
    path = _write_npz(tmp_path / "w.npz", lite.arrays, {**lite.meta, "output_range": output_range})
    with pytest.raises(WeightFileError, match="is empty"):
        load_normalizer_file(path)


def test_a_folder_of_several_weight_files_lists_them_and_guesses_none(tmp_path, lite):
    """A folder holding one ``.npz`` (or a run's final weight file) names it as the file meant; of several, which one
    was meant is unknown: the message lists them, where naming the first in name order guessed."""
    for name in ("b.npz", "a.npz"):
        save_normalizer_file(tmp_path / name, lite.arrays, lite.meta)
    with pytest.raises(WeightFileError) as info:
        load_normalizer_file(tmp_path)
    assert str(info.value) == f"{tmp_path} is a folder, not a weight file (.npz); it holds 2: a.npz, b.npz"
    (tmp_path / "b.npz").unlink()
    with pytest.raises(WeightFileError, match=f"did you mean {tmp_path / 'a.npz'}"):
        load_normalizer_file(tmp_path)
