"""The OpenCV-style contract of every registered normalization, and ALCN's own API."""

import inspect
import logging
import os

import cv2
import numpy as np
import pytest

import alcn_cv
import alcn_cv.enhance.alcn as alcn_module
from alcn_cv import InputError, WeightFileError
from alcn_cv.data.frames import synthetic_frame
from alcn_cv.enhance.registry import from_spec
from alcn_cv.runtime import MODELS

METHODS = alcn_cv.available()


@pytest.fixture(scope="module")
def frames():
    rng = np.random.default_rng(0)
    base = cv2.GaussianBlur(rng.random((60, 80), dtype=np.float32), (0, 0), 3)
    gray = cv2.normalize(base, None, 0.05, 0.95, cv2.NORM_MINMAX)
    bgr = np.dstack([gray, 0.6 * gray + 0.2, 1 - 0.8 * gray]).astype(np.float32)
    return gray, bgr


@pytest.fixture(scope="module")
def methods():
    return {name: alcn_cv.create(name) for name in METHODS}


def test_registry():
    assert {"none", "alcn"} <= set(METHODS)
    assert isinstance(alcn_cv.createALCN(), alcn_cv.ALCN)
    with pytest.raises(InputError, match="unknown normalization"):
        alcn_cv.create("nope")
    with pytest.raises(InputError, match="bad parameters"):
        alcn_cv.create("none", strength=3)


@pytest.mark.parametrize("name", METHODS)
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32])
@pytest.mark.parametrize("layout", ["gray", "gray1", "bgr"])
def test_shape_and_dtype_are_kept(methods, frames, name, dtype, layout):
    gray, bgr = frames
    img = {"gray": gray, "gray1": gray[..., None], "bgr": bgr}[layout]
    if dtype != np.float32:
        img = np.rint(img * np.iinfo(dtype).max).astype(dtype)
    out = methods[name].apply(img)
    assert out.shape == img.shape and out.dtype == img.dtype
    if dtype == np.float32:
        assert out.min() >= 0 and out.max() <= 1


@pytest.mark.parametrize("name", METHODS)
def test_float_output_on_request_and_fixed_mapping(methods, frames, name):
    gray, _ = frames
    method = methods[name]
    img8 = np.rint(gray * 255).astype(np.uint8)
    as_float = method.apply(img8, out_dtype=np.float32)
    assert as_float.dtype == np.float32
    # the intensities as apply converts them (the gain ALCN's division amplifies a last-bit difference)
    expected = method.to_unit(method.normalize(img8.astype(np.float32) * np.float32(1 / 255)))
    np.testing.assert_allclose(as_float, expected, atol=1e-6)
    np.testing.assert_array_equal(method.apply(img8), np.rint(expected * 255).astype(np.uint8))


@pytest.mark.parametrize("name", METHODS)
def test_colour_keeps_chroma(methods, frames, name):
    _, bgr = frames
    out = methods[name].apply(bgr)
    lab_in, lab_out = cv2.cvtColor(bgr, cv2.COLOR_BGR2Lab), cv2.cvtColor(out, cv2.COLOR_BGR2Lab)
    # a and b survive up to gamut clipping of the new lightness
    unclipped = (out > 0.01).all(axis=2) & (out < 0.99).all(axis=2)
    assert unclipped.mean() > 0.3
    np.testing.assert_allclose(lab_out[unclipped][:, 1:], lab_in[unclipped][:, 1:], atol=1.5)


@pytest.mark.parametrize("name", METHODS)
def test_callers_array_untouched(methods, frames, name):
    gray, bgr = frames
    for img in (gray, bgr, np.rint(bgr * 255).astype(np.uint8)):
        before = img.copy()
        methods[name].apply(img)
        np.testing.assert_array_equal(img, before)


def test_apply_takes_src_and_dst_by_keyword_as_opencv_does(frames):
    # cv2.createCLAHE().apply(src[, dst]) -> dst: the same names, by keyword as by position
    img8 = np.rint(frames[0] * 255).astype(np.uint8)
    clahe = alcn_cv.create("clahe")
    expected = cv2.createCLAHE(clipLimit=clahe.clipLimit, tileGridSize=clahe.tileGridSize).apply(src=img8)
    np.testing.assert_array_equal(clahe.apply(src=img8), expected)
    dst = np.empty_like(img8)
    assert clahe.apply(src=img8, dst=dst) is dst
    np.testing.assert_array_equal(dst, expected)
    assert list(inspect.signature(alcn_cv.createALCN().apply).parameters)[:2] == ["src", "dst"]


