"""alcn_cv.nn: ALCN2d / alcn2d, the torch runtime of every shipped model, against apply()."""

import os
import shutil
import threading
import time
import warnings
from collections.abc import Callable

import cv2
import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("kornia")


import alcn_cv
import alcn_cv.nn as alcn_nn
import alcn_cv.runtime as alcn_runtime
from alcn_cv.data.frames import synthetic_frame
from alcn_cv.errors import InputError
from alcn_cv.filters.torch_lab import LabToRgb, RgbToLab
from alcn_cv.filters.torch_pad import reflect101_pad
from alcn_cv.filters.torch_resize import upsample_blocks
from alcn_cv.nets import cpu_inference
from alcn_cv.nets.gain import GainNormalizer, contrast_equalization
from alcn_cv.nn import ALCN2d, alcn2d, batches
from alcn_cv.runtime import MODELS, GainRuntime
from alcn_cv.weight_file import load_normalizer_file, save_normalizer_file

CUDA = pytest.mark.skipif(
    not torch.cuda.is_available(), reason="no CUDA device: the CUDA path is checked on a GPU machine"
)


def _unit(img: np.ndarray) -> np.ndarray:
    """What apply() converts a uint8 image to (a multiplication by 1/255, not a division)."""
    return img.astype(np.float32) * np.float32(1.0 / 255)


def _gray(h=96, w=128, seed=0):
    return synthetic_frame(w, h, False, seed=seed)


def _bgr(h=96, w=128, seed=0):
    return synthetic_frame(w, h, True, seed=seed)


@pytest.mark.parametrize("model", list(MODELS))
@pytest.mark.parametrize("shape", [(96, 128), (75, 101)])
def test_gray_equals_the_float_output_of_apply(model, shape, cpu_route):
    """Against the OpenCV runtime (the default backend; the exact mixture, which the lite and paper models'
    default pyramid approximates), not the torch backend, which runs this module; odd sides too, which the lite and
    paper models' working scale resizes by OpenCV's area weights. The gain models' torch filters too (cpu_route)."""
    gray = _gray(*shape)
    expected = alcn_cv.createALCN(model=model, mixture="exact").apply(gray, out_dtype=np.float32)
    with torch.no_grad():
        out = ALCN2d(model=model).eval()(torch.from_numpy(_unit(gray))[None, None])
    assert out.shape == (1, 1, *gray.shape) and out.dtype == torch.float32
    np.testing.assert_allclose(out[0, 0].numpy(), expected, atol=1e-5, rtol=0)


@pytest.mark.parametrize("model", ["gain", "gain-lite"])
def test_cpu_inference_of_the_gain_models_runs_the_opencv_runtime(model, monkeypatch):
    """In CPU inference the gain models run apply()'s own runtime (GainRuntime) for one image or large ones, each image
    of a batch with its own floors (broadcast as the torch filters take them); with autograd the torch filters, to
    float rounding; a batch of small images stays on the torch filters (one pass over the batch)."""
    calls = []
    normalize = GainRuntime.normalize
    monkeypatch.setattr(
        GainRuntime, "normalize", lambda self, gray, *floors: (calls.append(floors), normalize(self, gray, *floors))[1]
    )
    module = ALCN2d(model=model).eval()
    x = torch.from_numpy(np.stack([_unit(_gray(512, 512, seed=i)) for i in range(2)]))[:, None]  # 2**18 pixels each
    floor, band_floor = torch.tensor([0.01, 0.02]).view(2, 1, 1, 1), torch.tensor(0.03)
    with torch.no_grad():
        routed = module.response(x, floor=floor, band_floor=band_floor)
    assert calls == [pytest.approx((0.01, 0.03)), pytest.approx((0.02, 0.03))]
    filters = module.response(x, floor=floor, band_floor=band_floor)  # autograd on: the torch filters
    assert len(calls) == 2 and not torch.equal(routed, filters.detach())
    # the contract's 1e-5 is of the output in [0, 1]
    torch.testing.assert_close(module.to_unit(routed), module.to_unit(filters.detach()), atol=1e-5, rtol=0)
    with torch.no_grad():
        module.response(x, half=True)  # the network in float16: torch's
        module(x[:, :, :100, :100])  # two small images
        assert module(x[:0]).shape == (0, 1, *x.shape[2:])  # an empty batch
        eq3 = module.eq3(x)  # the strips' first pass
    assert len(calls) == 2 and not torch.equal(eq3, module.eq3(x))
    torch.testing.assert_close(eq3, module.eq3(x), atol=1e-6, rtol=0)
    # forward, gray and RGB (apply()'s colour path), against the torch filters
    rgb = torch.from_numpy(np.stack([_unit(_bgr(seed=i)[..., ::-1].copy()) for i in range(2)])).permute(0, 3, 1, 2)
    for image in (x[:1], rgb[:1]):
        with torch.no_grad():
            routed = module(image)
        assert len(calls) == 3 and routed.shape == image.shape and routed.is_contiguous()
        torch.testing.assert_close(routed, module(image).detach(), atol=1e-5, rtol=0)
        del calls[2:]


def test_cpu_inference_follows_the_networks_own_scales_and_torchs_threads(tmp_path, monkeypatch):
    """The route takes tau and the floor as the network has them now (a learn_scales model after a step; they were the
    weight file's: 0.1 off the torch filters), its runtime kept between calls until they change, and no more parts of
    the rows than torch has threads."""
    net = GainNormalizer(learn_scales=True)
    path = save_normalizer_file(tmp_path / "gain.npz", net.state_arrays(), net.file_meta(trained=True))
    module = ALCN2d(weights=path).eval()
    x = torch.from_numpy(_unit(_gray(96, 128)))[None, None]
    with torch.no_grad():
        module(x)
        runtime = module._opencv_runtime()
        assert module._opencv_runtime() is runtime
        module.net.log_tau.add_(0.5)
        module.net.log_floor_scale.sub_(0.5)
        routed = module(x)
    assert module._opencv_runtime() is not runtime
    torch.testing.assert_close(routed, module(x).detach(), atol=1e-5, rtol=0)
    parts = []
    row_parts = alcn_runtime.row_parts
    monkeypatch.setattr(alcn_runtime, "row_parts", lambda *args: (parts.append(args[2]), row_parts(*args))[1])
    with torch.no_grad(), alcn_nn.torch_threads(1):
        module(x)
    assert parts == [1]


