"""The fast paths of ``apply`` and of ALCN give the results of the plain ones: strips of a large
image, the lite Normalizer's NumPy tanh, the level-0 maps by one resize, the torch thread
setting, the batched torch path, and the video pipeline's order and errors."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

torch = pytest.importorskip("torch")

import alcn_cv  # noqa: E402
from alcn_cv.data.frames import synthetic_frame  # noqa: E402
from alcn_cv.enhance import base  # noqa: E402
from alcn_cv.enhance.registry import from_spec  # noqa: E402
from alcn_cv.errors import InputError  # noqa: E402
from alcn_cv.io import map_video, open_video_writer  # noqa: E402
from alcn_cv.runtime import _integer_zoom  # noqa: E402

#: ALCN's models, and every other registered method that cuts a large image into strips (a method registered later
#: with a ``_tiling`` of its own is checked too).
STRIPPED = ["alcn", "alcn:model=lite", "alcn:model=paper:grid_stride=16"] + [
    m for m in alcn_cv.available() if m != "alcn" and type(from_spec(m))._tiling is not base.Normalization._tiling
]


@pytest.mark.parametrize("spec", STRIPPED)
@pytest.mark.parametrize("colour", [False, True])
def test_strips_give_the_whole_image(monkeypatch, spec, colour):
    method = from_spec(spec)
    frame = synthetic_frame(300, 416, colour, seed=4)
    whole = method.apply(frame, out_dtype=np.float32)
    monkeypatch.setattr(base, "TILE_PIXELS", 20_000)
    assert len(method._strips(frame.shape[:2])) > 3
    np.testing.assert_allclose(method.apply(frame, out_dtype=np.float32), whole, atol=1e-4)
    np.testing.assert_array_equal(np.abs(method.apply(frame).astype(int) - np.rint(whole * 255)) <= 1, True)


def test_whole_image_methods_and_odd_working_sizes_are_not_cut(monkeypatch):
    monkeypatch.setattr(base, "TILE_PIXELS", 20_000)
    assert from_spec("ns")._strips((416, 300)) is None
    assert from_spec("alcn:model=lite")._strips((417, 300)) is None  # 417 rows have no whole working image at scale 0.5
    assert from_spec("alcn")._strips((16, 300)) is None  # small images stay whole (below the limit)
    monkeypatch.setattr(base, "TILE_PIXELS", 10**9)
    assert from_spec("alcn")._strips((416, 300)) is None


def test_lite_inference_tanh_equals_torch():
    alcn = alcn_cv.createALCN(model="lite", backend="fast")
    image = torch.from_numpy(synthetic_frame(200, 160, False).astype(np.float32) / 255)[None, None]
    with torch.inference_mode():
        fast = alcn.net.dense_grid(image)
    reference = alcn.net.dense_grid(image).detach()  # gradients on: torch's own layers
    torch.testing.assert_close(fast, reference, atol=1e-6, rtol=0)


def test_level0_maps_are_the_exact_bilinear_interpolation():
    alcn = alcn_cv.createALCN(model="lite")
    gray = synthetic_frame(320, 240, False).astype(np.float32) / 255
    grid = alcn.weight_grid(gray)
    assert _integer_zoom(1 / 16, -1 / 32) == (16, 7)
    assert _integer_zoom(1 / 8, -1 / 32) is None  # level 1: a quarter-pixel shift
    maps = alcn.runtime._grid_maps_at(grid, (0.5, 0.5), 0, [0, 3], (243, 323))
    to_grid = np.array([[1 / 16, 0, -1 / 32], [0, 1 / 16, -1 / 32]])
    for k, m in zip([0, 3], maps):
        exact = cv2.warpAffine(
            grid[k], to_grid, (323, 243), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_REPLICATE
        )
        np.testing.assert_allclose(m, exact, atol=1e-6)


def test_torch_threads_default_by_backend_and_are_restored():
    before = torch.get_num_threads()
    alcn = alcn_cv.createALCN(backend="fast")  # the network in torch
    assert alcn.threads == 1 and alcn_cv.createALCN().threads == 1
    try:
        torch.set_num_threads(2)
        alcn.apply(synthetic_frame(96, 72, False))
        assert torch.get_num_threads() == 2
    finally:
        torch.set_num_threads(before)
    assert alcn_cv.createALCN(threads=None).threads is None
    # everything in torch: torch's own setting, unless asked
    assert alcn_cv.createALCN(backend="torch").threads is None
    assert alcn_cv.createALCN(backend="torch", threads=2).threads == 2
    with pytest.raises(InputError, match="'auto'"):
        alcn_cv.createALCN(threads="all")


@pytest.mark.parametrize("model", ["lite", "gain"])
def test_batched_torch_path_equals_apply(model, cpu_route):
    alcn = alcn_cv.createALCN(model=model, backend="torch")
    frames = np.stack([synthetic_frame(160, 96, False, seed=i) for i in range(3)])
    single = np.stack([alcn.apply(f, out_dtype=np.float32) for f in frames])
    batch = alcn.apply_batch(frames, out_dtype=np.float32)
    assert batch.shape == frames.shape and batch.dtype == np.float32
    np.testing.assert_allclose(batch, single, atol=1e-5)
    as_uint8 = alcn.apply_batch(frames)
    assert as_uint8.dtype == np.uint8
    assert np.abs(as_uint8.astype(int) - np.stack([alcn.apply(f) for f in frames])).max() <= 1
    # float16 on the CPU only checks the path: its error is reported by ``alcn bench speed``
    np.testing.assert_allclose(alcn.apply_batch(frames, out_dtype=np.float32, half=True), batch, atol=2e-2)


def test_batched_path_errors():
    with pytest.raises(InputError, match="backend='torch'"):
        alcn_cv.createALCN().apply_batch(np.zeros((2, 64, 64), np.uint8))
    alcn = alcn_cv.createALCN(backend="torch")
    with pytest.raises(InputError, match=r"\(B, H, W\)"):
        alcn.apply_batch(np.zeros((64, 64), np.uint8))
    with pytest.raises(InputError, match=r"\[0, 1\]"):
        alcn.apply_batch(np.full((2, 64, 64), 2.0, np.float32))


def test_batched_path_takes_what_apply_takes(cpu_route):
    """BGR and BGRA frames: normalized on their CIE L, alpha passed through, as apply() does."""
    alcn = alcn_cv.createALCN(backend="torch")
    rng = np.random.default_rng(0)
    bgra = rng.integers(0, 256, (2, 64, 80, 4), dtype=np.uint8)
    for frames in (np.ascontiguousarray(bgra[..., :3]), bgra):
        out = alcn.apply_batch(frames)
        assert out.shape == frames.shape and out.dtype == np.uint8
        assert np.abs(out.astype(int) - np.stack([alcn.apply(f) for f in frames])).max() <= 1


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device: the CUDA path is checked on a GPU machine")
def test_cuda_agrees_with_the_cpu():
    frames = np.stack([synthetic_frame(320, 240, False, seed=i) for i in range(4)])
    cpu = alcn_cv.createALCN(backend="torch").apply_batch(frames, out_dtype=np.float32)
    cuda = alcn_cv.createALCN(backend="torch", device="cuda")
    np.testing.assert_allclose(cuda.apply_batch(frames, out_dtype=np.float32), cpu, atol=1e-3)


def _video(path, frames: int) -> None:
    writer = open_video_writer(path, 10.0, (64, 48), color=True)
    for i in range(frames):
        writer.write(np.full((48, 64, 3), 10 + 20 * i, np.uint8))
    writer.release()


def test_video_pipeline_keeps_the_order(tmp_path):
    _video(tmp_path / "in.avi", 8)
    assert map_video(tmp_path / "in.avi", tmp_path / "out.avi", lambda frame: 255 - frame) == 8
    cap = cv2.VideoCapture(str(tmp_path / "out.avi"))
    means = []
    while (frame := cap.read()[1]) is not None:
        means.append(frame.mean())
    cap.release()
    np.testing.assert_allclose(means, [245 - 20 * i for i in range(8)], atol=3)


def test_video_pipeline_error_leaves_nothing(tmp_path):
    _video(tmp_path / "in.avi", 6)
    calls = []

    def failing(frame: np.ndarray) -> np.ndarray:
        calls.append(1)
        if len(calls) == 4:
            raise RuntimeError("boom")
        return frame

    with pytest.raises(RuntimeError, match="boom"):
        map_video(tmp_path / "in.avi", tmp_path / "out.avi", failing)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.avi"]


@pytest.mark.parametrize("name", ["he", "clahe"])
def test_uint8_shortcut_equals_the_float_path(monkeypatch, name):
    method = from_spec(name)
    frame = synthetic_frame(200, 150, False, seed=7)
    direct = method.apply(frame)
    monkeypatch.setattr(method, "_apply_gray_uint8", lambda gray8: None)
    np.testing.assert_array_equal(direct, method.apply(frame))


@pytest.mark.parametrize("name", ["none", "ns"])
def test_uint8_lookup_equals_the_float_path_on_every_level(monkeypatch, name):
    method = from_spec(name)
    rng = np.random.default_rng(3)
    frames = [
        np.arange(256, dtype=np.uint8).reshape(16, 16),
        rng.integers(0, 256, (123, 77), dtype=np.uint8),
        synthetic_frame(200, 150, False, seed=8),
        np.full((9, 11), 200, np.uint8),
    ]
    direct = [method.apply(frame) for frame in frames]
    monkeypatch.setattr(method, "_apply_gray_uint8", lambda gray8: None)
    for frame, result in zip(frames, direct):
        np.testing.assert_array_equal(result, method.apply(frame))


def test_unit_float_conversions_are_the_numpy_ones():
    from alcn_cv.checks import from_unit_float, to_unit_float, unit_windows
    from alcn_cv.enhance.histogram import _to_uint8

    values = np.random.default_rng(0).random((60, 256), dtype=np.float32) * 1.2 - 0.1
    values[0] = (np.arange(256) + 0.5) / 255  # ties
    expected = np.rint(np.clip(values, 0, 1) * 255).astype(np.uint8)
    kept = values.copy()
    np.testing.assert_array_equal(_to_uint8(values), expected)
    np.testing.assert_array_equal(values, kept)  # the caller's plane is left as it was
    strided, read_only = kept[:, ::2], kept.copy()
    read_only.flags.writeable = False  # other layouts are copied (OpenCV's dst= failed on a strided view)
    np.testing.assert_array_equal(from_unit_float(strided, np.dtype(np.uint8)), expected[:, ::2])
    np.testing.assert_array_equal(from_unit_float(read_only, np.dtype(np.uint16)), np.rint(np.clip(kept, 0, 1) * 65535))
    np.testing.assert_array_equal(from_unit_float(values, np.dtype(np.uint8)), expected)
    gray8 = np.arange(256, dtype=np.uint8).reshape(16, 16)
    np.testing.assert_array_equal(to_unit_float(gray8), gray8.astype(np.float32) * np.float32(1 / 255))
    windows = np.arange(256, dtype=np.uint8).reshape(1, 16, 16).repeat(3, axis=0)
    np.testing.assert_array_equal(unit_windows(windows), windows.astype(np.float32) * np.float32(1 / 255))


def test_output_map_is_the_numpy_one():
    method = from_spec("dog")
    response = np.random.default_rng(1).normal(0, 0.08, (120, 160)).astype(np.float32)
    unit = np.clip((response.astype(np.float64) + 0.1) * 5, 0, 1)
    np.testing.assert_allclose(method.to_unit(response), unit, atol=1e-6)
    np.testing.assert_array_equal(
        method._response_to(response.copy(), np.dtype(np.uint8)),
        np.rint(method.to_unit(response) * 255).astype(np.uint8),
    )


def test_strips_of_a_gain_model_without_its_band_give_the_whole_image(monkeypatch, tmp_path):
    """A user's gain model without the wide band: the shipped models' band reaches farther than the network's grid,
    the mixture and the divisive step together, so their strips test the band's halo only."""
    from alcn_cv.nets.gain import GainNormalizer
    from alcn_cv.runtime import MODELS
    from alcn_cv.weight_file import NormalizerFile, load_normalizer_file, save_normalizer_file

    shipped = load_normalizer_file(MODELS["gain"])
    net = GainNormalizer.from_file(
        NormalizerFile(shipped.arrays, {**shipped.meta, "config": {**shipped.meta["config"], "band": 0.0}})
    )
    save_normalizer_file(tmp_path / "no_band.npz", net.state_arrays(), net.file_meta(trained=True))
    method = alcn_cv.createALCN(weights=tmp_path / "no_band.npz")
    frame = synthetic_frame(300, 416, False, seed=4)
    whole = method.apply(frame, out_dtype=np.float32)
    monkeypatch.setattr(base, "TILE_PIXELS", 20_000)
    assert len(method._strips(frame.shape[:2])) > 3
    np.testing.assert_allclose(method.apply(frame, out_dtype=np.float32), whole, atol=1e-4)


def test_an_image_just_above_the_tile_limit_is_cut(monkeypatch):
    monkeypatch.setattr(base, "TILE_PIXELS", 20_000)
    assert from_spec("alcn")._strips((100, 300))  # 30 000 pixels: strips of 32 rows
    assert from_spec("alcn")._strips((60, 300)) is None