BAD = {
    "not an array": [[0.1, 0.2]],
    "empty": np.zeros((0, 5), np.uint8),
    "5 channels": np.zeros((8, 8, 5), np.uint8),
    "4 dims": np.zeros((2, 8, 8, 3), np.uint8),
    "1 dim": np.zeros(8, np.uint8),
    "float64": np.zeros((8, 8)),
    "int32": np.zeros((8, 8), np.int32),
    "nan": np.full((8, 8), np.nan, np.float32),
    "inf": np.full((8, 8), np.inf, np.float32),
    "0..255 float": np.full((8, 8), 200, np.float32),
}


@pytest.mark.parametrize("name", METHODS)
@pytest.mark.parametrize("case", BAD)
def test_bad_input_is_a_clear_error(methods, name, case):
    with pytest.raises(InputError):
        methods[name].apply(BAD[case])


def test_bad_input_messages(methods):
    alcn = methods["alcn"]
    with pytest.raises(InputError, match="BGRA"):
        alcn.apply(BAD["5 channels"])
    with pytest.raises(InputError, match="NaN"):
        alcn.apply(BAD["nan"])
    with pytest.raises(InputError, match="divide by 255"):
        alcn.apply(BAD["0..255 float"])
    with pytest.raises(InputError, match="out_dtype"):
        alcn.apply(np.zeros((8, 8), np.uint8), out_dtype=np.int16)
    with pytest.raises(InputError, match="unknown out_dtype 'foo'"):
        alcn.apply(np.zeros((8, 8), np.uint8), out_dtype="foo")
    with pytest.raises(InputError, match=r"image.astype\(np.float32\)"):
        alcn.apply(BAD["float64"])
    with pytest.raises(InputError, match=r"\[-0.5, 0.5\]$"):  # centred values: no hint about 0..255
        alcn.apply(np.full((8, 8), 0.5, np.float32) - np.eye(8, dtype=np.float32))


def test_alcn_backends_agree(frames, cpu_route):
    gray, _ = frames
    exact = alcn_cv.createALCN(mixture="exact").normalize(gray)
    np.testing.assert_allclose(exact, alcn_cv.createALCN(backend="torch").normalize(gray), atol=1e-4)
    # the lite model's default mixture is the pyramid, which approximates the exact one (torch has only that)
    pyramid, exact = (alcn_cv.createALCN(model="lite", mixture=m) for m in ("pyramid", "exact"))
    assert repr(pyramid) != repr(exact)
    approximate, exact = pyramid.normalize(gray), exact.normalize(gray)
    assert 0 < np.abs(approximate - exact).mean() < 0.02 * np.ptp(exact)


def test_alcn_is_eq3_with_scaled_sigmas(methods, frames):
    gray, _ = frames
    alcn = alcn_cv.createALCN(model="lite", mixture="exact")  # working scale 0.5; Eq. 3 is its whole output
    maps = alcn.weight_maps(gray)
    assert maps.shape == (len(alcn.sigmas),) + gray.shape
    expected = alcn_cv.alcn_filter(gray, maps, sigmas=[s / alcn.scale for s in alcn.sigmas])
    np.testing.assert_allclose(alcn.normalize(gray), expected, atol=1e-6)


def test_alcn_parameters():
    with pytest.raises(InputError, match="backend"):
        alcn_cv.createALCN(backend="vulkan")
    with pytest.raises(InputError, match="scale"):
        alcn_cv.createALCN(scale=0)
    with pytest.raises(WeightFileError, match="not found"):
        alcn_cv.createALCN(weights="/nonexistent/weights.npz")
    assert alcn_cv.createALCN(scale=1.0).scale == 1.0
    with pytest.raises(InputError, match="not both"):
        alcn_cv.createALCN(model="paper", weights=MODELS["lite"])
    assert alcn_cv.createALCN(weights=MODELS["lite"]).weights_path == MODELS["lite"]
    with pytest.raises(WeightFileError, match="an ONNX export; give the weight file .*beside it"):
        alcn_cv.createALCN(weights=MODELS["lite"].with_suffix(".onnx"))
    assert repr(alcn_cv.createALCN(model="lite")).startswith("ALCN(model='lite', ")  # a shipped model by its name
    with pytest.raises(InputError, match="backend='fast' runs on the CPU"):
        alcn_cv.createALCN(backend="fast", device="cuda")
    with pytest.raises(InputError, match="not a torch device"):
        alcn_cv.createALCN(backend="torch", device="gpu0")
    with pytest.raises(InputError, match="runs no torch"):
        alcn_cv.createALCN(backend="opencv", threads=2)
    assert alcn_cv.createALCN(threads=2).backend == "fast"  # torch threads: the backend that runs torch
    assert alcn_cv.createALCN(backend="fast", device="cpu:0").backend == "fast"