def _colour_differences(model: str, bgr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """|ALCN2d - apply()| in colour, in float32 inference and with autograd."""
    expected = alcn_cv.createALCN(model=model, mixture="exact").apply(bgr, out_dtype=np.float32)
    rgb = torch.from_numpy(_unit(bgr[..., ::-1].copy())).permute(2, 0, 1)[None]
    module = ALCN2d(model=model).eval()
    with torch.no_grad():
        inference = np.abs(module(rgb)[0].permute(1, 2, 0).numpy()[..., ::-1] - expected)
    autograd = np.abs(module(rgb)[0].detach().permute(1, 2, 0).numpy()[..., ::-1] - expected)
    return inference, autograd


@pytest.mark.parametrize("model", ["gain", "lite"])
def test_colour_is_normalized_on_lab_lightness(model):
    """RGB in, normalized on L with a and b kept, as apply() does: in float32 on the CPU by apply()'s own Lab passes,
    within 1e-5, with autograd too."""
    inference, autograd = _colour_differences(model, _bgr())
    assert inference.max() < 1e-5, inference.max()
    assert autograd.max() < 1e-5, autograd.max()


@pytest.mark.shared_data
@pytest.mark.parametrize("model", ["gain", "lite"])
def test_colour_of_a_photograph_within_1e5_in_inference(model, shared_data):
    """The torch conversion's float32 rounding of L (3e-5 of 100), amplified by the divisive step in the flat regions
    of a photograph, puts its output about 1e-4 from apply()'s; on the CPU, with autograd too, the Lab is apply()'s
    own."""
    photo = shared_data / "lumia_box" / "box5.JPG"
    if not photo.is_file():
        pytest.skip(f"{photo} not found")
    bgr = cv2.resize(cv2.imread(str(photo)), (320, 200), interpolation=cv2.INTER_AREA)
    inference, autograd = _colour_differences(model, bgr)
    assert inference.max() < 1e-5, inference.max()
    assert autograd.max() < 1e-5, autograd.max()


def test_eq3_of_the_gain_models_is_the_mixture_of_their_maps():
    """Eq. 3 of the two opposite maps as one difference of blurs: the mixture of both maps, to float rounding."""
    x = torch.from_numpy(_unit(_gray()))[None, None]
    for model in ("gain", "gain-lite"):
        module = ALCN2d(model=model).eval()
        with torch.no_grad():
            maps = module.weight_maps(x)
            torch.testing.assert_close(maps[:, 1:], -maps[:, :1])
            torch.testing.assert_close(module.eq3(x), module.mixture(x, maps), atol=1e-6, rtol=0)


def test_functional_form_and_weight_files():
    x = torch.from_numpy(_unit(_gray()))[None, None]
    module = ALCN2d(weights=MODELS["lite"]).eval()
    with torch.no_grad():
        torch.testing.assert_close(alcn2d(x, model="lite"), module(x))
        torch.testing.assert_close(ALCN2d()(x), alcn2d(x))  # the default model
    with pytest.raises(InputError, match="unknown model"):
        ALCN2d(model="vulkan")
    with pytest.raises(InputError, match=r"\(B, 1 \| 3, H, W\)"):
        module(torch.rand(1, 2, 64, 64))


def test_alcn2d_takes_the_working_scale_as_the_module():
    """alcn2d had no scale: a noisy camera's `scale=0.7` (the README's) needed an ALCN2d."""
    x = torch.from_numpy(_unit(_gray(48, 64)))[None, None]
    with torch.no_grad():
        torch.testing.assert_close(alcn2d(x, scale=0.7), ALCN2d(scale=0.7).eval()(x))
        assert not torch.allclose(alcn2d(x, scale=0.7), alcn2d(x), atol=1e-3)


def test_alcn2d_reads_a_weight_file_saved_again(tmp_path, monkeypatch):
    """alcn2d kept the module of a weight file by its name: a file saved again after more fine-tuning, or another
    file of the same relative name in another folder, gave the first file's output."""
    x = torch.from_numpy(_unit(_gray(48, 64)))[None, None]
    tuned = ALCN2d(model="lite")
    tuned.save(tmp_path / "tuned.npz")
    first = alcn2d(x, weights=tmp_path / "tuned.npz")
    with torch.no_grad():
        for parameter in tuned.parameters():
            parameter.add_(0.05)
    tuned.save(tmp_path / "tuned.npz")
    with torch.no_grad():
        torch.testing.assert_close(alcn2d(x, weights=tmp_path / "tuned.npz"), tuned.eval()(x))
    assert not torch.equal(alcn2d(x, weights=tmp_path / "tuned.npz"), first)
    for name, model in (("a", "lite"), ("b", "paper")):
        (tmp_path / name).mkdir()
        shutil.copy(MODELS[model], tmp_path / name / "w.npz")
        monkeypatch.chdir(tmp_path / name)
        torch.testing.assert_close(alcn2d(x, weights="w.npz"), alcn2d(x, model=model))


def test_a_module_of_a_weight_file_already_read_is_the_constructors(tmp_path):
    """ALCN2d(weights=contents), what createALCN builds from the file it read: the module of the file's path, the file
    not read again (deleted here)."""
    weights = shutil.copy(MODELS["gain-lite"], tmp_path / "mine.npz")
    weight_file = load_normalizer_file(weights)
    os.remove(weights)
    module = ALCN2d(weights=weight_file, grid_stride=16).eval()
    built = ALCN2d(model="gain-lite", grid_stride=16).eval()
    assert (module.spec, module.grid_stride, module.allow_tf32) == (built.spec, 16, False)
    x = torch.from_numpy(_unit(_bgr()))[None].permute(0, 3, 1, 2).flip(1).contiguous()
    with torch.no_grad():
        torch.testing.assert_close(module(x), built(x), atol=0, rtol=0)
    with pytest.raises(InputError, match="grid_stride"):
        ALCN2d(weights=weight_file, grid_stride=12)


def test_a_wrong_input_is_named_before_torch_fails():
    module = ALCN2d(model="lite").eval()
    with pytest.raises(InputError, match=r"H and W not 0"):
        module(torch.rand(1, 1, 0, 32))
    with pytest.raises(InputError, match=r"RGBA: image\[:, :3\]"):
        module(torch.rand(1, 4, 32, 32))
    with pytest.raises(InputError, match=r"channels last: image.permute\(0, 3, 1, 2\)"):
        module(torch.rand(1, 32, 32, 3))
    with pytest.raises(InputError, match=r"one image: image\[None\]"):
        module(torch.rand(3, 32, 32))
    with pytest.raises(InputError, match=r"a batch of gray images: image\[:, None\]"):
        module(torch.rand(5, 32, 32))
    with pytest.raises(InputError, match=r"float in \[0, 1\], got torch.uint8"):
        module(torch.zeros(1, 1, 32, 32, dtype=torch.uint8))
    with pytest.raises(InputError, match=r"torch.float64 on cpu, the module torch.float32 on cpu: move the module"):
        module(torch.rand(1, 1, 32, 32, dtype=torch.float64))
    with torch.no_grad():
        assert module.double()(torch.rand(1, 1, 32, 32, dtype=torch.float64)).dtype == torch.float64


def test_the_functional_form_names_a_wrong_input_too():
    """alcn2d checks the image before it builds a module for its dtype (torch's own error for an integer one); the
    hint for integers is apply()'s conversion, a multiplication (a division is 6e-5 off apply() on a photograph)."""
    with pytest.raises(InputError, match=r"got torch.uint8 \(a uint8 image: image \* \(1 / 255\)\)"):
        alcn2d(torch.zeros(1, 1, 32, 32, dtype=torch.uint8))
    with pytest.raises(InputError, match=r"must be a torch.Tensor, got ndarray \(a NumPy array: torch.from_numpy\)"):
        alcn2d(np.zeros((1, 1, 32, 32), np.float32))
    with pytest.raises(InputError, match=r"one image, channels last: image.permute\(2, 0, 1\)\[None\]"):
        alcn2d(torch.rand(32, 40, 3))


def test_values_outside_the_unit_range_are_named_on_the_cpu():
    """On the CPU, run eagerly, the range is read (no device to wait for): 0..255 RGB was normalized silently wrong
    (0.73 off), a standardized gray image gave NaN everywhere, a NaN pixel a NaN image. apply()'s 1e-3 of rounding
    is let through; traced, compiled or vmapped it is not checked (test_traces_as_one_graph_for_torch_compile,
    test_colour_under_torch_func_transforms)."""
    module = ALCN2d(model="lite").eval()
    x = torch.rand(2, 3, 32, 40)
    with pytest.raises(InputError, match=r"got values in \[.*\] \(0\.\.255 intensities: image \* \(1 / 255\)\)"):
        module(x * 255)
    with pytest.raises(InputError, match=r"\(0\.\.65535 intensities: image \* \(1 / 65535\)\)"):
        module(x * 65535)
    with pytest.raises(InputError, match=r"standardized\? undo transforms.Normalize"):
        module((x[:, :1] - 0.5) / 0.25)
    with pytest.raises(InputError, match=r"got values in \[-0\.1, 1\.1\] \(an overshoot.*: image.clamp\(0, 1\)\)"):
        module(x.clamp(0.1, 0.9) * 1.5 - 0.25)
    nan = x.clone()
    nan[1, 0, 3, 4] = float("nan")
    with pytest.raises(InputError, match=r"one such pixel would make its whole image NaN"):
        alcn2d(nan)
    with pytest.raises(InputError, match=r"\(0\.\.255 intensities"):
        alcn2d(x[:, :1] * 255, model="lite")
    with torch.no_grad():
        assert torch.isfinite(module(x * (1 + 5e-4) - 2e-4)).all()


def test_an_empty_batch_gives_an_empty_output():
    """B = 0, which convolutions take (the last batch of a filtered stream, say), was refused; its output keeps the
    autograd graph of a trainable module, as any batch's."""
    module = ALCN2d(model="gain")
    for channels in (1, 3):
        x = torch.rand(0, channels, 32, 40, requires_grad=True)
        out = module(x)
        assert (out.shape, out.dtype, out.device) == (x.shape, x.dtype, x.device)
        out.sum().backward()
        assert x.grad is not None and x.grad.shape == x.shape
        assert alcn2d(x.detach()).shape == x.shape


@pytest.mark.parametrize("dtype", [torch.float32, torch.float16])
def test_an_empty_batch_under_no_grad(dtype):
    """Under no_grad, B = 0 of images below the OpenCV passes' 2**18 pixels (torch's filters) ended in a RuntimeError:
    the head's maps reshaped with -1, which a batch of no cells leaves undefined."""
    module = ALCN2d(model="gain").to(dtype)
    for channels in (1, 3):
        with torch.no_grad():
            out = module(torch.zeros(0, channels, 48, 64, dtype=dtype))
        assert (out.shape, out.dtype) == ((0, channels, 48, 64), dtype)


def test_the_meta_device_propagates_gray_shapes_and_names_colour():
    """On the meta device repr() read tau's value and forward asked torch whether autocast was on, both errors; a gray
    image now propagates its shape, colour (whose Lab conversions switch autocast off) is an InputError."""
    module = ALCN2d().to("meta")
    assert "tau=?" in repr(module)
    out = module(torch.empty(2, 1, 33, 47, device="meta"))
    assert out.shape == (2, 1, 33, 47) and out.device.type == "meta" and out.dtype == torch.float32
    with pytest.raises(InputError, match=r"colour is not supported on the meta device"):
        module(torch.empty(1, 3, 33, 47, device="meta"))


def test_the_functional_form_checks_an_image_once(monkeypatch):
    calls = []
    check = alcn_nn._check_image
    monkeypatch.setattr(alcn_nn, "_check_image", lambda image: (calls.append(image), check(image))[1])
    x = torch.rand(1, 1, 32, 32)
    with torch.no_grad():
        alcn2d(x, model="lite")  # the module built, or reused
        alcn2d(x, model="lite")  # reused
    assert len(calls) == 2


_OPENMP = "parallel backend: OpenMP" in torch.__config__.parallel_info()


def _run_threads(*targets: Callable[[], None], timeout: float = 20) -> None:
    """Run ``targets`` in threads of their own; none may still run after ``timeout`` seconds (a hang fails)."""
    threads = [threading.Thread(target=t, daemon=True) for t in targets]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout)
    assert not any(t.is_alive() for t in threads), "a torch_threads block waited for another thread's"


