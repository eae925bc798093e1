"""CIE Lab of apply() (alcn_cv.filters.lab) and its torch twin (alcn_cv.filters.torch_lab)."""

import cv2
import numpy as np
import pytest

from alcn_cv.filters.lab import inverse_gamma_table, spline_coefficients, srgb_to_linear

torch = pytest.importorskip("torch")
torch_lab = pytest.importorskip("alcn_cv.filters.torch_lab")


def _srgb_formula(x):
    x = np.asarray(x, np.float64)
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def _bgr(seed=0, shape=(48, 64, 3)):
    return np.random.default_rng(seed).integers(0, 256, shape, dtype=np.uint8)


def test_spline_passes_through_its_knots_with_continuous_slope_and_curvature():
    values = np.cbrt(np.linspace(0.0, 2.0, 33))
    a, b, c, d = spline_coefficients(values).astype(np.float64).T
    np.testing.assert_allclose(a, values[:-1], atol=1e-7)
    np.testing.assert_allclose(a + b + c + d, values[1:], atol=1e-6)  # the end of each interval
    np.testing.assert_allclose((b + 2 * c + 3 * d)[:-1], b[1:], atol=1e-5)  # slope
    np.testing.assert_allclose((c + 3 * d)[:-1], c[1:], atol=1e-5)  # curvature / 2
    assert c[0] == 0 and abs(c[-1] + 3 * d[-1]) < 1e-6  # natural ends


@pytest.mark.parametrize("shape", [(7,), (5, 9), (6, 5, 3)])
def test_srgb_decoding_is_the_formula_in_place(shape):
    unit = np.random.default_rng(1).random(shape).astype(np.float32)
    expected = _srgb_formula(unit)
    out = srgb_to_linear(unit)
    assert out is unit
    np.testing.assert_allclose(out, expected, atol=3e-7)


def test_inverse_gamma_spline_follows_the_srgb_encoding():
    x = np.linspace(0.0, 1.0, 4097)
    a, b, c, d = inverse_gamma_table()[np.minimum((x * 1024).astype(int), 1023)].astype(np.float64).T
    t = x * 1024 - np.minimum((x * 1024).astype(int), 1023)
    spline = ((d * t + c) * t + b) * t + a
    exact = np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)
    assert np.abs(spline - exact).max() < 1e-4  # the spline's own error, largest near the curve's kink


def test_torch_lab_is_opencvs_linear_conversion_of_the_decoded_image():
    bgr = _bgr()
    unit = bgr.astype(np.float32) / 255
    expected = cv2.cvtColor(srgb_to_linear(unit.copy()), cv2.COLOR_LBGR2Lab)
    rgb = torch.from_numpy(unit[..., ::-1].copy()).permute(2, 0, 1)[None]
    lab = torch_lab.rgb_to_lab(rgb)[0].permute(1, 2, 0).numpy()
    assert np.abs(lab[..., 0] - expected[..., 0]).max() < 1e-4
    assert np.abs(lab[..., 1:] - expected[..., 1:]).max() < 1e-3
    # OpenCV's sRGB conversion is tabulated: its L is a tenth of a unit off
    assert np.abs(cv2.cvtColor(unit, cv2.COLOR_BGR2Lab)[..., 0] - expected[..., 0]).max() > 0.05


def test_torch_lab_to_rgb_is_opencvs_and_differentiable():
    bgr = _bgr(2)
    lab = cv2.cvtColor(srgb_to_linear(bgr.astype(np.float32) / 255), cv2.COLOR_LBGR2Lab)
    expected = cv2.cvtColor(lab, cv2.COLOR_Lab2BGR)[..., ::-1]
    out = torch_lab.lab_to_rgb(torch.from_numpy(lab).permute(2, 0, 1)[None])[0].permute(1, 2, 0).numpy()
    assert np.abs(out - expected).max() < 1e-5
    rgb = torch.rand(1, 3, 6, 7, dtype=torch.float64, requires_grad=True)
    torch_lab.lab_to_rgb(torch_lab.rgb_to_lab(rgb)).sum().backward()
    assert torch.isfinite(rgb.grad).all() and rgb.grad.abs().sum() > 0


def test_apply_decodes_uint8_and_float_images_alike():
    import alcn_cv

    bgr = _bgr(3, (40, 56, 3))
    clahe = alcn_cv.create("clahe")
    from_uint8 = clahe.apply(bgr, out_dtype=np.float32)
    # the float values apply() sees for a uint8 image: the table of the decoded curve is the float path's
    from_float = clahe.apply(bgr.astype(np.float32) * np.float32(1 / 255), out_dtype=np.float32)
    np.testing.assert_array_equal(from_uint8, from_float)


@pytest.mark.parametrize("dtype", [torch.float16, torch.bfloat16, torch.float64])
def test_torch_lab_in_other_dtypes_stays_near_float32(dtype):
    """The spline's interval is found in float32 (1023 is not a bfloat16); the values follow the dtype's precision."""
    rgb = torch.rand(1, 3, 16, 20)
    lab = torch_lab.rgb_to_lab(rgb)
    other = torch_lab.RgbToLab().to(dtype)(rgb.to(dtype))
    assert other.dtype == dtype
    assert (other.float() - lab).abs().max() < {torch.float16: 1.0, torch.bfloat16: 5.0, torch.float64: 1e-3}[dtype]
    back = torch_lab.LabToRgb().to(dtype)(lab.to(dtype)).float()
    assert (back - torch_lab.lab_to_rgb(lab)).abs().max() < {
        torch.float16: 0.05,
        torch.bfloat16: 0.15,
        torch.float64: 1e-5,
    }[dtype]


def test_srgb_to_linear_writes_a_strided_view_in_place():
    """The reshape of a strided view is a copy: the view was returned unchanged."""
    unit = np.random.default_rng(2).random((6, 8, 3), dtype=np.float32)
    expected = srgb_to_linear(unit.copy())
    whole = unit.copy()
    assert srgb_to_linear(whole[:, ::2]) is not None
    np.testing.assert_array_equal(whole[:, ::2], expected[:, ::2])
    np.testing.assert_array_equal(whole[:, 1::2], unit[:, 1::2])  # the rest untouched
    fortran = np.asfortranarray(unit)
    np.testing.assert_array_equal(srgb_to_linear(fortran), expected)


def test_the_conversions_refuse_what_they_cannot_convert():
    """srgb_to_linear of a uint8 BGR frame (an OpenCV user's first try) crashed the process: OpenCV's pow of a uint8
    image corrupts its state; the torch conversions broadcast one channel as three."""
    from alcn_cv.errors import InputError
    from alcn_cv.filters.lab import srgb_to_lab

    frame = np.full((48, 64, 3), 200, np.uint8)
    for convert in (srgb_to_linear, srgb_to_lab):
        with pytest.raises(InputError, match="float32 intensities in \\[0, 1\\] are converted in place, got uint8"):
            convert(frame)
    assert (frame == 200).all()
    with pytest.raises(InputError, match="a C-ordered HxWx3 image, got shape \\(48, 64\\)"):
        srgb_to_lab(np.zeros((48, 64), np.float32))
    for convert in (torch_lab.rgb_to_lab, torch_lab.lab_to_rgb, torch_lab.RgbToLab()):
        with pytest.raises(InputError, match=r"a \(B, 3, H, W\) image, got shape \(2, 1, 8, 8\)"):
            convert(torch.rand(2, 1, 8, 8))