def test_model_and_weights_are_one_or_the_other_as_in_alcn2d():
    """createALCN and the registry refuse a model beside a weight file, the default model's name too, as ALCN2d."""
    from alcn_cv.runtime import DEFAULT_MODEL

    for model in ("gain", "lite"):
        with pytest.raises(InputError, match="give a model or a weight file, not both"):
            alcn_cv.createALCN(weights=MODELS["lite"], model=model)
        with pytest.raises(InputError, match="not both"):
            alcn_cv.create(f"alcn:model={model}:weights={MODELS['lite']}")
    assert alcn_cv.createALCN().weights_path == MODELS[DEFAULT_MODEL]
    assert alcn_cv.create("alcn").weights_path == MODELS[DEFAULT_MODEL]
    assert alcn_cv.create("alcn:model=lite").weights_path == MODELS["lite"]


@pytest.mark.parametrize("scale", ["abc", "0.5", float("nan"), float("inf"), 0, -1, 5, True])
def test_a_scale_that_is_not_a_number_in_range_names_scale_and_its_range(scale):
    with pytest.raises(InputError, match=r"scale must be a number in \(0, 4\], got "):
        alcn_cv.createALCN(model="lite", scale=scale)


def test_the_registry_checks_scale_as_createALCN():
    with pytest.raises(InputError, match=r"scale must be a number in \(0, 4\], got 5"):
        alcn_cv.create("alcn:model=lite:scale=5")


def test_shipped_weights_say_what_they_are(caplog):
    for model in ("lite", "paper"):
        alcn = alcn_cv.createALCN(model=model)
        assert alcn.weights_path == MODELS[model] and alcn.trained
        with caplog.at_level(logging.WARNING):
            alcn_cv.createALCN(model=model)
        assert "UNTRAINED" not in caplog.text and "re-distil" not in caplog.text


def test_import_does_not_load_torch(run_without_torch):
    """Every classical method runs where torch cannot be imported; so does importing alcn_cv."""
    run_without_torch("""
        import numpy as np, alcn_cv
        for name in alcn_cv.available():
            if name != "alcn":
                alcn_cv.create(name).apply(np.zeros((40, 40), np.uint8))
    """)


def test_backend_follows_what_is_installed(run_python):
    """createALCN() runs a shipped Normalizer's ONNX export by cv2.dnn, installed torch or not, and a user's
    weight file in torch when torch is installed; asking for torch where it is missing names the extra to install."""
    assert alcn_cv.createALCN().backend == "opencv" and alcn_cv.createALCN(model="lite").backend == "opencv"
    assert alcn_cv.createALCN(weights=alcn_cv.createALCN().weights_path).backend == "fast"
    assert alcn_cv.createALCN(model="paper", grid_stride=16).backend == "fast"  # cv2.dnn runs the network's own
    proc = run_python("""
        import sys, numpy as np, alcn_cv
        from alcn_cv.errors import ALCNError, MissingDependencyError
        alcn = alcn_cv.createALCN()
        assert alcn.backend == "opencv" and "backend='opencv'" in repr(alcn), repr(alcn)
        assert alcn.apply((np.random.rand(48, 64) * 255).astype(np.uint8)).shape == (48, 64)
        for backend in ("fast", "torch"):
            try:
                alcn_cv.createALCN(backend=backend)
            except MissingDependencyError as exc:
                assert isinstance(exc, ImportError) and isinstance(exc, ALCNError)
                print(exc)
        try:
            from alcn_cv.nets import Normalizer
        except MissingDependencyError as exc:
            print(exc)
        assert "torch" not in sys.modules
    """)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert len(lines) == 3 and all('pip install "alcn-cv[train]"' in line for line in lines), lines
    assert lines[0].startswith("ALCN(backend='fast'): needs the [train] extra")
    assert lines[2].startswith("alcn_cv.nets.Normalizer: needs the [train] extra")