def _fresh_count() -> int:
    """The count a new thread starts with: torch's last set in the process (OpenMP), not this thread's own."""
    seen = []
    _run_threads(lambda: seen.append(torch.get_num_threads()))
    return seen[0]


def test_torch_threads_of_two_python_threads_do_not_mix():
    """Overlapping blocks of different counts in two threads run together, each with its own count (OpenMP: a
    thread's count is its own), and the count of before the first is left when the last ends (interleaved, the second
    block restored the first's count after the first had restored it); nested in one thread, the inner count, then
    the outer."""
    seen: dict[str, int] = {}
    before = _fresh_count()
    mine, other = before + 1, before + 2
    opened, second_open = threading.Event(), threading.Event()

    def first() -> None:
        with alcn_nn.torch_threads(mine):
            opened.set()
            assert second_open.wait(10)  # the second block opened while this one is: it did not wait
            seen["first"] = torch.get_num_threads()

    def second() -> None:
        assert opened.wait(10)
        with alcn_nn.torch_threads(other):
            second_open.set()
            seen["second"] = torch.get_num_threads()
            time.sleep(0.3)  # ends after the first block

    _run_threads(first, second)
    assert seen["second"] == other and (seen["first"] == mine or not _OPENMP)
    assert _fresh_count() == before and alcn_nn._SCOPES.open == 0

    def together(name: str, barrier: threading.Barrier) -> None:
        with alcn_nn.torch_threads(mine):
            barrier.wait(10)
            with alcn_nn.torch_threads(mine):
                seen[name] = torch.get_num_threads()

    barrier = threading.Barrier(2)
    _run_threads(lambda: together("a", barrier), lambda: together("b", barrier))
    assert seen["a"] == seen["b"] == mine and not barrier.broken
    main = torch.get_num_threads()
    with alcn_nn.torch_threads(mine):
        with alcn_nn.torch_threads(other):
            seen["inner"] = torch.get_num_threads()
        seen["outer"] = torch.get_num_threads()
    assert (seen["inner"], seen["outer"], torch.get_num_threads()) == (other, mine, main)


def test_torch_threads_nested_in_two_threads_do_not_wait():
    """Two threads each inside a block of 2, each opening a nested block of 1 while the other's is open (two runs in
    a thread pool, each calling apply() with threads=1), waited for each other forever."""
    before = _fresh_count()
    inside, nested = threading.Barrier(2), threading.Barrier(2)
    seen: dict[str, tuple[int, int]] = {}

    def run(name: str) -> None:
        with alcn_nn.torch_threads(2):
            inside.wait(10)  # both outer blocks open
            with alcn_nn.torch_threads(1):
                nested.wait(10)  # both nested blocks open
                inner = torch.get_num_threads()
            seen[name] = (inner, torch.get_num_threads())

    _run_threads(lambda: run("a"), lambda: run("b"))
    assert not inside.broken and not nested.broken
    assert seen["a"][0] == seen["b"][0] == 1
    if _OPENMP:
        assert seen["a"][1] == seen["b"][1] == 2
    assert _fresh_count() == before and alcn_nn._SCOPES.open == 0


def test_torch_threads_never_waits_for_a_long_block_of_another_count():
    """A whole training run holds a block: another thread's apply() (threads=1) waited for it to end (hours)."""
    before = _fresh_count()
    held, release = threading.Event(), threading.Event()
    frame = synthetic_frame(96, 72, False)
    alcn = alcn_cv.createALCN(backend="fast", threads=1)
    out = []

    def training() -> None:
        with alcn_nn.torch_threads(before + 1):
            held.set()
            release.wait(60)

    holder = threading.Thread(target=training, daemon=True)
    holder.start()
    try:
        assert held.wait(10)
        _run_threads(lambda: out.append(alcn.apply(frame)), lambda: out.append(alcn.apply(frame)))
        assert holder.is_alive() and len(out) == 2
        np.testing.assert_array_equal(out[0], out[1])
    finally:
        release.set()
        holder.join(20)
    assert not holder.is_alive() and _fresh_count() == before and alcn_nn._SCOPES.open == 0


@pytest.mark.parametrize("bad", [0, -1, 2.5, True, "2"])
def test_a_bad_thread_count_is_an_input_error_and_leaves_nothing_behind(bad):
    """torch refused the count after the block was registered: the stale block made every other thread's block of
    another count wait forever. Now the count is checked first; a count torch refuses all the same is not counted."""
    before = _fresh_count()
    with pytest.raises(InputError, match=r"whole number >= 1 or None, got"), alcn_nn.torch_threads(bad):
        pass
    with alcn_nn.torch_threads(None):  # None: no change, nothing checked
        pass
    assert alcn_nn._SCOPES.open == 0
    seen = []
    _run_threads(lambda: seen.append(_in_block(before + 1)), lambda: seen.append(_in_block(before + 2)))
    assert sorted(seen) == [before + 1, before + 2] and _fresh_count() == before and alcn_nn._SCOPES.open == 0


def test_a_count_torch_refuses_is_not_counted(monkeypatch):
    before = _fresh_count()

    def refuse(threads: int) -> None:
        raise RuntimeError("refused")

    monkeypatch.setattr(torch, "set_num_threads", refuse)
    with pytest.raises(RuntimeError, match="refused"), alcn_nn.torch_threads(before + 1):
        pass
    monkeypatch.undo()
    assert alcn_nn._SCOPES.open == 0
    seen = []
    _run_threads(lambda: seen.append(_in_block(before + 2)))
    assert seen == [before + 2] and _fresh_count() == before and alcn_nn._SCOPES.open == 0


