"""The fast ALCN approximations (issue 8): each one's error against the exact Eq. 3 is bounded
on a fixed input. The bounds are the errors measured when the approximation was written, with
a margin of about 1.5x; a change that makes an approximation worse fails here."""

import cv2
import numpy as np
import pytest
import torch

import alcn_cv
from alcn_cv import InputError
from alcn_cv.filters.gaussian_mixture import PYRAMID_MIN_SIGMA, alcn_filter, pyramid_mixture, pyramid_plan
from alcn_cv.nets import Normalizer
from alcn_cv.runtime import MODELS
from alcn_cv.weight_file import load_normalizer_file, save_normalizer_file

FULL_RES_SIGMAS = tuple(float(s) for s in range(1, 11))  # the shipped file's sigmas at working scale 0.5


@pytest.fixture(scope="module")
def image():
    """A fixed 121x163 textured image under uneven light, float32 in [0, 1] (odd, unaligned size)."""
    rng = np.random.default_rng(3)
    h, w = 121, 163
    texture = cv2.resize(rng.random((31, 41), dtype=np.float32), (w, h), interpolation=cv2.INTER_CUBIC)
    texture += 0.3 * rng.random((h, w), dtype=np.float32)
    cv2.rectangle(texture, (30, 20), (90, 70), 1.5, -1)
    light = np.linspace(0.2, 1.0, w, dtype=np.float32)[None, :]
    return np.clip(texture / texture.max() * light, 0, 1).astype(np.float32)


@pytest.fixture(scope="module")
def random_weights(tmp_path_factory):
    """A weight file whose Normalizer has a random head: its maps vary over the image, unlike
    those of an untrained (DoG-initialised) file, whose maps are constant."""
    torch.manual_seed(0)
    net = Normalizer(output_scale=3.0).eval()
    meta = dict(load_normalizer_file(MODELS["paper"]).meta)
    meta.update(config=net.config, trained=False)
    return save_normalizer_file(tmp_path_factory.mktemp("w") / "random.npz", net.state_arrays(), meta)


def _alcn(weights, **params):
    """ALCN with the exact mixture unless asked otherwise (the reference of every approximation)."""
    return alcn_cv.createALCN(weights=weights, **{"mixture": "exact", **params})


def test_pyramid_plan_keeps_every_sigma():
    for level, residual in pyramid_plan(FULL_RES_SIGMAS):
        assert residual >= PYRAMID_MIN_SIGMA or level == 0
    # residual^2 * 4^L plus the variance of L pyrDown + L pyrUp steps gives back sigma^2
    for sigma, (level, residual) in zip(FULL_RES_SIGMAS, pyramid_plan(FULL_RES_SIGMAS)):
        np.testing.assert_allclose(residual**2 * 4**level + 2 * (4**level - 1) / 3, sigma**2)
    assert [lv for lv, _ in pyramid_plan(FULL_RES_SIGMAS)] == [0, 1, 1, 1, 2, 2, 2, 2, 3, 3]
    assert [lv for lv, _ in pyramid_plan(FULL_RES_SIGMAS, min_sigma=1.0)] == [0, 0, 1, 1, 1, 2, 2, 2, 2, 2]
    assert all(lv == 0 for lv, _ in pyramid_plan(FULL_RES_SIGMAS, max_level=0))
    with pytest.raises(InputError):
        pyramid_plan(FULL_RES_SIGMAS, min_sigma=0)


def _pyramid_eq1(image, weights):
    """Eq. 1 on the pyramid: one weight per kernel for the whole image."""
    return pyramid_mixture(image, FULL_RES_SIGMAS, lambda level, ks, shape: [float(weights[k]) for k in ks])


def test_pyramid_keeps_constants():
    flat = np.full((50, 70), 0.4, np.float32)
    weights = np.linspace(-1, 2, 10)
    np.testing.assert_allclose(_pyramid_eq1(flat, weights), 0.4 * weights.sum(), atol=1e-5)


def test_pyramid_eq1_error_bound(image):
    dog = np.array([1, 0, -1, 0, 0, 0, 0, 0, 0, 0], np.float64)
    ones = np.ones(10)
    for weights, max_bound, mean_bound in [(dog, 1.5e-3, 2e-4), (ones, 9.5e-3, 2e-3)]:
        exact = alcn_filter(image, weights, FULL_RES_SIGMAS)
        diff = np.abs(_pyramid_eq1(image, weights) - exact)
        assert diff.max() <= max_bound and diff.mean() <= mean_bound, (diff.max(), diff.mean())