@pytest.mark.parametrize(
    ("call", "error", "ending"),
    [
        # threads select the backend that runs torch; without torch that said backend='opencv' runs no torch, and
        # then named a backend='fast' the user had not asked for
        (
            "threads=2",
            "MissingDependencyError",
            "ALCN(threads=2, torch's threads, runs backend='fast'): needs the [train] extra (torch, kornia are not "
            "installed): without a GPU, first pip install torch --index-url https://download.pytorch.org/whl/cpu; "
            'then pip install "alcn-cv[train]"',
        ),
        (
            "device='gpu'",
            "MissingDependencyError",
            "ALCN(device='gpu', runs backend='torch'): needs the [train] extra (torch, kornia are not installed): "
            "without a GPU, first pip install torch --index-url https://download.pytorch.org/whl/cpu; then pip install "
            '"alcn-cv[train]"',
        ),
        # cv2.dnn runs the network at its own stride
        (
            "grid_stride=16",
            "InputError",
            "another grid stride runs the network in torch: backend='fast' (the [train] extra)",
        ),
    ],
    ids=["threads", "device", "grid_stride"],
)
def test_what_needs_torch_without_it_says_what_to_do(run_python, call, error, ending):
    proc = run_python(f"""
        import alcn_cv
        from alcn_cv.errors import {error}
        try:
            alcn_cv.createALCN({call})
        except {error} as exc:
            print(exc)
    """)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip().endswith(ending), proc.stdout


def test_gain_models_before_opencv_4_8_fail_in_one_line(monkeypatch, capfd):
    """The ONNX importer of OpenCV 4.5 to 4.7 cannot import the gain exports: one line saying what runs them, before
    cv2.dnn logs its own errors and fails with lines of C++ context."""
    monkeypatch.setattr(alcn_module, "RUNS_GAIN", False)
    for model in ("gain", "gain-lite"):
        with pytest.raises(WeightFileError) as error:
            alcn_cv.createALCN(model=model, backend="opencv")
        assert "\n" not in str(error.value), error.value
        assert "cv2.dnn cannot run the gain Normalizers" in str(error.value)
        assert "use OpenCV 4.8 or newer, install torch (backend='fast') or model='lite'" in str(error.value)
    assert "onnx_importer" not in capfd.readouterr().err
    assert alcn_cv.createALCN(model="lite", backend="opencv").backend == "opencv"
    assert alcn_cv.createALCN().backend == "fast"  # the default: torch where cv2.dnn cannot


def test_gain_models_on_opencv_4_mirror_tiny_images_first(monkeypatch):
    """OpenCV 4's cv2.dnn runs the gain exports (4.8 on) but not a reflect pad longer than the side it pads: an image
    whose grid is smaller than the network's largest pad (4 grid points: under 18 px) is mirrored to 18 px first, as
    apply() completes a small window, and gives OpenCV 5's output within 0.01 (simulated here: CI runs OpenCV 5,
    which mirrors the grid instead, so the outputs agree with or without the mirroring: a spy on dense_grid checks
    that the network got the mirrored image and that its grid was cut back); from 18 px on, the same output."""
    from alcn_cv.nets import opencv_runtime

    calls = []  # (the image dense_grid was given, the grid it returned, the network's stride and largest pad)
    dense_grid = opencv_runtime.OpenCVNormalizer.dense_grid

    def spy(self, image, *args, **kwargs):
        grid = dense_grid(self, image, *args, **kwargs)
        calls.append((image.shape, grid.shape, self.stride, self.largest_pad))
        return grid

    monkeypatch.setattr(opencv_runtime.OpenCVNormalizer, "dense_grid", spy)
    rng = np.random.default_rng(0)
    texture = cv2.GaussianBlur((rng.random((64, 320)) * 255).astype(np.uint8), (0, 0), 1.5)
    for model in ("gain", "gain-lite"):
        alcn = alcn_cv.createALCN(model=model)
        assert alcn.backend == "opencv"  # the default on OpenCV 4.8 and newer, torch installed or not
        for shape in [(17, 40), (12, 300), (5, 5), (18, 18)]:
            image = np.ascontiguousarray(texture[: shape[0], : shape[1]])
            calls.clear()
            opencv5 = alcn.apply(image, out_dtype=np.float32)
            assert [c[0] for c in calls] == [shape], (model, shape, calls)  # OpenCV 5: the image itself
            calls.clear()
            with monkeypatch.context() as opencv4_dnn:
                opencv4_dnn.setattr(opencv_runtime, "OPENCV_4_DNN", True)
                opencv4 = alcn.apply(image, out_dtype=np.float32)
            stride, largest_pad = calls[-1][2:]
            grid = opencv_runtime.grid_shape(shape, stride)
            assert calls[-1][:2] == (shape, (calls[-1][1][0], *grid)), (model, shape, calls)  # the grid cut back
            if min(shape) < 18:
                assert min(grid) < largest_pad == 4 and stride == 8, (model, shape, calls)
                side = stride * (largest_pad - 2) + 2  # 18 px
                mirrored = (max(side, shape[0]), max(side, shape[1]))
                # the network ran on the image mirrored to 18 px a side, before the grid was cut back
                assert [c[0] for c in calls] == [mirrored, shape], (model, shape, calls)
                assert calls[0][1][1:] == opencv_runtime.grid_shape(mirrored, stride), (model, shape, calls)
            else:
                assert [c[0] for c in calls] == [shape], (model, shape, calls)  # no mirroring
            assert opencv4.shape == image.shape and np.abs(opencv4 - opencv5).max() < 1e-2, (model, shape)
            if min(shape) >= 18:
                np.testing.assert_array_equal(opencv4, opencv5)


