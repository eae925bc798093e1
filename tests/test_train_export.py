"""ONNX export and the torch-free OpenCV runtime (alcn_cv.train.export, alcn_cv.nets.opencv_runtime)."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
import torch

from alcn_cv.enhance.alcn import ALCN
from alcn_cv.errors import InputError, WeightFileError
from alcn_cv.filters.gaussian_mixture import alcn_filter
from alcn_cv.nets import Normalizer, opencv_runtime
from alcn_cv.nets.lite import LiteNormalizer, normalizer_from_file
from alcn_cv.nets.opencv_runtime import OpenCVNormalizer
from alcn_cv.runtime import MODELS
from alcn_cv.train.export import export_onnx
from alcn_cv.weight_file import load_normalizer_file, save_normalizer_file


@pytest.fixture(scope="module")
def random_weights(tmp_path_factory):
    """A Normalizer whose outputs vary from window to window (the placeholder's are constant)."""
    torch.manual_seed(0)
    net = Normalizer(output_scale=2.0)
    with torch.no_grad():
        net.head.weight.normal_(0, 0.05)
    path = tmp_path_factory.mktemp("w") / "random.npz"
    meta = {
        "config": net.config,
        "sigmas": [0.5 * i for i in range(1, 11)],
        "working_scale": 0.5,
        "output_range": [-0.2, 0.2],
        "trained": False,
    }
    save_normalizer_file(path, net.state_arrays(), meta)
    onnx_path = export_onnx(path.with_suffix(".onnx"), path)
    return path, onnx_path, net.eval()


def _images(shared_data, n=3):
    paths = sorted((shared_data / "psm").glob("*/*.0.png"))[:n]
    assert paths
    return [
        cv2.resize(cv2.imread(str(p), cv2.IMREAD_GRAYSCALE), None, fx=0.3, fy=0.3).astype(np.float32) / 255
        for p in paths
    ]


def test_window_matches_the_network():
    assert opencv_runtime.WINDOW == Normalizer.window == LiteNormalizer.window == 48  # the paper's windows
    first = LiteNormalizer().features[0]
    assert first.kernel_size == first.stride == (opencv_runtime.LITE_BLOCK,) * 2


def test_lite_normalizer_exports_and_runs_in_opencv(tmp_path):
    torch.manual_seed(1)
    net = LiteNormalizer(output_scale=2.0)
    path = tmp_path / "lite.npz"
    meta = {
        "config": net.config,
        "architecture": "lite",
        "sigmas": [0.5 * i for i in range(1, 11)],
        "working_scale": 1.0,
        "output_range": [-0.2, 0.2],
        "trained": False,
    }
    save_normalizer_file(path, net.state_arrays(), meta)
    ocv = OpenCVNormalizer(export_onnx(path.with_suffix(".onnx"), path))
    assert ocv.stride == net.stride == 8
    image = np.random.default_rng(2).random((75, 98), dtype=np.float32)
    with torch.no_grad():
        t = torch.from_numpy(image)[None, None]
        grid, dense = net.eval().dense_grid(t)[0].numpy(), net.dense(t)[0].numpy()
    assert np.ptp(grid[0]) > 1e-3
    np.testing.assert_allclose(ocv.dense_grid(image), grid, atol=1e-4)
    np.testing.assert_allclose(ocv.dense(image), dense, atol=1e-4)
    for mixture in ("exact", "pyramid"):
        fast = ALCN(weights=path, mixture=mixture).normalize(image)
        np.testing.assert_allclose(
            ALCN(weights=path, backend="opencv", mixture=mixture).normalize(image), fast, atol=1e-4
        )


@pytest.mark.shared_data
def test_torch_onnx_opencv_and_fast_path_agree(shared_data, random_weights):
    path, onnx_path, net = random_weights
    ocv = OpenCVNormalizer(onnx_path)
    alcn = ALCN(weights=path, scale=1.0, mixture="exact")
    for image in _images(shared_data):
        with torch.no_grad():
            t = torch.from_numpy(image)[None, None]
            grid_torch, dense_torch = net.dense_grid(t)[0].numpy(), net.dense(t)[0].numpy()
        assert np.ptp(grid_torch[0]) > 1e-3  # a non-trivial test: the weights vary over the image
        np.testing.assert_allclose(ocv.dense_grid(image), grid_torch, atol=1e-4)
        dense = ocv.dense(image)
        np.testing.assert_allclose(dense, dense_torch, atol=1e-4)
        # The full normalization: OpenCV runtime + OpenCV mixture vs. the library's fast path.
        np.testing.assert_allclose(alcn_filter(image, dense, alcn.full_res_sigmas), alcn.normalize(image), atol=1e-4)


@pytest.mark.parametrize("model", ["paper", "lite", "gain", "gain-lite"])
def test_shipped_onnx_matches_shipped_weights(model):
    weights = MODELS[model]
    net = normalizer_from_file(load_normalizer_file(weights))
    image = np.random.default_rng(0).random((61, 83), dtype=np.float32)
    with torch.no_grad():
        ref = net.dense_grid(torch.from_numpy(image)[None, None])[0].numpy()
    ocv = OpenCVNormalizer(weights.with_suffix(".onnx"))
    assert ocv.stride == net.stride
    np.testing.assert_allclose(ocv.dense_grid(image), ref, atol=1e-4)


def _webcam_frame(shared_data):
    path = sorted((shared_data / "webcam" / "mexico").glob("*.jpg"))[0]
    return cv2.imread(str(path), cv2.IMREAD_GRAYSCALE).astype(np.float32) / 255


def test_gain_onnx_takes_the_features(shared_data):
    """The gain export runs the grid's convolutions only (the features computed outside, the cell moments bit
    for bit as torch's), at any size (even below its reflections' reach), and equals the torch model on a real
    frame; so do the features."""
    net = normalizer_from_file(load_normalizer_file(MODELS["gain"]))
    ocv = OpenCVNormalizer(MODELS["gain"].with_suffix(".onnx"))
    assert ocv.input == opencv_runtime.FEATURES_INPUT and ocv.stride == net.stride == 8
    assert OpenCVNormalizer(MODELS["lite"].with_suffix(".onnx")).input == opencv_runtime.BLOCKS_INPUT
    assert OpenCVNormalizer(MODELS["paper"].with_suffix(".onnx")).input == opencv_runtime.IMAGE_INPUT
    rng = np.random.default_rng(2)
    shapes = [(48, 48), (5, 9), (1, 1), (17, 130)]
    for image in [_webcam_frame(shared_data), *(rng.random(shape, dtype=np.float32) for shape in shapes)]:
        with torch.no_grad():
            ref = net.dense_grid(torch.from_numpy(image)[None, None])[0].numpy()
        np.testing.assert_allclose(ocv.dense_grid(image), ref, atol=1e-5, rtol=0)
        with torch.no_grad():
            features = net.features(torch.from_numpy(image)[None, None]).numpy()
        np.testing.assert_allclose(ocv.features(image), features, atol=1e-5, rtol=0)


def test_cell_moments_are_torch_bit_for_bit():
    """Flat cells (their deviation is the sums' rounding, amplified by the log) and cells cut by the border."""
    net = normalizer_from_file(load_normalizer_file(MODELS["gain"]))
    rng = np.random.default_rng(5)
    image = rng.random((83, 117), dtype=np.float32)
    image[10:50, 20:90] = np.float32(200 / 255)
    for frame in (image, image[:9, :13], image[:1, :3]):
        with torch.no_grad():
            ref = net.cell_moments(torch.from_numpy(np.ascontiguousarray(frame))[None, None]).numpy()
        np.testing.assert_array_equal(opencv_runtime.cell_moments(np.ascontiguousarray(frame), net.stride), ref)


def test_flat_cells_have_the_features_of_torch_not_nan():
    """A flat cell's variance ``E[x^2] - E[x]^2`` rounds below 0 at many intensities (0.7: -8e-7), which torch
    clamps to 0; the square root of it unclamped is NaN, and a flat wall or sky in the frame made the opencv
    backend's output NaN there."""
    net = normalizer_from_file(load_normalizer_file(MODELS["gain"]))
    ocv = OpenCVNormalizer(MODELS["gain"].with_suffix(".onnx"))
    for value in (0.7, 0.77, 0.9, 200 / 255):
        image = np.full((40, 56), value, np.float32)
        moments = opencv_runtime.cell_moments(image, net.stride)
        assert (moments[0, 1] - moments[0, 0] ** 2).min() < 0 or value == 200 / 255  # the rounding at stake
        with torch.no_grad():
            expected = net.features(torch.from_numpy(image)[None, None]).numpy()
        features = ocv.features(image)
        assert np.isfinite(features).all(), value
        np.testing.assert_allclose(features, expected, atol=1e-5, rtol=0)
    out = ALCN(model="gain", backend="opencv").normalize(np.full((48, 64), 0.7, np.float32))
    assert np.isfinite(out).all()


def _reflect_pads(onnx_path) -> list[list[int] | None]:
    """Each ``Pad`` node's pads: the constant's values, or None where the graph computes them."""
    onnx = pytest.importorskip("onnx")
    from onnx import numpy_helper

    graph = onnx.load(str(onnx_path)).graph
    constants = {init.name: numpy_helper.to_array(init) for init in graph.initializer}
    constants |= {n.output[0]: numpy_helper.to_array(n.attribute[0].t) for n in graph.node if n.op_type == "Constant"}
    pads = [n for n in graph.node if n.op_type == "Pad"]
    assert pads and all(n.attribute[0].s == b"reflect" for n in pads)
    return [constants[n.input[1]].tolist() if n.input[1] in constants else None for n in pads]


@pytest.mark.parametrize("model", ["gain", "gain-lite"])
def test_shipped_gain_exports_pad_by_constants(model):
    """OpenCV 4's ONNX importer fails on the chain of nodes by which torch computes a reflect pad's pads (at its
    Reshape): the shipped gain exports hold each as a constant, one per dilation, so that OpenCV 4.x loads them."""
    path = MODELS[model].with_suffix(".onnx")
    dilations = load_normalizer_file(MODELS[model]).meta["config"]["dilations"]
    assert _reflect_pads(path) == [[0, 0, d, d, 0, 0, d, d] for d in dilations]
    assert not opencv_runtime.computes_pads(path)


@pytest.mark.filterwarnings("ignore:Constant folding:UserWarning")  # torch's computed pads: its Slice of step -1
def test_export_writes_constant_pads_where_torch_computes_them(tmp_path, monkeypatch):
    """A fresh export's pads are constants as the shipped ones; torch's own symbolic is back after it, and an older
    export (torch's computed pads), which OpenCV 4 cannot read, gets one line saying how to export it again."""
    import contextlib

    from alcn_cv.train import export

    fresh = export_onnx(tmp_path / "fresh.onnx", MODELS["gain"])
    assert _reflect_pads(fresh) == _reflect_pads(MODELS["gain"].with_suffix(".onnx"))
    assert not opencv_runtime.computes_pads(fresh)
    with monkeypatch.context() as patch:  # the export as alcn-cv wrote it before
        patch.setattr(export, "_constant_reflect_pads", contextlib.nullcontext)
        older = export_onnx(tmp_path / "older.onnx", MODELS["gain"])
    # computed: torch's own symbolic, registered again after the fresh export
    assert None in _reflect_pads(older) and opencv_runtime.computes_pads(older)
    monkeypatch.setattr(opencv_runtime, "OPENCV_4_DNN", True)
    config = load_normalizer_file(MODELS["gain"]).meta["config"]
    with pytest.raises(WeightFileError) as error:
        OpenCVNormalizer(older, config)
    assert "\n" not in str(error.value), error.value
    assert f"`alcn export --weights {older.with_suffix('.npz')} --onnx {older} --overwrite`" in str(error.value)
    assert OpenCVNormalizer(fresh, config).largest_pad == max(config["dilations"])


def test_gain_export_needs_its_config(tmp_path):
    onnx = tmp_path / "gain.onnx"
    onnx.write_bytes(MODELS["gain"].with_suffix(".onnx").read_bytes())
    with pytest.raises(WeightFileError, match="config"):
        OpenCVNormalizer(onnx)
    config = load_normalizer_file(MODELS["gain"]).meta["config"]
    assert OpenCVNormalizer(onnx, config={**config, "stride": 16}).stride == 16


def test_gain_export_with_a_trained_head(tmp_path):
    """A gain Normalizer with a non-trivial head exports too."""
    from alcn_cv.nets.gain import GainNormalizer

    torch.manual_seed(0)
    net = GainNormalizer()
    with torch.no_grad():
        net.head.weight.normal_(0, 0.1)
    path = save_normalizer_file(tmp_path / "gain.npz", net.state_arrays(), net.file_meta(trained=False))
    ocv = OpenCVNormalizer(export_onnx(tmp_path / "gain.onnx", path))
    image = np.random.default_rng(3).random((70, 93), dtype=np.float32)
    with torch.no_grad():
        ref = net.eval().dense_grid(torch.from_numpy(image)[None, None])[0].numpy()
    np.testing.assert_allclose(ocv.dense_grid(image), ref, atol=1e-4, rtol=0)


@pytest.mark.parametrize("mixture", ["pyramid", "exact"])
def test_gain_model_through_opencv_backend(shared_data, mixture):
    """``createALCN(model="gain", backend="opencv")``: the fast backend's output (equalization
    included) and its Eq. 1 window weights."""
    image = cv2.resize(_webcam_frame(shared_data), (203, 151), interpolation=cv2.INTER_AREA)
    ocv = ALCN(model="gain", backend="opencv", mixture=mixture)
    fast = ALCN(model="gain", backend="fast", mixture=mixture)
    out = ocv.normalize(image)
    assert np.abs(out).max() < 1
    np.testing.assert_allclose(out, fast.normalize(image), atol=1e-4, rtol=0)
    windows = np.stack([image[:48, :48], image[50:98, 100:148]])
    np.testing.assert_allclose(ocv.window_weights(windows), fast.window_weights(windows), atol=1e-4, rtol=0)


def test_gain_model_runs_where_torch_cannot_be_imported(tmp_path, run_without_torch):
    image = np.random.default_rng(4).random((66, 90), dtype=np.float32)
    out = tmp_path / "gain.npy"
    run_without_torch(
        """
        import numpy as np
        import alcn_cv
        image = np.random.default_rng(4).random((66, 90), dtype=np.float32)
        np.save(sys.argv[1], alcn_cv.createALCN(model="gain", backend="opencv").normalize(image))
    """,
        out,
    )
    np.testing.assert_allclose(np.load(out), ALCN(model="gain", backend="fast").normalize(image), atol=1e-4, rtol=0)


def test_runs_where_torch_cannot_be_imported(random_weights, run_without_torch):
    _, onnx_path, net = random_weights
    image = np.random.default_rng(1).random((50, 70), dtype=np.float32)
    with torch.no_grad():
        ref = net.dense_grid(torch.from_numpy(image)[None, None])[0].numpy()
    out = onnx_path.parent / "grid.npy"
    run_without_torch(
        f"""
        import numpy as np
        from alcn_cv.nets.opencv_runtime import OpenCVNormalizer
        image = np.random.default_rng(1).random((50, 70), dtype=np.float32)
        np.save(sys.argv[1], OpenCVNormalizer({str(onnx_path)!r}).dense_grid(image))
    """,
        out,
    )
    np.testing.assert_allclose(np.load(out), ref, atol=1e-4)


def test_bad_files_and_inputs(tmp_path, random_weights):
    with pytest.raises(WeightFileError, match="not found"):
        OpenCVNormalizer(tmp_path / "missing.onnx")
    bad = tmp_path / "bad.onnx"
    bad.write_bytes(b"not an onnx model")
    with pytest.raises(WeightFileError, match="cannot read"):
        OpenCVNormalizer(bad)
    with pytest.raises(InputError, match=".onnx"):
        export_onnx(tmp_path / "x.pt", random_weights[0])
    ocv = OpenCVNormalizer(random_weights[1])
    with pytest.raises(InputError, match="float32"):
        ocv.dense_grid(np.zeros((20, 20), np.uint8))
    with pytest.raises(InputError, match="HxW"):
        ocv.dense_grid(np.zeros((20, 20, 3), np.float32))


def test_image_blocks_are_space_to_depth():
    padded = np.arange(8 * 12, dtype=np.float32).reshape(8, 12)
    blocks = opencv_runtime.image_blocks(padded)
    b = opencv_runtime.LITE_BLOCK
    assert blocks.shape == (1, b * b, 8 // b, 12 // b)
    for y, x, i, j in [(0, 0, 0, 0), (1, 2, 1, 0), (3, 3, 1, 2), (2, 1, 0, 1)]:
        assert blocks[0, b * y + x, i, j] == padded[b * i + y, b * j + x]


def test_the_export_carries_the_weight_files_header(tmp_path):
    """The ``.onnx`` describes itself: its ``metadata_props["alcn_cv"]`` is the weight file's header without the
    training record (sigmas, working scale and output range: what Eq. 3 around the network needs)."""
    import onnx

    from alcn_cv.train.export import export_onnx
    from alcn_cv.weight_file import ONNX_METADATA_KEY

    out = export_onnx(tmp_path / "lite.onnx", MODELS["lite"])
    props = {p.key: p.value for p in onnx.load(str(out)).metadata_props}
    meta = load_normalizer_file(MODELS["lite"]).meta
    assert json.loads(props[ONNX_METADATA_KEY]) == {k: v for k, v in meta.items() if k != "training"}