def _in_block(threads: int) -> int:
    with alcn_nn.torch_threads(threads):
        return torch.get_num_threads()


@pytest.mark.skipif(not hasattr(os, "fork"), reason="no fork on this platform")
def test_a_forked_child_keeps_only_its_own_thread_blocks():
    """Forked while another thread holds a block: the child (the forking thread only) counts its own blocks, runs
    its blocks on one thread, and does not wait for the lock the other thread may have held."""
    held, release = threading.Event(), threading.Event()

    def other() -> None:
        with alcn_nn.torch_threads(3):
            held.set()
            release.wait(30)

    holder = threading.Thread(target=other, daemon=True)
    holder.start()
    try:
        assert held.wait(10)
        with alcn_nn.torch_threads(2):
            pid = os.fork()
            if pid == 0:  # the child: no pytest from here, only an exit status
                ok = False
                try:
                    with alcn_nn.torch_threads(4):
                        ok = torch.get_num_threads() == 1 and alcn_nn._SCOPES.open == 2
                    ok = ok and alcn_nn._SCOPES.open == 1
                finally:
                    os._exit(0 if ok else 1)
            _, status = os.waitpid(pid, 0)
    finally:
        release.set()
        holder.join(20)
    assert os.waitstatus_to_exitcode(status) == 0 and alcn_nn._SCOPES.open == 0


@pytest.mark.parametrize("grad", [False, True])  # apply()'s passes with the module's weights; torch's filters
@pytest.mark.parametrize("channels", [1, 3])
@pytest.mark.parametrize(
    ("dtype", "mean", "largest"),  # measured 9e-5 / 5e-4 and 8e-4 / 5e-3 (on a photograph, 7e-4 and 6e-3 at most)
    [(torch.float16, 2e-4, 1e-3), (torch.bfloat16, 2e-3, 1e-2)],
)
def test_lower_precision_dtypes_run_and_stay_close(dtype, mean, largest, channels, grad):
    """Against the float32 module on the same image (the image's own rounding to float16 is not the module's).
    float16 was 6e-3 off (4e-2 on a photograph): the log of a cell's deviation, from the difference of two nearly
    equal moments, 1.3 off; Eq. 3's difference of two blurs, and its kernels rounded with the module. On the CPU
    with the gain model (torch's CPU float16 convolutions of the lite one's strided layers take minutes); float16
    against float32 on CUDA is checked below."""
    image = _gray() if channels == 1 else _bgr()[..., ::-1].copy()
    x = torch.from_numpy(_unit(image)).reshape(1, *image.shape[:2], channels).permute(0, 3, 1, 2).to(dtype)
    module = ALCN2d(model="gain").eval().requires_grad_(False)
    with torch.set_grad_enabled(grad):
        reference = module(x.float().requires_grad_(grad))
        out = module.to(dtype)(x.requires_grad_(grad))
    assert out.dtype == dtype and torch.isfinite(out).all()
    error = (out.float() - reference).abs()
    assert error.mean() < mean and error.max() < largest, (error.mean(), error.max())


def test_a_float16_network_keeps_its_dtype():
    """The network alone, cast to float16, on a float16 image: its features and head run in float32, its response
    and output are float16 (a float32 response reached its float16 kernels and failed)."""
    net = GainNormalizer().half()
    x = torch.from_numpy(_unit(_gray()))[None, None].half()
    assert net.dense(x).dtype == torch.float32 and net(x).dtype == torch.float16


@pytest.mark.parametrize("channels", [1, 3])
def test_float16_on_flat_and_dark_images(channels):
    """In float16 a flat or black image gave NaN (gray) or an IndexError from the Lab spline's NaN index (colour):
    float16 holds neither the divisive floor's 1e-8 nor a flat region's energy, and their inverse square root was
    infinite. The divisive step runs in float32 for a float16 image."""
    module = ALCN2d(model="gain").half().eval().requires_grad_(False)
    reference = ALCN2d(model="gain").eval().requires_grad_(False)
    for value in (0.0, 0.3, 1.0):
        x = torch.full((1, channels, 32, 40), value)
        out = module(x.half())
        assert out.dtype == torch.float16 and torch.isfinite(out).all(), value
        assert (out.float() - reference(x)).abs().max() < 1e-2, value


def test_float16_gradients_are_finite():
    """``.half()`` modules and float16 autocast gave non-finite gradients everywhere (the inverse square root's
    derivative, ``x^-1.5 / 2``, overflows float16 for a flat region's energy): no step of a mixed-precision
    fine-tuning could be taken."""
    image = _unit(_gray(64, 80))
    image[:16] = 0  # flat cells
    half = ALCN2d(model="gain").half()
    x = torch.from_numpy(image)[None, None].half().requires_grad_(True)
    half(x).float().square().mean().backward()
    assert torch.isfinite(x.grad).all() and all(torch.isfinite(p.grad).all() for p in half.parameters())
    module = ALCN2d(model="gain")
    with torch.autocast("cpu", dtype=torch.float16):
        out = module(torch.from_numpy(image)[None, None])
    out.float().square().mean().backward()
    assert all(torch.isfinite(p.grad).all() for p in module.parameters())


@pytest.mark.parametrize("model", ["gain", "lite"])
def test_differentiable_frozen_or_fine_tuned(model):
    image = _unit(_gray(64, 80))
    image[:16] = 0  # a black border: flat cells, where a square root's gradient would be infinite
    x = torch.from_numpy(image)[None, None].requires_grad_(True)
    frozen = ALCN2d(model=model).eval().requires_grad_(False)
    frozen(x).square().mean().backward()
    assert x.grad is not None and torch.isfinite(x.grad).all() and x.grad.abs().sum() > 0
    tuned = ALCN2d(model=model)
    tuned(x.detach()).square().mean().backward()
    grads = [p.grad for p in tuned.parameters() if p.requires_grad]
    assert grads and all(g is not None and torch.isfinite(g).all() for g in grads)
    assert sum(float(g.abs().sum()) for g in grads) > 0


def test_colour_gradient_on_the_cpu_is_the_torch_conversions():
    """On the CPU the Lab values are OpenCV's and their gradient the torch conversion's, which the other devices run."""
    rgb = torch.from_numpy(_unit(_bgr(48, 64)[..., ::-1].copy())).permute(2, 0, 1)[None]
    module = ALCN2d(model="gain").eval().requires_grad_(False)
    eager = rgb.clone().requires_grad_(True)
    module(eager).square().mean().backward()
    compiled = rgb.clone().requires_grad_(True)
    torch.compile(module, backend="eager", fullgraph=True)(compiled).square().mean().backward()
    assert eager.grad.abs().sum() > 0
    torch.testing.assert_close(eager.grad, compiled.grad, atol=1e-6, rtol=1e-3)


def test_colour_under_torch_func_transforms():
    """torch.func.grad and vmap see the OpenCV Lab passes as one differentiable, batchable operation."""
    rgb = torch.from_numpy(_unit(_bgr(32, 40)[..., ::-1].copy())).permute(2, 0, 1)[None]
    module = ALCN2d(model="gain").eval().requires_grad_(False)
    x = rgb.clone().requires_grad_(True)
    module(x).square().mean().backward()
    torch.testing.assert_close(torch.func.grad(lambda t: module(t).square().mean())(rgb), x.grad)
    pair = torch.cat([rgb, rgb.flip(-1)])
    torch.testing.assert_close(torch.func.vmap(lambda t: module(t[None])[0])(pair), module(pair))


@pytest.mark.parametrize("model", ["gain", "lite"])
def test_vmap_in_inference(model):
    """torch.func.vmap of a frozen module under no_grad (a batched evaluation): the CPU inference kernels read their
    tensors' values, which a vmapped tensor has not ("Cannot access data pointer"); they are left to torch there."""
    module = ALCN2d(model=model).eval()
    for channels in (1, 3):
        images = torch.rand(3, 2, channels, 48, 64)
        with torch.no_grad():
            out = torch.func.vmap(module)(images)
            torch.testing.assert_close(out, torch.stack([module(x) for x in images]), atol=1e-5, rtol=0)