@pytest.fixture(scope="module")
def random_head_weights(tmp_path_factory):
    """A weight file whose maps vary over the image, and its ONNX export beside it."""
    import torch

    from alcn_cv.nets import Normalizer
    from alcn_cv.train.export import export_onnx
    from alcn_cv.weight_file import save_normalizer_file

    torch.manual_seed(3)
    net = Normalizer(output_scale=2.0)
    folder = tmp_path_factory.mktemp("weights")
    meta = {
        "config": net.config,
        "sigmas": list(alcn_cv.gaussian_sigmas()),
        "working_scale": 0.5,
        "output_range": [-1.0, 1.0],
        "trained": False,
    }
    path = save_normalizer_file(folder / "random.npz", net.state_arrays(), meta)
    export_onnx(path.with_suffix(".onnx"), path)
    return path


def test_alcn_opencv_backend_agrees(random_head_weights, frames):
    gray, _ = frames
    fast = alcn_cv.createALCN(weights=random_head_weights, mixture="exact")
    opencv = alcn_cv.createALCN(weights=random_head_weights, backend="opencv", mixture="exact")
    assert np.ptp(fast.weight_maps(gray), axis=(1, 2)).max() > 1e-3  # maps really vary
    np.testing.assert_allclose(opencv.normalize(gray), fast.normalize(gray), atol=1e-4)
    np.testing.assert_allclose(opencv.weight_grid(gray), fast.weight_grid(gray), atol=1e-4)
    with pytest.raises(InputError, match="grid_stride"):
        alcn_cv.createALCN(weights=random_head_weights, backend="opencv", grid_stride=8)


def test_alcn_opencv_backend_runs_without_torch(random_head_weights, run_without_torch):
    run_without_torch(f"""
        import numpy as np, alcn_cv
        alcn = alcn_cv.createALCN(weights={str(random_head_weights)!r}, backend="opencv")
        out = alcn.apply((np.random.rand(48, 64) * 255).astype(np.uint8))
        assert out.shape == (48, 64) and out.dtype == np.uint8
    """)


def test_alcn_window_in_input_pixels_and_small_images(caplog, monkeypatch):
    from alcn_cv.enhance import base

    monkeypatch.setattr(base, "_WARNED_SMALL", set())
    assert alcn_cv.createALCN(scale=0.5).min_size == 96 and alcn_cv.createALCN(scale=1.0).min_size == 48
    assert alcn_cv.createALCN(model="paper", scale=0.7).min_size == 69  # 68.6 rounded up
    with caplog.at_level("WARNING", logger="alcn_cv.enhance.base"):
        out = alcn_cv.createALCN(model="lite").apply(np.full((47, 47), 128, np.uint8))
    assert out.shape == (47, 47)
    assert any("96 px window" in r.getMessage() for r in caplog.records)


@pytest.mark.parametrize("model", ["gain", "lite"])
def test_one_alcn_shared_by_threads(model):
    """cv2.dnn keeps the input it was given between setInput and forward: the default backend runs one
    inference at a time, so threads sharing one ALCN each get their own frame's output."""
    from concurrent.futures import ThreadPoolExecutor

    alcn = alcn_cv.createALCN(model=model)
    frames = [synthetic_frame(160, 120, False, seed=i) for i in range(8)]
    expected = [alcn.apply(f) for f in frames]
    with ThreadPoolExecutor(4) as pool:
        for _ in range(3):
            for got, want in zip(pool.map(alcn.apply, frames), expected):
                np.testing.assert_array_equal(got, want)