# the gain models' responses are after the division and tanh (in (-1, 1)), so their bounds are larger; these also
# bound the wide band the pyramid path adds (WindowRuntime.normalize), which at another weight is 0.47 off
@pytest.mark.parametrize(
    ("model", "max_bound", "mean_bound"),
    [("lite", 3e-3, 3e-4), ("paper", 7e-3, 4e-4), ("gain", 3.5e-2, 4e-3), ("gain-lite", 3.5e-2, 4e-3)],
)
def test_shipped_pyramid_error_bound(image, model, max_bound, mean_bound):
    """The shipped pyramid path (``pyramid_mixture`` on the maps of the Normalizer's grid) against Eq. 3 exact."""
    exact = _alcn(None, model=model).normalize(image)
    diff = np.abs(_alcn(None, model=model, mixture="pyramid").normalize(image) - exact)
    assert exact.std() > 0.03
    assert diff.max() <= max_bound and diff.mean() <= mean_bound, (diff.max(), diff.mean())


def test_coarse_grid_is_the_fine_grid_subsampled():
    torch.manual_seed(1)
    net = Normalizer(output_scale=3.0).eval()
    image = torch.rand(1, 1, 57, 83)
    with torch.no_grad():
        fine = net.dense_grid(image)
        for stride in (8, 16):
            coarse = net.dense_grid(image, stride)
            step = stride // 4
            sub = fine[..., ::step, ::step]
            assert coarse.shape[-2:] == (-(-56 // stride) + 1, -(-82 // stride) + 1)
            n, m = sub.shape[-2:]
            np.testing.assert_allclose(coarse[..., :n, :m], sub, atol=1e-5)
            on_grid = net.dense(image, stride)[..., ::stride, ::stride]
            n, m = on_grid.shape[-2:]
            np.testing.assert_allclose(on_grid, coarse[..., :n, :m], atol=1e-5)
    with pytest.raises(InputError, match="multiple of 4"):
        net.dense_grid(image, 6)


@pytest.mark.parametrize(
    "params, max_bound, mean_bound",
    [
        ({"mixture": "pyramid"}, 0.03, 1.4e-3),
        ({"grid_stride": 16}, 0.11, 0.022),
        ({"grid_stride": 16, "mixture": "pyramid"}, 0.12, 0.022),
    ],
)
def test_alcn_approximation_error_bound(image, random_weights, params, max_bound, mean_bound):
    exact = _alcn(random_weights).normalize(image)
    approx = _alcn(random_weights, **params).normalize(image)
    diff = np.abs(approx - exact)
    assert exact.std() > 0.03
    assert diff.max() <= max_bound and diff.mean() <= mean_bound, (diff.max(), diff.mean())


def test_constant_maps_lose_nothing_on_a_coarse_grid(image, tmp_path):
    # A Normalizer predicting the same weights everywhere (an untrained, DoG-initialised one):
    # interpolating its maps from any grid is exact.
    net = Normalizer(hidden=16, init_weights=[1.0, 0.0, -1.0] + [0.0] * 7)
    meta = dict(load_normalizer_file(MODELS["paper"]).meta)
    meta.update(config=net.config)
    path = save_normalizer_file(tmp_path / "constant.npz", net.state_arrays(), meta)
    np.testing.assert_allclose(_alcn(path, grid_stride=32).normalize(image), _alcn(path).normalize(image), atol=1e-6)


def test_torch_backend_follows_the_grid_stride(image, random_weights):
    fast = _alcn(random_weights, grid_stride=16).normalize(image)
    torch_cpu = _alcn(random_weights, grid_stride=16, backend="torch").normalize(image)
    np.testing.assert_allclose(fast, torch_cpu, atol=1e-4)


def test_fast_parameters():
    with pytest.raises(InputError, match="grid_stride"):
        alcn_cv.createALCN(grid_stride=6)
    with pytest.raises(InputError, match="grid_stride"):
        alcn_cv.createALCN(grid_stride=0)
    with pytest.raises(InputError, match="mixture"):
        alcn_cv.createALCN(mixture="fft")
    with pytest.raises(InputError, match="pyramid"):
        alcn_cv.createALCN(mixture="pyramid", backend="torch")
    alcn = alcn_cv.createALCN(grid_stride=16, mixture="pyramid")
    assert "grid_stride=16" in repr(alcn) and "pyramid" in repr(alcn)
    out = alcn.apply(np.zeros((30, 40, 3), np.uint8))
    assert out.shape == (30, 40, 3) and out.dtype == np.uint8


# --- The light, distilled Normalizer -------------------------------------------------------


def _lite_file(path, seed=0):
    from alcn_cv.nets.lite import LiteNormalizer

    torch.manual_seed(seed)
    net = LiteNormalizer(output_scale=3.0).eval()
    meta = dict(load_normalizer_file(MODELS["paper"]).meta)
    meta.update(config=net.config, architecture="lite", trained=False)
    return net, save_normalizer_file(path, net.state_arrays(), meta)


def test_lite_dense_equals_windows_at_grid_pixels(tmp_path):
    from alcn_cv.filters.torch_pad import reflect101_pad

    net, _ = _lite_file(tmp_path / "lite.npz")
    assert net.stride == 8
    image = torch.rand(1, 1, 61, 77)
    padded = reflect101_pad(image, 24, 24, 24, 24)
    with torch.no_grad():
        for stride in (8, 16):
            grid = net.dense_grid(image, stride)[0]
            for i, y in enumerate(range(0, 61, stride)):
                for j, x in enumerate(range(0, 77, stride)):
                    np.testing.assert_allclose(grid[:, i, j], net(padded[..., y : y + 48, x : x + 48])[0], atol=1e-5)
        assert net.dense(image).shape == (1, 10, 61, 77)
    with pytest.raises(InputError, match="multiple of 8"):
        net.dense_grid(image, 4)


def test_alcn_runs_a_lite_weight_file(tmp_path, image):
    from alcn_cv.nets.lite import LiteNormalizer

    _, path = _lite_file(tmp_path / "lite.npz")
    alcn = _alcn(path)
    assert isinstance(alcn.net, LiteNormalizer) and alcn.grid_stride == 8
    exact = alcn.normalize(image)
    np.testing.assert_allclose(_alcn(path, backend="torch").normalize(image), exact, atol=1e-4)
    diff = np.abs(_alcn(path, mixture="pyramid").normalize(image) - exact)
    assert diff.max() <= 0.05 and diff.mean() <= 2e-3, (diff.max(), diff.mean())
    with pytest.raises(InputError, match="multiple of 8"):
        _alcn(path, grid_stride=4)


def test_unknown_architecture_is_a_weight_file_error(tmp_path):
    from alcn_cv import WeightFileError

    net, _ = _lite_file(tmp_path / "lite.npz")
    meta = dict(load_normalizer_file(MODELS["paper"]).meta)
    meta.update(config=net.config, architecture="transformer")
    path = save_normalizer_file(tmp_path / "x.npz", net.state_arrays(), meta)
    with pytest.raises(WeightFileError, match="architecture"):
        alcn_cv.createALCN(weights=path)
    meta.update(architecture="lite")
    path = save_normalizer_file(tmp_path / "y.npz", Normalizer().state_arrays(), meta)
    with pytest.raises(WeightFileError, match="do not fit"):
        alcn_cv.createALCN(weights=path)


def test_distill_writes_a_student_closer_than_its_start(tmp_path):
    import hashlib

    from alcn_cv.train import distill
    from alcn_cv.train.config import LiteDistillConfig

    torch.manual_seed(2)
    teacher = Normalizer(hidden=16, output_scale=3.0).eval()
    meta = dict(load_normalizer_file(MODELS["paper"]).meta)
    meta.update(config=teacher.config, trained=True, description="a test teacher")
    teacher_path = save_normalizer_file(tmp_path / "teacher.npz", teacher.state_arrays(), meta)
    cfg = LiteDistillConfig(teacher=str(teacher_path), n_windows=256, n_val=64, epochs=6, batch_size=64, n_objects=4)
    out = distill.main(tmp_path / "student.npz", cfg, "test", progress=False)
    header = load_normalizer_file(out).meta
    assert header["architecture"] == "lite" and header["trained"] is True
    assert header["teacher"]["sha256"] == hashlib.sha256(teacher_path.read_bytes()).hexdigest()
    fit = header["distillation"]
    assert fit["validation"]["output_rmse"] < fit["validation_initial"]["output_rmse"]
    card = out.with_suffix(".md").read_text()
    assert "Command: `test`" in card and "teacher.npz" in card
    assert _alcn(out).normalize(np.full((40, 50), 0.5, np.float32)).shape == (40, 50)


def test_distill_copies_a_constant_teacher_exactly(tmp_path):
    from alcn_cv.train import distill
    from alcn_cv.train.config import LiteDistillConfig

    dog = [1.0, 0.0, -1.0] + [0.0] * 7
    teacher = Normalizer(hidden=16, init_weights=dog)
    meta = dict(load_normalizer_file(MODELS["paper"]).meta)
    meta.update(config=teacher.config)
    path = save_normalizer_file(tmp_path / "teacher.npz", teacher.state_arrays(), meta)
    cfg = LiteDistillConfig(teacher=str(path), n_windows=32, n_val=8, n_objects=2)
    student, record = distill.distill(cfg, progress=False)
    assert record["constant_teacher"] and record["settings"]["epochs"] == 0
    with torch.no_grad():
        out = student(torch.rand(3, 1, 48, 48))
    np.testing.assert_allclose(out.numpy(), np.tile(dog, (3, 1)), atol=1e-6)


def test_distill_validates_on_windows_it_did_not_train_on(tmp_path, monkeypatch):
    """The validation windows are rendered apart from the training windows (another seed): drawn with the training
    seed they would be the first training windows again, and the fidelity a card reports would be in sample."""
    from alcn_cv.train import distill
    from alcn_cv.train.config import LiteDistillConfig

    rendered = []
    render = distill.render_windows
    monkeypatch.setattr(
        distill, "render_windows", lambda *args, **kwargs: (rendered.append(r := render(*args, **kwargs)), r)[1]
    )
    teacher = Normalizer(hidden=16, init_weights=[1.0, 0.0, -1.0] + [0.0] * 7)  # constant: no training steps
    meta = dict(load_normalizer_file(MODELS["paper"]).meta)
    meta.update(config=teacher.config)
    path = save_normalizer_file(tmp_path / "teacher.npz", teacher.state_arrays(), meta)
    distill.distill(LiteDistillConfig(teacher=str(path), n_windows=32, n_val=8, n_objects=2), progress=False)
    train, val = (r.windows for r in rendered)
    assert (len(train), len(val)) == (32, 8)
    assert not any(np.array_equal(v, t) for v in val for t in train)


def test_model_names():
    with pytest.raises(InputError, match="model"):
        alcn_cv.createALCN(model="huge")
    assert alcn_cv.createALCN(model="paper").weights_path == MODELS["paper"]
    lite = _alcn(None, model="lite", mixture="pyramid")
    assert lite.weights_path == MODELS["lite"] and lite.apply(np.zeros((48, 64), np.uint8)).shape == (48, 64)


def test_default_is_the_gain_normalizer_and_lite_the_pyramid():
    default = alcn_cv.createALCN()
    assert (default.weights_path, default.mixture, default.grid_stride, default.scale) == (
        MODELS["gain"],
        "exact",
        8,
        1.0,
    )
    assert alcn_cv.createALCN(backend="opencv").mixture == "exact"
    lite = alcn_cv.createALCN(model="lite")
    assert (lite.weights_path, lite.mixture, lite.grid_stride) == (MODELS["lite"], "pyramid", 8)
    assert alcn_cv.createALCN(model="lite", backend="torch").mixture == "exact"  # no pyramid in torch
    assert alcn_cv.createALCN(model="lite", backend="opencv").mixture == "pyramid"


def test_threads_are_restored(image, monkeypatch):
    """The network in torch (``backend="fast"``) on 1 thread while it runs, the caller's 2 again after."""
    before = torch.get_num_threads()
    set_threads = torch.set_num_threads
    calls: list[int] = []
    monkeypatch.setattr(torch, "set_num_threads", lambda n: (calls.append(n), set_threads(n))[1])
    try:
        torch.set_num_threads(2)
        alcn = _alcn(None, model="paper", backend="fast", threads=1, grid_stride=16)
        np.testing.assert_allclose(
            alcn.normalize(image),
            _alcn(None, model="paper", backend="fast", threads=None, grid_stride=16).normalize(image),
            atol=1e-6,
        )
        assert 1 in calls and calls[-1] == 2 and torch.get_num_threads() == 2  # set for the call, then restored
    finally:
        set_threads(before)
    with pytest.raises(InputError, match="threads"):
        alcn_cv.createALCN(threads=0)


@pytest.mark.parametrize(("model", "teacher"), [("lite", "paper"), ("gain-lite", "gain")])
def test_a_stale_lite_file_is_reported(tmp_path, monkeypatch, caplog, model, teacher):
    import logging

    from alcn_cv.enhance import alcn as alcn_module

    other_teacher = tmp_path / "other.npz"
    other_teacher.write_bytes(b"not the teacher the lite file was distilled from")
    monkeypatch.setitem(alcn_module.MODELS, teacher, other_teacher)
    with caplog.at_level(logging.WARNING, logger="alcn_cv.enhance.alcn"):
        alcn_cv.createALCN(model=model)
    assert "re-distil" in caplog.text


def test_files_record_the_default_model_by_name():
    from alcn_cv.enhance.alcn import pin_default_model
    from alcn_cv.runtime import DEFAULT_MODEL

    assert pin_default_model(
        "alcn"
    ) == f"alcn:model={DEFAULT_MODEL}" and alcn_cv.createALCN().weights_path.stem.endswith(DEFAULT_MODEL)
    assert pin_default_model("alcn:threads=1") == f"alcn:threads=1:model={DEFAULT_MODEL}"
    for spec in ("alcn:model=lite", "alcn:weights=w.npz", "dog", "dog:sigma1=1"):
        assert pin_default_model(spec) == spec
    # "model=None" is the default model too: it was appended to ("alcn:model=None:model=gain"), a spec that a
    # model given twice makes unreadable
    assert pin_default_model("alcn:scale=1.0:model=None") == f"alcn:scale=1.0:model={DEFAULT_MODEL}"


def test_pyramid_error_bound_on_a_small_image_and_for_the_widest_kernel():
    """A small image keeps the pyramid to levels of at least 8 pixels, and the bottom and right borders are padded
    beyond the widest blur's reach: without either, the widest kernel's error grows 5 to 70 times."""
    rng = np.random.default_rng(3)
    widest = np.eye(10)[9]
    for h, w, max_bound, mean_bound in [(24, 30, 4e-4, 2e-4), (121, 163, 1.5e-3, 2e-4)]:
        coarse = rng.random((h // 4 + 1, w // 4 + 1), dtype=np.float32)
        texture = cv2.resize(coarse, (w, h), interpolation=cv2.INTER_CUBIC) + 0.3 * rng.random((h, w), dtype=np.float32)
        image = np.clip(texture / texture.max() * np.linspace(0.2, 1.0, w, dtype=np.float32)[None, :], 0, 1)
        approx = pyramid_mixture(image, FULL_RES_SIGMAS, lambda level, ks, shape: [float(widest[k]) for k in ks])
        diff = np.abs(approx - alcn_filter(image, widest, FULL_RES_SIGMAS))
        assert diff.max() <= max_bound and diff.mean() <= mean_bound, (h, w, diff.max(), diff.mean())


def test_output_gram_is_the_mean_product_of_the_blurs_over_the_centre():
    """The distillation's metric ``M_ij = mean(B_i B_j)`` over each window's centre 32x32: a Gram over the window's
    corner, or a sum where the mean is meant (1024 times the loss and the recorded output_rmse 32 times), passed every
    run of the distillation unseen."""
    from scipy import ndimage

    from alcn_cv.train.distill import output_gram

    windows = np.random.default_rng(0).random((2, 64, 64), dtype=np.float32)
    windows[1, :20] = 0.0  # the top rows differ from the centre's: a Gram over the corner would differ
    sigmas = [1.0, 2.5]
    gram = output_gram(windows, sigmas)
    assert gram.shape == (2, 2, 2) and gram.dtype == np.float32
    for w, m in zip(windows, gram, strict=True):
        whole = [ndimage.gaussian_filter(w.astype(np.float64), s, mode="mirror", truncate=3.0) for s in sigmas]
        blurs = [b[16:48, 16:48] for b in whole]
        expected = [[np.mean(bi * bj) for bj in blurs] for bi in blurs]
        np.testing.assert_allclose(m, expected, rtol=1e-5)