def test_vmap_without_torchs_private_functorch_check(monkeypatch):
    """_check_range asked torch's private is_functorch_wrapped_tensor; a torch without it broke every call. Without
    it a vmapped image (whose values cannot be read) goes unchecked, and a plain one is checked as before."""
    monkeypatch.setattr(cpu_inference, "_IS_WRAPPED", None)
    module = ALCN2d(model="gain").eval().requires_grad_(False)
    pair = torch.rand(2, 1, 32, 40)
    torch.testing.assert_close(torch.func.vmap(lambda t: module(t[None])[0])(pair), module(pair))
    with torch.no_grad():  # the CPU inference kernels, which read their tensors, left to torch
        torch.testing.assert_close(torch.func.vmap(module)(pair[:, None]), module(pair)[:, None], atol=1e-5, rtol=0)
    with pytest.raises(InputError, match=r"0\.\.255 intensities"):
        module(pair * 255)


def test_the_functional_forms_module_is_frozen_and_fixed_scales_stay_fixed():
    """alcn2d's cached module gathers no gradient from the caller's backward; requires_grad_(True) on ALCN2d makes
    its network trainable, not the divisive step's fixed tau and floor (buffers)."""
    x = torch.rand(1, 1, 64, 64)
    out = alcn2d(x, model="gain-lite")
    assert not out.requires_grad
    module = ALCN2d(model="gain").requires_grad_(False).requires_grad_(True)
    names = [name for name, _ in module.named_parameters()]
    assert names and not [name for name in names if "log_" in name]
    assert {"net.log_tau", "net.log_floor_scale"} <= set(module.state_dict())


def test_a_callers_autocast_stays_on():
    """Under the caller's bfloat16 autocast, a bfloat16 image runs (the float16 autocast of half=True is not
    opened otherwise, which would switch the caller's off inside)."""
    module = ALCN2d(model="gain").eval()
    x = torch.from_numpy(_unit(_gray(64, 80)))[None, None]
    with torch.no_grad():
        reference = module(x)
        with torch.autocast("cpu", dtype=torch.bfloat16):
            out = module(x.bfloat16())
    assert torch.isfinite(out).all() and (out.float() - reference).abs().mean() < 1e-2


def test_a_callers_autocast_leaves_the_colour_conversions_in_the_images_dtype():
    """Under the caller's bfloat16 autocast the Lab conversions run in float32 for a float32 image (a bfloat16 einsum
    moves L by 1.6 of 100); the network takes autocast's precision (the filters' operations, on the CPU, autocast
    leaves in float32)."""
    rgb = torch.from_numpy(_unit(_bgr(48, 64)[..., ::-1].copy())).permute(2, 0, 1)[None]
    module = ALCN2d(model="gain").eval()
    to_lab, from_lab = RgbToLab(), LabToRgb()
    layers = []  # (autocast on, the output's dtype) of each layer of the network that ran under the caller's autocast

    def record(layer, inputs, output):
        layers.append((torch.is_autocast_enabled("cpu"), output.dtype))

    with torch.no_grad():
        lab, reference = to_lab(rgb), module(rgb)
        hooks = [layer.register_forward_hook(record) for layer in module.net.modules()]
        with torch.autocast("cpu", dtype=torch.bfloat16):
            autocast_lab, autocast_rgb, out = to_lab(rgb), from_lab(lab), module(rgb)
        for hook in hooks:
            hook.remove()
    assert autocast_lab.dtype == autocast_rgb.dtype == torch.float32
    torch.testing.assert_close(autocast_lab, lab, atol=0, rtol=0)
    torch.testing.assert_close(autocast_rgb, from_lab(lab), atol=0, rtol=0)
    # the network ran in autocast's bfloat16, not in float32 with the caller's autocast switched off inside
    assert layers and all(layer == (True, torch.bfloat16) for layer in layers), layers
    assert 1e-4 < (out - reference).abs().max() < 2e-2


@pytest.mark.parametrize("device", ["cpu", pytest.param("cuda", marks=CUDA)])
@pytest.mark.parametrize("grad", [False, True])
@pytest.mark.parametrize(("autocast", "largest"), [(torch.bfloat16, 3e-3), (torch.float16, 5e-4)])
def test_a_callers_autocast_leaves_the_filters_in_float32(autocast, largest, grad, device):
    """Under a caller's autocast with a gradient recorded, Eq. 3's and the divisive step's blurs (convolutions there)
    ran in autocast's dtype, 5e-2 off in bfloat16 where the same call without a gradient was 9e-4 off, and the output
    was bfloat16 or float32 by whether a gradient was recorded. Only the network's convolutions take autocast's
    precision; the output is the image's dtype (on CUDA, against the CPU's float32 output)."""
    reference_module, module = ALCN2d(model="gain"), ALCN2d(model="gain").to(device)
    for channels in (1, 3):
        image = _gray() if channels == 1 else _bgr()[..., ::-1].copy()
        x = torch.from_numpy(_unit(image)).reshape(1, *image.shape[:2], channels).permute(0, 3, 1, 2)
        with torch.no_grad():
            reference = reference_module(x)
        with torch.autocast(device, dtype=autocast), torch.set_grad_enabled(grad):
            out = module(x.to(device).requires_grad_(grad))
        assert out.dtype == torch.float32 and out.requires_grad == grad
        assert 0 < (out.detach().cpu() - reference).abs().max() < largest, channels


@pytest.mark.parametrize(("dtype", "autocast"), [(torch.float16, torch.bfloat16), (torch.bfloat16, torch.float16)])
def test_a_half_image_under_the_other_halfs_autocast(dtype, autocast):
    """A float16 image under bfloat16 autocast (or the converse), colour with a gradient, ended in torch's "Unexpected
    floating ScalarType in at::autocast::prioritize" (two half dtypes in one operation); it runs in float32 as
    outside autocast, the output in the image's dtype."""
    module = ALCN2d(model="gain")
    rgb = torch.from_numpy(_unit(_bgr()[..., ::-1].copy())).permute(2, 0, 1)[None]
    reference = module(rgb).detach()
    with torch.autocast("cpu", dtype=autocast):
        out = module(rgb.to(dtype).requires_grad_(True))
    out.float().sum().backward()
    assert out.dtype == dtype and (out.detach().float() - reference).abs().max() < 2e-2


@pytest.mark.parametrize("dtype", [torch.float16, torch.bfloat16, torch.float64])
def test_a_cast_keeps_the_constants_exact(dtype):
    """``.half()`` rounded the mixture's kernels, the Lab conversions' constants and the fixed tau and floor (bfloat16:
    tau 3 became 3.016), and a cast back to float32 kept them rounded: 1e-3 off on a photograph. They follow the
    module's device, not its dtype (float64 kernels are made from the sigmas where an image needs them)."""
    fresh = dict(ALCN2d(model="gain").named_buffers())
    assert {"mixture.bank", "to_lab.matrix", "from_lab.spline", "net.log_tau", "net.log_floor_scale"} <= set(fresh)
    for module, parameters in ((ALCN2d(model="gain").to(dtype), dtype), (ALCN2d().to(dtype).float(), torch.float32)):
        assert {p.dtype for p in module.parameters()} == {parameters}
        buffers = dict(module.named_buffers())
        assert buffers.keys() == fresh.keys()
        for name, value in fresh.items():
            torch.testing.assert_close(buffers[name], value, atol=0, rtol=0, msg=name)
    assert ALCN2d(model="gain").to("meta").net.log_tau.is_meta


@pytest.mark.parametrize("model", ["lite", "paper"])
def test_torch_jit_trace_records_the_working_scale(model):
    """The lite and paper models resize to their working scale from the image's sizes, which a trace gives as
    tensors; the traced module equals the module on the traced size."""
    x = torch.rand(2, 1, 64, 80)
    module = ALCN2d(model=model).eval()
    with torch.no_grad(), warnings.catch_warnings():
        warnings.simplefilter("ignore", torch.jit.TracerWarning)
        traced = torch.jit.trace(module, x)
        torch.testing.assert_close(traced(x), module(x), atol=1e-5, rtol=0)