def test_same_method_fills_in_the_defaults():
    from alcn_cv.enhance.registry import same_method

    assert same_method("clahe", "clahe:clip_limit=2.0:tileGridSize=(8, 8)")
    assert same_method("alcn", "alcn:device=cpu:threads=auto")
    # the default model named or not (its default is None): examples/track_cookie_box.py rebuilt its part model on
    # every run when they differed
    assert same_method("alcn", "alcn:model=gain") and same_method("alcn:model=gain:scale=1.0", "alcn:scale=1.0")
    assert not same_method("alcn", f"alcn:weights={MODELS['gain']}")
    assert not same_method("clahe", "clahe:clipLimit=4")
    assert not same_method("alcn", "alcn:model=lite")
    with pytest.raises(InputError, match="unknown normalization"):
        same_method("clahe", "clahee")


def test_a_weight_file_without_its_export_says_how_to_make_it(tmp_path):
    import shutil

    weights = shutil.copy(MODELS["lite"], tmp_path / "mine.npz")
    with pytest.raises(WeightFileError, match=r"alcn export --weights .*mine\.npz --onnx .*mine\.onnx"):
        alcn_cv.createALCN(weights=weights, backend="opencv")
    assert f"weights='{weights}'" in repr(alcn_cv.createALCN(weights=weights))  # a user's file by its path


@pytest.mark.parametrize("backend", ["opencv", "fast", "torch"])
@pytest.mark.parametrize("model", ["gain", "lite"])
def test_building_an_alcn_reads_its_weight_file_once(tmp_path, monkeypatch, model, backend):
    """ALCN reads the header and hands what it read down: the runtime (the gain export's features on ``opencv``,
    ``ALCN2d`` on ``fast`` and ``torch``) does not load the file again."""
    import shutil

    if backend == "opencv" and model == "gain" and not alcn_module.RUNS_GAIN:
        pytest.skip("cv2.dnn of OpenCV 4.5 to 4.7 cannot run the gain Normalizers")
    weights = shutil.copy(MODELS[model], tmp_path / "mine.npz")
    shutil.copy(MODELS[model].with_suffix(".onnx"), tmp_path / "mine.onnx")
    load, loads = np.load, []

    def counted_load(file, *args, **kwargs):
        if isinstance(file, (str, os.PathLike)) and os.fspath(file) == os.fspath(weights):
            loads.append(file)
        return load(file, *args, **kwargs)

    monkeypatch.setattr(np, "load", counted_load)
    alcn = alcn_cv.createALCN(weights=weights, backend=backend)
    assert alcn.backend == backend and len(loads) == 1


@pytest.mark.skipif(not hasattr(os, "fork"), reason="no fork on this platform")
@pytest.mark.parametrize("kwargs", [{"backend": "torch"}, {"backend": "fast", "threads": 2}])
def test_a_forked_child_normalizes_after_its_parent_used_torchs_threads(kwargs):
    """torch's threads do not survive a fork: the child's first call hung (a multiprocessing pool's worker)."""
    import multiprocessing

    frame = np.random.default_rng(0).integers(0, 256, (240, 320, 3)).astype(np.uint8)
    alcn = alcn_cv.createALCN(**kwargs)
    parent = alcn.apply(frame)

    def child() -> None:
        os._exit(0 if np.abs(alcn.apply(frame).astype(int) - parent).max() <= 1 else 3)

    process = multiprocessing.get_context("fork").Process(target=child)
    process.start()
    process.join(120)
    hung = process.is_alive()
    if hung:
        process.kill()
    assert not hung and process.exitcode == 0


@pytest.mark.parametrize("shape", [(1, 640), (640, 1), (3, 3), (6, 6, 3)])
def test_the_torch_backend_mirrors_small_images_as_the_default_backend(shape, cpu_route):
    """apply() mirrors an image smaller than its kernels; the torch backend raised below 7 px (31 for lite)."""
    img = np.random.default_rng(1).integers(0, 256, shape).astype(np.uint8)
    for model in ("gain", "lite"):
        torch_out = alcn_cv.createALCN(model=model, backend="torch").apply(img)
        assert np.abs(torch_out.astype(int) - alcn_cv.createALCN(model=model).apply(img)).max() <= 1


