"""The classical baselines of issue 5: the apply() contract, and each against an independent computation."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

import alcn_cv
from alcn_cv.enhance.base import NoNormalization
from alcn_cv.errors import InputError

#: Every registered method but none (nothing to check), ALCN and Tan-Triggs (their own files check them): a method
#: registered later is checked here too.
CLASSICAL = [m for m in alcn_cv.available() if m not in ("none", "alcn", "tantriggs")]


def _scene(h: int = 40, w: int = 52, seed: int = 0) -> np.ndarray:
    """A textured float32 image in [0.05, 0.95] with edges and a smooth shading ramp."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w]
    texture = ndimage.gaussian_filter(rng.random((h, w)), 1.5)
    texture = (texture - texture.min()) / (np.ptp(texture) + 1e-9)
    blocks = ((x // 13 + y // 11) % 2).astype(np.float64)
    shading = 0.4 + 0.6 * x / w
    img = shading * (0.3 + 0.4 * blocks + 0.3 * texture)
    return np.clip(img, 0.05, 0.95).astype(np.float32)


@pytest.mark.parametrize("name", CLASSICAL)
@pytest.mark.parametrize("kind", ["gray_u8", "gray_u16", "gray_f32", "gray_hw1", "bgr_u8", "bgr_f32"])
def test_apply_contract(name, kind):
    gray = _scene()
    rgb = np.stack([gray, gray[::-1], gray[:, ::-1]], -1)
    img = {
        "gray_u8": np.rint(gray * 255).astype(np.uint8),
        "gray_u16": np.rint(gray * 65535).astype(np.uint16),
        "gray_f32": gray,
        "gray_hw1": np.rint(gray * 255).astype(np.uint8)[..., None],
        "bgr_u8": np.rint(rgb * 255).astype(np.uint8),
        "bgr_f32": rgb.astype(np.float32),
    }[kind]
    before = img.copy()
    out = alcn_cv.create(name).apply(img)
    assert out.shape == img.shape and out.dtype == img.dtype
    np.testing.assert_array_equal(img, before)  # the caller's array is untouched
    if out.dtype == np.float32:
        assert np.isfinite(out).all() and out.min() >= 0 and out.max() <= 1
    assert np.ptp(out.astype(np.float64)) > 0  # not a blank image
    f32 = alcn_cv.create(name).apply(img, out_dtype=np.float32)
    assert f32.dtype == np.float32 and f32.shape == img.shape


@pytest.mark.parametrize("name", CLASSICAL)
def test_small_and_flat_images(name):
    norm = alcn_cv.create(name)
    for img in (np.full((9, 11), 0.5, np.float32), np.zeros((1, 1), np.float32), _scene(3, 4)):
        out = norm.normalize(img)
        assert out.shape == img.shape and out.dtype == np.float32 and np.isfinite(out).all()


@pytest.mark.parametrize("name", CLASSICAL)
@pytest.mark.parametrize(
    "bad",
    [
        np.zeros((0, 5), np.uint8),
        np.zeros((8, 8, 5), np.uint8),
        np.zeros((8, 8), np.int32),
        np.full((8, 8), np.nan, np.float32),
        np.full((8, 8), 200.0, np.float32),
        np.zeros((2, 8, 8, 1), np.uint8),
    ],
    ids=["empty", "5ch", "int32", "nan", "float_255", "4d"],
)
def test_bad_input(name, bad):
    with pytest.raises(InputError):
        alcn_cv.create(name).apply(bad)


@pytest.mark.parametrize(
    ("name", "params"),
    [
        ("dog", {"sigma1": 2.0, "sigma2": 1.0}),
        ("dog", {"sigma1": -1.0}),
        ("slcn", {"sigma": 0}),
        ("dlcn", {"eps": float("nan")}),
        ("lrn", {"size": 4}),
        ("clahe", {"tileGridSize": (0, 8)}),
        ("sqi", {"sigmas": ()}),
        ("intrinsic", {"threshold": -1}),
        ("he", {"unknown": 1}),
    ],
)
def test_bad_parameters(name, params):
    with pytest.raises(InputError):
        alcn_cv.create(name, **params)


def _mirror_gauss(img: np.ndarray, sigma: float) -> np.ndarray:
    """scipy's Gaussian with the project's kernel convention: truncate 3, reflect-101 ("mirror")."""
    return ndimage.gaussian_filter(img.astype(np.float64), sigma, mode="mirror", truncate=3.0)


def test_dog_matches_skimage():
    from skimage.filters import difference_of_gaussians

    img = _scene()
    ref = difference_of_gaussians(img.astype(np.float64), 0.7, 2.3, mode="mirror", truncate=3.0)
    out = alcn_cv.create("dog", sigma1=0.7, sigma2=2.3).normalize(img)
    np.testing.assert_allclose(out, ref, atol=1e-5)


def test_slcn_dlcn_match_scipy():
    img = _scene()
    sigma = 1.7
    v = img - _mirror_gauss(img, sigma)
    np.testing.assert_allclose(alcn_cv.create("slcn", sigma=sigma).normalize(img), v, atol=1e-5)
    s = np.sqrt(_mirror_gauss(v * v, sigma))
    ref = v / np.maximum(s, s.mean())
    np.testing.assert_allclose(alcn_cv.create("dlcn", sigma=sigma).normalize(img), ref, atol=1e-4)


def test_dlcn_and_ns_remove_a_gain():
    img = _scene()
    for name in ("ns", "dlcn", "whitening"):
        norm = alcn_cv.create(name)
        np.testing.assert_allclose(norm.normalize(img * np.float32(0.3)), norm.normalize(img), atol=2e-3)


def test_ns_standardizes():
    out = alcn_cv.create("ns").normalize(_scene())
    assert abs(out.mean()) < 1e-5 and abs(out.std() - 1) < 1e-2


def test_lrn_matches_torch_across_one_axis():
    torch = pytest.importorskip("torch")
    size, alpha, beta, k = 5, 0.8, 0.75, 0.02
    row = _scene(1, 60, seed=3)[0]
    img = np.repeat(row[None], 30, axis=0)  # constant along y: the 5x5 sum is 5 times the 1D sum along x
    out = alcn_cv.create("lrn", size=size, alpha=alpha, beta=beta, k=k).normalize(img)
    a = torch.from_numpy((row - row.mean()).astype(np.float32)).reshape(1, -1, 1, 1)  # x as channels
    ref = torch.nn.LocalResponseNorm(size, alpha=alpha, beta=beta, k=k)(a).reshape(-1).numpy()
    r = size // 2
    np.testing.assert_allclose(out[15, r:-r], ref[r:-r], rtol=1e-4, atol=1e-6)


@pytest.mark.parametrize("transposed", [False, True])  # the gratings vertical, then horizontal: both frequencies
def test_whitening_gain_follows_the_filter(transposed):
    h, w = 64, 256
    f1, f2 = 8 / w, 64 / w  # cycles per pixel
    x = np.arange(w)
    img = np.repeat((0.5 + 0.2 * np.sin(2 * np.pi * f1 * x) + 0.2 * np.sin(2 * np.pi * f2 * x))[None], h, 0)
    f0 = 0.3
    whitening = alcn_cv.create("whitening", f0=f0)
    whole = (
        whitening.normalize(img.T.copy().astype(np.float32)).T
        if transposed
        else whitening.normalize(img.astype(np.float32))
    )
    out = whole[h // 2, w // 4 : 3 * w // 4]
    xs = x[w // 4 : 3 * w // 4]
    basis = np.stack([np.sin(2 * np.pi * f * xs + p) for f in (f1, f2) for p in (0, np.pi / 2)], 1)
    coef = np.linalg.lstsq(basis, out, rcond=None)[0]
    amp1, amp2 = np.hypot(coef[0], coef[1]), np.hypot(coef[2], coef[3])

    def gain(f):
        return f * np.exp(-((f / f0) ** 4))

    assert amp2 / amp1 == pytest.approx(gain(f2) / gain(f1), rel=0.05)


def test_he_flattens_the_histogram():
    rng = np.random.default_rng(1)
    img = (rng.random((64, 64)) ** 3).astype(np.float32)  # dark-skewed
    out = alcn_cv.create("he").normalize(img)
    order = np.argsort(img, axis=None)
    assert np.all(np.diff(out.reshape(-1)[order]) >= 0)  # monotone
    counts, _ = np.histogram(out, bins=4, range=(0, 1))
    assert counts.min() > 0.2 * out.size


def test_clahe_is_opencv():
    import cv2

    img8 = np.rint(_scene() * 255).astype(np.uint8)
    ref = cv2.createCLAHE(clipLimit=3.0, tileGridSize=(2, 3)).apply(img8)
    out = alcn_cv.create("clahe", clipLimit=3.0, tileGridSize=(2, 3)).apply(img8)
    np.testing.assert_array_equal(out, ref)


def test_sqi_unweighted_matches_scipy():
    img = _scene()
    eps = 0.01
    ref = np.mean([np.log(img + eps) - np.log(_mirror_gauss(img, s) + eps) for s in (1.0, 2.5)], axis=0)
    out = alcn_cv.create("sqi", sigmas=(1.0, 2.5), weighted=False).normalize(img)
    np.testing.assert_allclose(out, ref, atol=1e-4)


def test_sqi_weighted_matches_direct_computation():
    img = _scene(14, 17, seed=5)
    sigma, eps = 1.0, 0.01
    r = 3
    g1 = np.exp(-0.5 * (np.arange(-r, r + 1) / sigma) ** 2)
    g1 /= g1.sum()
    g = np.outer(g1, g1)
    padded = np.pad(img.astype(np.float64), r, mode="reflect")  # numpy "reflect" is reflect-101
    ref = np.empty(img.shape)
    for i in range(img.shape[0]):
        for j in range(img.shape[1]):
            win = padded[i : i + 2 * r + 1, j : j + 2 * r + 1]
            tau = (g * win).sum()
            side = win <= tau if (win <= tau).sum() * 2 >= win.size else win > tau
            smooth = (g * win * side).sum() / (g * side).sum()
            ref[i, j] = np.log(img[i, j] + eps) - np.log(smooth + eps)
    out = alcn_cv.create("sqi", sigmas=(sigma,), eps=eps).normalize(img)
    np.testing.assert_allclose(out, ref, atol=1e-4)


@pytest.mark.parametrize("shading_along", ["x", "y"])  # the threshold of each direction's gradients
def test_intrinsic_recovers_reflectance_under_smooth_shading(shading_along):
    h, w = 48, 64
    y, x = np.mgrid[0:h, 0:w]
    reflectance = np.where((x // 16 + y // 12) % 2 == 0, 0.8, 0.3)
    # gradient in log well below the threshold
    shading = 0.5 + 0.4 * (x / w) if shading_along == "x" else 0.5 + 0.4 * (y / h)
    img = (reflectance * shading).astype(np.float32)
    eps = 1e-6
    out = alcn_cv.create("intrinsic", threshold=0.1, eps=eps).normalize(img)
    ref = np.log(reflectance)
    ref -= ref.mean()
    np.testing.assert_allclose(out, ref, atol=2e-2)
    # with no threshold every gradient is kept: the log image itself, zero-mean
    keep_all = alcn_cv.create("intrinsic", threshold=0.0, eps=0.01).normalize(img)
    log = np.log(img.astype(np.float64) + 0.01)
    np.testing.assert_allclose(keep_all, log - log.mean(), atol=1e-4)


@pytest.mark.parametrize("name", CLASSICAL)
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32])
@pytest.mark.parametrize("colour", ["bgra", "gray_alpha"])
def test_alpha_is_passed_through(name, dtype, colour):
    gray = _scene()
    colours = np.stack([gray, gray[::-1], gray[:, ::-1]], -1) if colour == "bgra" else gray[..., None]
    alpha = np.linspace(0, 1, gray.size, dtype=np.float32).reshape(gray.shape)
    unit = np.dstack([colours, alpha])
    img = unit if dtype == np.float32 else np.rint(unit * np.iinfo(dtype).max).astype(dtype)
    before = img.copy()
    norm = alcn_cv.create(name)
    out = norm.apply(img)
    assert out.shape == img.shape and out.dtype == img.dtype
    np.testing.assert_array_equal(out[..., -1], img[..., -1])
    np.testing.assert_array_equal(out[..., :-1], norm.apply(img[..., :-1]))
    np.testing.assert_array_equal(img, before)
    as_float = norm.apply(img, out_dtype=np.float32)
    np.testing.assert_allclose(
        as_float[..., -1], alpha, atol=1e-6 if dtype == np.float32 else 0.5 / np.iinfo(dtype).max
    )


@pytest.mark.parametrize("name", CLASSICAL)
def test_non_native_byte_order_is_accepted(name):
    img = np.rint(_scene() * 65535).astype(np.uint16)
    swapped = img.astype(img.dtype.newbyteorder("S"))  # same values, other byte order
    out = alcn_cv.create(name).apply(swapped)
    assert out.dtype == np.uint16 and out.dtype.isnative
    np.testing.assert_array_equal(out, alcn_cv.create(name).apply(img))


def test_small_images_warn_once(caplog):
    class Windowed(NoNormalization):
        name = "windowed-test"
        min_size = 48

    norm = Windowed()
    with caplog.at_level("WARNING", logger="alcn_cv.enhance.base"):
        for side in (1, 3, 47, 47):
            assert norm.apply(np.zeros((side, side), np.uint8)).shape == (side, side)
        Windowed().apply(np.zeros((48, 48), np.uint8))
    warnings = [r for r in caplog.records if "smaller than" in r.getMessage()]
    assert len(warnings) == 1 and "48 px window" in warnings[0].getMessage()
    caplog.clear()
    with caplog.at_level("WARNING", logger="alcn_cv.enhance.base"):
        alcn_cv.create("dog").apply(np.zeros((3, 3), np.uint8))  # no window: no warning
    assert not caplog.records


@pytest.mark.parametrize(
    ("name", "params", "message"),
    [
        ("alcn", {"scale": "abc"}, "'alcn': scale='abc' must be a number"),
        ("dog", {"sigma1": "x"}, "'dog': sigma1='x' must be a number"),
        ("slcn", {"sgma": 1.0}, "'slcn': no parameter 'sgma'; its parameters: sigma"),
        ("he", {"clipLimit": 2.0}, "'he': no parameter 'clipLimit'"),
        ("sqi", {"weighted": "yes"}, "'sqi': weighted='yes' must be True or False"),
    ],
)
def test_parameter_errors_name_the_method_and_the_parameter(name, params, message):
    with pytest.raises(InputError, match=message):
        alcn_cv.create(name, **params)


def test_parameters_of_the_right_kind_pass():
    assert alcn_cv.create("clahe", clipLimit=np.float32(3), tileGridSize=[4, 4]).tileGridSize == (4, 4)
    assert alcn_cv.create("sqi", sigmas=[1, 2]).sigmas == (1.0, 2.0)


def test_every_method_is_described():
    from alcn_cv.enhance.registry import describe

    for name in alcn_cv.available():
        summary, reference = describe(name)
        assert summary and "\n" not in summary, name
        assert reference or name in ("none", "alcn"), name


def test_intrinsic_default_threshold_takes_a_log_step_below_0_1_as_shading():
    norm = alcn_cv.create("intrinsic")
    assert (norm.threshold, norm.eps) == (0.1, 0.01)  # Grosse et al.'s Retinex baseline, as documented
    shading = np.full((32, 32), 0.5, np.float32)
    shading[:, 16:] = 0.51 * np.exp(0.08) - 0.01  # log(I + eps) steps by 0.08: shading, removed
    np.testing.assert_allclose(norm.normalize(shading), 0.0, atol=1e-6)
    edge = shading.copy()
    edge[:, 16:] = 0.51 * np.exp(0.12) - 0.01  # a step of 0.12: reflectance, kept
    assert np.ptp(norm.normalize(edge)) > 0.1


def test_a_methods_repr_shows_its_parameters():
    """create("dog:sigma1=1:sigma2=3") printed DifferenceOfGaussians(name='dog'), its settings hidden."""
    assert repr(alcn_cv.create("dog:sigma1=1:sigma2=3")) == "DifferenceOfGaussians(sigma1=1.0, sigma2=3.0)"
    assert repr(alcn_cv.create("clahe:clip_limit=4")) == "CLAHE(clipLimit=4.0, tileGridSize=(8, 8))"
    assert repr(alcn_cv.create("none")) == "NoNormalization(name='none')"  # no parameter


def test_sqi_uses_its_eps_in_the_numerator_too():
    """``SQI(I) = mean_k log((I + eps) / (F_k * I + eps))``: the numerator's eps must be the parameter, not the
    default 0.01 (a flat image would then have a non-zero quotient, log(0.01 + I) - log(eps + I))."""
    img = _scene()
    eps = 0.2
    ref = np.mean([np.log(img + eps) - np.log(_mirror_gauss(img, s) + eps) for s in (1.0, 2.5)], axis=0)
    out = alcn_cv.create("sqi", sigmas=(1.0, 2.5), eps=eps, weighted=False).normalize(img)
    np.testing.assert_allclose(out, ref, atol=1e-5)
    flat = np.full((20, 24), 0.4, np.float32)
    np.testing.assert_allclose(alcn_cv.create("sqi", eps=eps).normalize(flat), 0.0, atol=1e-6)


def test_ns_divides_by_the_deviation_plus_its_eps():
    """``NS(I) = (I - mean(I)) / (std(I) + eps)`` with the caller's eps (a fixed 1e-6 passed every default test)."""
    img = _scene()
    eps = 0.5
    ref = (img.astype(np.float64) - img.mean()) / (img.std() + eps)
    np.testing.assert_allclose(alcn_cv.create("ns", eps=eps).normalize(img), ref, atol=1e-6)


def test_lrn_sums_with_reflect_101_borders():
    """LRN's neighbourhood sum runs over reflect-101 borders (as the docstring says): the torch comparison is checked
    away from the borders only, so another border mode (replicate, say) changed the border pixels unseen."""
    size, alpha, beta, k = 5, 0.8, 0.75, 0.02
    img = _scene(23, 29, seed=4)
    a = img.astype(np.float64) - img.mean()
    r = size // 2
    padded = np.pad(a * a, r, mode="reflect")  # NumPy's "reflect" is reflect-101
    energy = np.lib.stride_tricks.sliding_window_view(padded, (size, size)).mean(axis=(2, 3))
    ref = a / (k + alpha * energy) ** beta
    out = alcn_cv.create("lrn", size=size, alpha=alpha, beta=beta, k=k).normalize(img)
    np.testing.assert_allclose(out, ref, rtol=1e-4, atol=1e-6)