@pytest.mark.parametrize("channels", [1, 3])
def test_torch_jit_trace_of_a_trainable_module(channels):
    """Traced with gradients on and the network trainable: torch.jit.trace's check traces again under no_grad,
    where the filters take in-place paths ("Graphs differed across invocations"); the traced module trains."""
    x = torch.rand(1, channels, 24, 32)
    module = ALCN2d(model="gain").eval()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", torch.jit.TracerWarning)
        traced = torch.jit.trace(module, x)
    out = traced(x)
    torch.testing.assert_close(out, module(x), atol=1e-5, rtol=0)
    out.square().mean().backward()
    assert all(p.grad is not None and torch.isfinite(p.grad).all() for p in module.parameters())


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("shape", [(120, 160), (121, 163)])
def test_a_users_onnx_export_gives_the_modules_output(model, shape, tmp_path):
    """torch.onnx.export of the module (the docstring lists it), run by ONNX's reference evaluator: the lite and paper
    models' grid was one point short in the graph, 0.02-0.05 off without an error, and the gain models' wide band
    failed on some sides that are not a multiple of 8 (121, 125 or 161 px: ceilings written with a negative floor
    division, which ONNX's integer Div truncates)."""
    import onnx
    from onnx.reference import ReferenceEvaluator

    module = ALCN2d(model=model).eval().requires_grad_(False)
    x = torch.rand(1, 1, *shape)
    path = tmp_path / "alcn.onnx"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the tracer's notes on Python values
        torch.onnx.export(module, (x,), path, dynamo=False, opset_version=17)
    graph = onnx.load(path).graph
    exported = ReferenceEvaluator(str(path)).run(None, {graph.input[0].name: x.numpy()})[0]
    np.testing.assert_allclose(exported, module(x).numpy(), atol=1e-5, rtol=0)


@pytest.mark.skipif(
    not any(shutil.which(c) for c in ("c++", "g++", "clang++")), reason="inductor on the CPU needs a C++ compiler"
)
def test_inductor_compiles_the_borders_of_a_small_image():
    """A side shorter than its pad mirrored (reflect101_pad), then the wide band's edges held (upsample_blocks):
    inductor fails on an index_select of computed indices and on F.pad's replicate mode after a concatenation (torch
    2.13), which the module meets on training crops. The graph kept small: on the CPU inductor compiles the whole
    module for minutes."""

    def borders(x: torch.Tensor) -> torch.Tensor:
        return upsample_blocks(torch.tanh(reflect101_pad(x, 9, 9, 9, 9)), 4, (90, 90))

    x = torch.rand(1, 1, 6, 5)
    torch.testing.assert_close(torch.compile(borders)(x), borders(x), atol=1e-6, rtol=0)


@pytest.mark.parametrize("model", ["gain", "lite"])
@pytest.mark.parametrize("channels", [1, 3])
def test_traces_as_one_graph_for_torch_compile(model, channels):
    """Dynamo captures the whole module (``fullgraph=True``), colour conversions included; the inductor backend on
    the CPU compiles for minutes on a loaded machine, so the compiled kernels are checked by the GPU script, not here.
    Traced, the module takes torch's kernels where the CPU inference takes NumPy's tanh and OpenCV's Lab (float
    rounding apart, which a random image has no flat region to amplify: 6.6e-6 at most over 40 images of colour for
    `lite`; seeded, as an unseeded image failed once in a full run)."""
    x = torch.rand(2, channels, 64, 80, generator=torch.Generator().manual_seed(0))
    module = ALCN2d(model=model).eval()
    with torch.no_grad():
        torch.testing.assert_close(
            torch.compile(module, backend="eager", fullgraph=True)(x), module(x), atol=1e-5, rtol=0
        )


def test_the_functional_form_traces_as_one_graph():
    """alcn2d read its weight file's version on each call, which Dynamo cannot trace: torch.compile(fullgraph=True)
    of a step that called it failed ("Attempted to call function marked as skipped")."""
    x = torch.rand(1, 1, 48, 64)
    with torch.no_grad():
        expected = alcn2d(x, model="lite")
        compiled = torch.compile(lambda image: alcn2d(image, model="lite"), backend="eager", fullgraph=True)
        torch.testing.assert_close(compiled(x), expected, atol=1e-5, rtol=0)


def test_apply_batch_uploads_integers_and_casts_on_the_device(cpu_route):
    frames = np.stack([_gray(seed=i) for i in range(3)])
    alcn = alcn_cv.createALCN(backend="torch")
    for out_dtype in (np.uint8, np.uint16, np.float32):
        batch = alcn.apply_batch(frames, out_dtype=out_dtype)
        assert batch.dtype == out_dtype and batch.shape == frames.shape
        expected = np.stack([alcn.apply(f, out_dtype=out_dtype) for f in frames])
        np.testing.assert_allclose(
            batch.astype(np.float64), expected.astype(np.float64), atol=1 if out_dtype != np.float32 else 1e-5
        )
    sixteen = frames.astype(np.uint16) * 257
    np.testing.assert_allclose(
        alcn.apply_batch(sixteen, out_dtype=np.float32), alcn.apply_batch(frames, out_dtype=np.float32), atol=1e-5
    )


@pytest.mark.parametrize("colour", [False, True])
def test_apply_batch_passes_each_frames_own_alpha_through(colour):
    """The alpha channel, the frames' last, comes back unchanged and equal to apply()'s, gray + alpha and BGRA. An
    alpha that copies a colour channel (as a folder's RGBA test image did) cannot tell the last channel from the
    first: here it is a pattern of its own."""
    rng = np.random.default_rng(4)
    body = np.stack([_bgr(seed=i) if colour else _gray(seed=i) for i in range(2)])
    alpha = rng.integers(0, 256, body.shape[:3], dtype=np.uint8)
    frames = np.concatenate([body.reshape(*body.shape[:3], -1), alpha[..., None]], axis=3)
    alcn = alcn_cv.createALCN(backend="torch")
    out = alcn.apply_batch(frames)
    assert out.shape == frames.shape and out.dtype == np.uint8
    np.testing.assert_array_equal(out[..., -1], alpha)
    for frame, batched in zip(frames, out):
        assert np.abs(batched.astype(int) - alcn.apply(frame).astype(int)).max() <= 1


def test_batches_group_a_stream():
    frames = [np.full((4, 5), i, np.uint8) for i in range(7)]
    groups = list(batches(iter(frames), 3))
    assert [g.shape for g in groups] == [(3, 4, 5), (3, 4, 5), (1, 4, 5)] and groups[2][0, 0, 0] == 6
    with pytest.raises(InputError):
        next(batches(frames, 0))


@CUDA
@pytest.mark.parametrize("model", ["gain", "lite"])
def test_cuda_equals_the_cpu_and_float16_stays_close(model):
    x = torch.from_numpy(_unit(synthetic_frame(640, 400, False)))[None, None]
    cpu = ALCN2d(model=model).eval()
    cuda = ALCN2d(model=model).eval().cuda()
    with torch.no_grad():
        reference = cpu(x)
        out = cuda(x.cuda())
        assert (out.cpu() - reference).abs().max() < 1e-4
        reference = cpu(x.half().float())  # the float32 output of the image float16 holds
        half = cuda.half()(x.cuda().half())
        # the documented float16 error (the convolutions of the network; on the CPU 5e-4 and 1.6e-3 at most, 1e-4
        # and 7e-4 on average)
        error = (half.float().cpu() - reference).abs()
        assert half.dtype == torch.float16 and error.max() < (1e-3 if model == "gain" else 2e-3)
        assert error.mean() < 1e-3


@CUDA
def test_cuda_colour_equals_the_cpu():
    """The CIE Lab conversions' buffers move with the module; the colour output is the CPU's to float rounding."""
    rgb = torch.from_numpy(_unit(_bgr()[..., ::-1].copy())).permute(2, 0, 1)[None]
    with torch.no_grad():
        reference = ALCN2d().eval()(rgb)
        out = ALCN2d().eval().cuda()(rgb.cuda()).cpu()
    assert (out - reference).abs().max() < 1e-3