def test_the_default_path_imports_neither_torch_nor_scipy():
    """An OpenCV app's start-up: `import alcn_cv` took twice as long with SciPy, used by the Retinex baseline only."""
    import subprocess
    import sys

    code = (
        "import sys, numpy as np, alcn_cv; alcn_cv.createALCN().apply(np.zeros((64, 64), np.uint8)); "
        "print(sorted(m for m in ('torch', 'scipy') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert out.stdout.strip() == "[]", out.stdout + out.stderr


@pytest.mark.parametrize("name", [n for n in METHODS if n != "alcn"])
def test_a_method_shared_by_threads_and_pickled_gives_each_frame_its_output(name):
    """A cv2.CLAHE keeps its buffers between calls: one shared by threads mixed their frames (and it could not be
    pickled for a process pool); ALCN's own case is test_one_alcn_shared_by_threads."""
    import pickle
    from concurrent.futures import ThreadPoolExecutor

    method = alcn_cv.create(name)
    frames = [synthetic_frame(96 + 16 * i, 72 + 8 * i, False, seed=i) for i in range(6)]
    expected = [method.apply(f) for f in frames]
    with ThreadPoolExecutor(4) as pool:
        for got, want in zip(pool.map(method.apply, frames * 8), expected * 8):
            np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(pickle.loads(pickle.dumps(method)).apply(frames[0]), expected[0])


def test_to_unit_takes_a_response_of_any_shape(methods):
    """A stack of windows' responses, say: OpenCV takes no array of four dimensions."""
    dog = methods["dog"]
    response = np.random.default_rng(0).normal(0.0, 0.1, (2, 3, 4, 5)).astype(np.float32)
    expected = np.stack([dog.to_unit(r) for r in response.reshape(-1, 4, 5)]).reshape(response.shape)
    np.testing.assert_allclose(dog.to_unit(response), expected, atol=1e-7, rtol=0)  # planes: cv2.addWeighted


def test_window_weights_take_uint8_windows_as_normalize_windows_does():
    """uint8 windows were cast to float32 without the scale: intensities of 0-255 where the network wants [0, 1]."""
    alcn = alcn_cv.createALCN(model="lite")
    windows = (np.random.default_rng(0).random((3, 48, 48)) * 255).astype(np.uint8)
    np.testing.assert_array_equal(
        alcn.window_weights(windows), alcn.window_weights(windows.astype(np.float32) * np.float32(1 / 255))
    )
    with pytest.raises(InputError, match="uint8 or float32"):
        alcn.window_weights(windows.astype(np.int32))


def test_eq1_weights_come_from_the_windows_centre():
    """Eq. 1 on a window larger than the Normalizer's: its one weight vector is predicted from the central 48x48 of
    the working image (8 working pixels in, for a 128-px window at scale 0.5), then mixed over the whole window. A
    crop from the corner instead gives weights of another part of the scene, a few hundredths off."""
    from alcn_cv.filters.gaussian_mixture import alcn_filter

    alcn = alcn_cv.createALCN(model="lite", backend="opencv")
    window = synthetic_frame(128, 128, False, seed=2).astype(np.float32) * np.float32(1 / 255)
    working = alcn.spec.working_image(window)
    assert working.shape == (64, 64)
    weights = alcn.window_weights(np.ascontiguousarray(working[None, 8:56, 8:56]))
    expected = alcn_filter(window, weights[0], alcn.full_res_sigmas)
    np.testing.assert_allclose(alcn.normalize_windows(window[None])[0], expected, atol=1e-6, rtol=0)


def test_the_largest_documented_scale_is_accepted():
    """``scale`` is a number in (0, 4], the bound included (a ``<`` for ``<=`` refused the documented 4)."""
    assert alcn_cv.createALCN(model="lite", scale=4).scale == 4.0
    with pytest.raises(InputError, match=r"scale must be a number in \(0, 4\], got 4\.001"):
        alcn_cv.createALCN(model="lite", scale=4.001)


def test_a_spec_value_may_hold_a_colon():
    """A Windows path (``C:\\...``) or a POSIX file name with a ``:`` split the spec into a bad parameter."""
    from alcn_cv.enhance.registry import parse_spec

    assert parse_spec(r"alcn:weights=C:\models\a.npz:scale=0.5") == (
        "alcn",
        {"weights": r"C:\models\a.npz", "scale": 0.5},
    )
    assert parse_spec("alcn:weights=/tmp/a:b.npz") == ("alcn", {"weights": "/tmp/a:b.npz"})
    with pytest.raises(InputError, match="expected NAME"):
        parse_spec("alcn:lite")  # a value without its key


def test_a_parameter_given_twice_or_of_the_wrong_type_says_how_to_give_it():
    with pytest.raises(InputError, match=r"sigma1 given in the spec 'dog:sigma1=1' and again on its own .*a keyword"):
        alcn_cv.create("dog:sigma1=1", sigma1=2)
    with pytest.raises(InputError, match=r"tileGridSize=4 must be a tuple, e.g. tileGridSize=\(8,8\)$"):
        alcn_cv.create("clahe", tileGridSize=4)


def test_numpy_integers_are_integers():
    """grid_stride=np.int64(16) was refused as "must be a positive multiple of 8, got np.int64(16)", and
    threads=np.int64(2) as "must be a positive integer"."""
    alcn = alcn_cv.createALCN(grid_stride=np.int64(16), threads=np.int64(2))
    assert (alcn.grid_stride, alcn.threads) == (16, 2) and type(alcn.grid_stride) is int and type(alcn.threads) is int


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: alcn_cv.create(3), "a method is a string NAME"),  # AttributeError: 'int' object has no 'strip'
        (lambda: alcn_cv.create(None), "a method is a string NAME"),
        (lambda: alcn_cv.create("clahe:clipLimit=3:clipLimit=4"), "parameter 'clipLimit' given twice"),  # the last
        (lambda: alcn_cv.createALCN("lite"), "weights='lite' is no file; the shipped model of that name is model="),
        (lambda: alcn_cv.createALCN(device=None), "device must be a torch device's name"),  # backend='torch'
    ],
)
def test_arguments_an_opencv_user_may_pass_by_mistake(call, message):
    with pytest.raises(InputError, match=message.replace("(", r"\(")):
        call()