@CUDA
def test_cuda_compiles_with_inductor():
    x = torch.rand(4, 1, 400, 640, device="cuda")
    module = ALCN2d().eval().cuda()
    # the TF32 switch is the caller's under torch.compile (dynamo cannot trace cudnn.flags): set as the module sets it
    with torch.no_grad(), torch.backends.cudnn.flags(enabled=True, allow_tf32=False):
        torch.testing.assert_close(torch.compile(module, fullgraph=True)(x), module(x), atol=1e-4, rtol=0)


@CUDA
def test_cuda_apply_batch_equals_the_cpu():
    frames = np.stack([synthetic_frame(640, 400, False, seed=i) for i in range(8)])
    cpu = alcn_cv.createALCN(backend="torch").apply_batch(frames)
    cuda = alcn_cv.createALCN(backend="torch", device="cuda").apply_batch(frames)
    assert cuda.dtype == np.uint8 and np.abs(cuda.astype(int) - cpu.astype(int)).max() <= 1


def test_apply_batch_takes_any_byte_order_and_names_a_bad_out_dtype():
    """As apply(): big-endian frames were refused as an "unsupported out_dtype >u2" nobody gave, and their float
    range went unchecked; an unknown out_dtype raised numpy's TypeError."""
    frames = np.stack([_gray(seed=i) for i in range(2)]).astype(np.uint16) * 257
    alcn = alcn_cv.createALCN(backend="torch")
    expected = alcn.apply_batch(frames)
    swapped = alcn.apply_batch(frames.astype(">u2"))
    assert swapped.dtype == np.uint16 and swapped.dtype.isnative
    np.testing.assert_array_equal(swapped, expected)
    unit = frames.astype(np.float32) / np.float32(65535)
    np.testing.assert_array_equal(alcn.apply_batch(unit.astype(">f4")), alcn.apply_batch(unit))
    unit[1, 0, 0] = 2.0  # the second frame's: the first frame is checked alone
    with pytest.raises(InputError, match=r"in \[0, 1\]"):
        alcn.apply_batch(unit.astype(">f4"))
    with pytest.raises(InputError, match="unknown out_dtype"):
        alcn.apply_batch(frames, out_dtype="nonsense")


def test_a_fine_tuned_module_saved_is_what_an_opencv_app_loads(tmp_path):
    """A PyTorch user found no way from a fine-tuned ALCN2d to createALCN(weights=...): torch.save of its state_dict
    is no weight file."""
    alcn = ALCN2d()
    with torch.no_grad():
        next(p for p in alcn.parameters() if p.ndim == 4).mul_(1.5)  # a step of fine-tuning
    path = alcn.save(tmp_path / "tuned.npz")
    meta = load_normalizer_file(path).meta
    assert meta["fine_tuned_from"]["file"] == str(MODELS["gain"]) and "fine-tuned from" in meta["description"]
    gray = _gray()
    with torch.no_grad():
        expected = alcn(torch.from_numpy(_unit(gray))[None, None])[0, 0].numpy()
    out = alcn_cv.createALCN(weights=path).apply(gray, out_dtype=np.float32)
    np.testing.assert_allclose(out, expected, atol=1e-5)
    assert not np.allclose(out, alcn_cv.createALCN().apply(gray, out_dtype=np.float32), atol=1e-3)  # tuned, not shipped
    torch.save(alcn.state_dict(), tmp_path / "state.pt")
    with pytest.raises(alcn_cv.WeightFileError, match=r"no header; a torch state_dict .* ALCN2d.save\(path\)"):
        alcn_cv.createALCN(weights=tmp_path / "state.pt")
    with pytest.raises(InputError, match="got OrderedDict .*load_state_dict") as info:
        ALCN2d(weights=alcn.state_dict())
    assert len(str(info.value)) < 400  # not every tensor of it


@pytest.mark.parametrize("dtype", [torch.float16, torch.bfloat16])
def test_a_module_in_lower_precision_saves(dtype, tmp_path):
    """save() of a float16 module said the fixed tau had changed (the cast had rounded it), and of a bfloat16 one
    ended in NumPy's TypeError (it has no bfloat16). The parameters are saved as they are, in float32; the fixed
    scales as the file had them; a fixed scale changed by more than the rounding is still refused."""
    module = ALCN2d(model="gain").to(dtype)
    saved = load_normalizer_file(module.save(tmp_path / "half.npz")).arrays
    original = load_normalizer_file(MODELS["gain"]).arrays
    assert saved["log_tau"] == original["log_tau"] and saved["log_floor_scale"] == original["log_floor_scale"]
    for name, value in module.net.state_dict().items():
        if name not in ("log_tau", "log_floor_scale"):
            np.testing.assert_array_equal(saved[name], value.float().numpy())
    with torch.no_grad():
        module.net.log_tau.add_(0.1)
    with pytest.raises(alcn_cv.WeightFileError, match="header field 'equalization.tau' is 3.0"):
        module.save(tmp_path / "changed.npz")


def test_a_colour_output_is_contiguous():
    """Its channels were strided after the Lab conversion back: out.view(B, -1) failed."""
    with torch.no_grad():
        for image in (torch.rand(2, 3, 32, 40), torch.rand(2, 3, 32, 40).to(memory_format=torch.channels_last)):
            assert ALCN2d(model="gain-lite")(image).is_contiguous()


def test_a_channels_last_module_runs_in_cpu_inference():
    """The lite model's layers of a module moved to channels-last gave strided outputs, which the OpenCV tanh of CPU
    inference refused (ValueError); a transposed response to the equalization likewise."""
    image = torch.rand(2, 1, 64, 80)
    with torch.no_grad():
        for model in ("lite", "gain"):
            expected = ALCN2d(model=model).eval()(image)
            module = ALCN2d(model=model).eval().to(memory_format=torch.channels_last)
            torch.testing.assert_close(module(image), expected, atol=1e-5, rtol=0)
        response = torch.randn(2, 1, 30, 20)
        torch.testing.assert_close(
            contrast_equalization(response.transpose(-1, -2), 0.5), torch.tanh(response / 0.5).transpose(-1, -2)
        )


def test_settings_that_are_not_what_they_say_are_refused():
    """batches(frames, 1.5) never reached a batch of 1.5 and gave one of everything; ALCN2d(allow_tf32="yes") was
    taken; createALCN(device="mps") on a torch without it ended in torch's RuntimeError."""
    with pytest.raises(InputError, match="size must be a positive integer, got 1.5"):
        list(batches([np.zeros((4, 4), np.float32)] * 3, 1.5))
    with pytest.raises(InputError, match="allow_tf32 must be True or False, got 'yes'"):
        ALCN2d(allow_tf32="yes")
    if not torch.backends.mps.is_available():
        with pytest.raises(InputError, match="device is 'mps', but torch cannot use mps devices here"):
            alcn_cv.createALCN(device="mps")


def test_the_functional_form_first_called_in_inference_mode_keeps_autograd(monkeypatch):
    """alcn2d's module built in a first call under torch.inference_mode() (a sanity check, a validation pass) held
    inference tensors: every later call with gradients failed ("Inference tensors cannot be saved for backward")."""
    monkeypatch.setattr(alcn_nn, "_MODULES", {})
    with torch.inference_mode():
        alcn2d(torch.rand(1, 1, 32, 32))
    x = torch.rand(1, 1, 32, 32, requires_grad=True)
    alcn2d(x).sum().backward()
    assert x.grad is not None and torch.isfinite(x.grad).all()


def test_an_onnx_export_of_a_small_image_says_to_export_a_larger_one(tmp_path):
    """torch's own error ("Padding size should be less than the corresponding input dimension") named a 9x11 plane
    the user never gave: the gain network's grid of a 64x80 image."""
    module = ALCN2d().eval().requires_grad_(False)
    with warnings.catch_warnings(), pytest.raises(InputError, match="export with a larger example image"):
        warnings.simplefilter("ignore")
        torch.onnx.export(module, (torch.rand(1, 1, 64, 80),), tmp_path / "small.onnx", dynamo=False)


@pytest.mark.filterwarnings("ignore:`torch.jit.script` is deprecated:DeprecationWarning")
def test_scripting_says_what_to_use_instead():
    with pytest.raises(InputError, match=r"cannot be scripted: use torch.jit.trace .* or torch.compile"):
        torch.jit.script(ALCN2d())


def test_the_repr_names_the_model_or_the_weight_file(tmp_path):
    assert ALCN2d().extra_repr().startswith("model='gain', scale=1.0")
    assert ALCN2d(model="lite").extra_repr().startswith("model='lite', scale=0.5")
    assert ALCN2d(weights=MODELS["gain-lite"]).extra_repr().startswith("model='gain-lite', ")  # a shipped file
    copy = shutil.copy(MODELS["gain-lite"], tmp_path / "mine.npz")
    assert ALCN2d(weights=copy).extra_repr().startswith(f"weights={str(copy)!r}, scale=1.0")
    assert ALCN2d(weights=load_normalizer_file(copy)).extra_repr().startswith(f"weights={str(copy)!r}")


def test_apply_batch_rounds_to_the_nearest_level():
    """An integer output is the float output rounded to the nearest level (as apply()'s), not truncated: half the
    pixels would otherwise lose a grey level."""
    pytest.importorskip("torch")
    rng = np.random.default_rng(0)
    frames = cv2.GaussianBlur((rng.random((60, 80, 3)) * 255).astype(np.uint8), (0, 0), 2).transpose(2, 0, 1).copy()
    alcn = alcn_cv.createALCN(backend="torch")
    unit = alcn.apply_batch(frames, out_dtype=np.float32)
    np.testing.assert_array_equal(alcn.apply_batch(frames), np.rint(unit * 255).astype(np.uint8))
    np.testing.assert_array_equal(
        alcn.apply_batch(frames, out_dtype=np.uint16), np.rint(unit * np.float32(65535)).astype(np.uint16)
    )


def test_the_working_image_is_opencvs_area_resize_for_any_width():
    """ALCN2d's working image at scale 0.5 of a 60 x 81 frame (the width no multiple of 2) is apply()'s
    ``cv2.INTER_AREA`` resize, not an average pooling that drops the last column."""
    torch = pytest.importorskip("torch")
    from alcn_cv.nn import ALCN2d

    module = ALCN2d(model="paper").eval()
    gray = np.random.default_rng(0).random((60, 81), dtype=np.float32)
    with torch.no_grad():
        working = module.working(torch.from_numpy(gray)[None, None])[0, 0].numpy()
    np.testing.assert_allclose(working, module.spec.working_image(gray), atol=1e-5)


def test_apply_batch_clamps_float_frames_as_apply_does():
    """Float frames a rounding above 1 (allowed: 1e-3) are clamped to 1 first."""
    pytest.importorskip("torch")
    rng = np.random.default_rng(0)
    frames = rng.random((2, 48, 64), dtype=np.float32)
    frames[:, :8] = 1.0
    over = frames.copy()
    over[:, :8] = 1.0009
    alcn = alcn_cv.createALCN(backend="torch")
    np.testing.assert_array_equal(alcn.apply_batch(over), alcn.apply_batch(frames))


def test_the_mistakes_of_a_pytorch_user_are_named(tmp_path):
    """ALCN2d("tuned.npz") (createALCN's first argument is the weights, ALCN2d's the model), gray and alpha, frames of
    several clips and alcn_cv.nn.batches of frames of two sizes: each error says what was meant."""
    from alcn_cv.nn import batches

    with pytest.raises(InputError, match=r"unknown model 'tuned.npz'; .* \(a weight file: weights='tuned.npz'\)$"):
        ALCN2d("tuned.npz")
    alcn = ALCN2d()
    with pytest.raises(InputError, match=r"got \(1, 2, 32, 32\) \(gray and alpha: image\[:, :1\]\)$"):
        alcn(torch.rand(1, 2, 32, 32))
    clips = r"got \(2, 4, 3, 32, 32\) \(frames of several clips: image.flatten\(0, 1\)\)$"
    with pytest.raises(InputError, match=clips):
        alcn(torch.rand(2, 4, 3, 32, 32))
    frames = [np.zeros((8, 8), np.uint8), np.zeros((8, 9), np.uint8)]
    with pytest.raises(InputError, match=r"frame 1 is of shape \(8, 9\), the first \(8, 8\): a batch is of one size"):
        list(batches(frames, 4))


def test_a_cuda_device_torch_does_not_see_is_named(monkeypatch):
    """`--device cuda:1` on a one-GPU machine passed the check and failed later in torch ("invalid device ordinal")."""
    from alcn_cv.nets.device import torch_device

    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 1)
    assert torch_device("cuda:0") == torch.device("cuda:0") and torch_device("cuda") == torch.device("cuda")
    with pytest.raises(InputError, match=r"--device is 'cuda:1' but torch sees 1 CUDA device\(s\), from cuda:0"):
        torch_device("cuda:1", "--device")


def test_the_blurs_kernel_is_made_once_per_device_and_dtype():
    """Each torch Gaussian blur copied its kernel from NumPy to the device at every call: on CUDA a copy that waits
    for the queued work, six times a batch."""
    from alcn_cv.filters import torch_divisive

    x = torch.rand(1, 1, 20, 30)
    torch_divisive.gaussian_blur(x, 2.0)
    before = torch_divisive._kernel_on.cache_info()
    blurred = torch_divisive.gaussian_blur(x, 2.0)
    assert torch_divisive._kernel_on.cache_info().hits == before.hits + 1
    with torch.inference_mode():  # made under inference, the cached kernel still serves a backward later
        torch_divisive.gaussian_blur(torch.rand(1, 1, 20, 30, dtype=torch.float64), 3.0)
    y = torch.rand(1, 1, 20, 30, dtype=torch.float64, requires_grad=True)
    torch_divisive.gaussian_blur(y, 3.0).sum().backward()
    assert y.grad is not None and torch.allclose(blurred, torch_divisive.gaussian_blur(x.clone(), 2.0))


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32])
def test_apply_batch_in_chunks_gives_each_frames_own_output(dtype):
    """apply_batch runs a batch in chunks of nn.CUDA_CHUNK frames (the CUDA pipeline's, taken on the CPU too): a
    batch of two chunks and a part gives each frame's output alone, in its place."""
    from alcn_cv import nn as alcn_nn

    frames = np.stack([synthetic_frame(40, 32, False, seed=i) for i in range(2 * alcn_nn.CUDA_CHUNK + 3)])
    frames = frames.astype(dtype) * (257 if dtype == np.uint16 else 1)
    frames = frames / np.float32(255) if dtype == np.float32 else frames
    alcn = alcn_cv.createALCN(backend="torch")
    batch = alcn.apply_batch(frames)
    alone = np.stack([alcn.apply_batch(frame[None])[0] for frame in frames])
    # to float rounding (torch's batched kernels sum in another order): a frame in another's place would be far off
    tolerance = 1e-5 if dtype == np.float32 else 1
    assert batch.dtype == frames.dtype and np.abs(batch.astype(np.float64) - alone).max() <= tolerance


@CUDA
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32])
def test_cuda_apply_batch_in_chunks_equals_the_cpu(dtype):
    """The three-stream pipeline over two chunks and a part (and again, on the streams the first call made) gives the
    CPU's output, each frame in its place."""
    from alcn_cv import nn as alcn_nn

    frames = np.stack([synthetic_frame(96, 64, False, seed=i) for i in range(2 * alcn_nn.CUDA_CHUNK + 3)])
    frames = frames.astype(dtype) * (257 if dtype == np.uint16 else 1)
    frames = frames / np.float32(255) if dtype == np.float32 else frames
    cpu = alcn_cv.createALCN(backend="torch").apply_batch(frames).astype(np.float64)
    cuda = alcn_cv.createALCN(backend="torch", device="cuda")
    for _ in range(2):
        out = cuda.apply_batch(frames)
        assert out.dtype == frames.dtype and np.abs(out - cpu).max() <= (1e-4 if dtype == np.float32 else 1)