def test_the_output_range_is_fixed_as_the_other_settings():
    """Assigning output_range was taken: apply() read the new one, apply_batch the weight file's, 10 levels apart."""
    alcn = alcn_cv.createALCN()
    with pytest.raises(AttributeError, match=r"ALCN.output_range is fixed .* createALCN\(weights=...\)"):
        alcn.output_range = (-1.0, 1.0)


@pytest.mark.parametrize("backend", ["opencv", "fast", "torch"])
def test_the_float_entry_points_refuse_values_outside_the_unit_range(backend):
    """normalize(), weight_maps() and weight_grid() took 0-255 floats silently (negative ones gave NaN), where apply()
    refuses them; on the OpenCV backend the working image's range was reported, not the caller's."""
    alcn = alcn_cv.createALCN(model="lite", backend=backend)
    gray = np.random.default_rng(0).random((64, 80), dtype=np.float32)
    for method in (alcn.normalize, alcn.weight_maps, alcn.weight_grid):
        method(gray)
        with pytest.raises(InputError, match=r"must be in \[0, 1\], got \[0\.0\d+, 25\d(\.\d)?\] \(divide by 255"):
            method(gray * 255)
        with pytest.raises(InputError, match="contains NaN or inf"):
            method(np.full_like(gray, np.nan))
    with pytest.raises(InputError, match=r"must be in \[0, 1\], got \[0\.0\d+, 25\d(\.\d)?\] \(divide by 255"):
        alcn.window_weights(np.random.default_rng(1).random((2, 48, 48), dtype=np.float32) * 255)


def test_the_filters_star_import_imports_no_torch(run_without_torch):
    """`from alcn_cv.filters import *` loaded torch and kornia (their two lazy names were in __all__), and failed on
    a base install with a bare ModuleNotFoundError; the NumPy/OpenCV filters import no torch."""
    run_without_torch("from alcn_cv.filters import *\nassert callable(alcn_filter)\n")


def test_the_numpy_filters_name_a_wrong_dtype():
    """divisive_normalization and gaussian_energy of a float64 or uint8 image ended in OpenCV's "Unsupported
    combination of buffer format"; wide_band of a uint8 image averaged 0-255 values silently."""
    from alcn_cv.filters.divisive import divisive_normalization, gaussian_energy
    from alcn_cv.filters.wide_band import wide_band

    calls = (
        lambda a: divisive_normalization(a, 2.0, 1.0),
        lambda a: gaussian_energy(a, 2.0),
        lambda a: wide_band(a, 3.0),
    )
    for call in calls:
        for dtype in (np.float64, np.uint8):
            with pytest.raises(InputError, match=f"must be float32 .*got {np.dtype(dtype).name}"):
                call(np.zeros((32, 32), dtype))


def test_from_spec_defaults_yield_to_the_specs_own_parameters():
    """``from_spec(spec, **defaults)``: the defaults fill in what the spec does not give, never override it (the
    corner detector's ``scale=1.0`` under a recorded ``alcn:scale=...``)."""
    dog = from_spec("dog:sigma2=3", sigma2=2.0, sigma1=0.75)
    assert (dog.sigma1, dog.sigma2) == (0.75, 3.0)


def test_a_whole_float_for_an_integer_parameter_is_left_to_the_constructor():
    """``-p size=9.0`` (a float where an int is annotated) is accepted as the registry's comment promises."""
    assert alcn_cv.create("lrn:size=9.0").size == 9
    assert alcn_cv.create("lrn", size=np.int64(9)).size == 9
