"""Physically motivated changes of light applied to a real photograph, and relit pairs with their correspondence.

:func:`relight` treats a uint8 photograph as the scene's reflectance under a neutral light and
films it again under another light, with a camera:

1. decode to linear intensities (``I^2.2``);
2. the new light: a global strength (:attr:`LightChangeConfig.gain`), a smooth shading field
   with a gain ramp (:func:`shading_field`), hard cast shadows with a penumbra
   (:func:`shadow_mask`: edges, polygons, blinds, windows, foliage, several at once), optionally the
   shading of the photograph read as a relief under a directional light (:func:`relief_shading`)
   and the light's colour (per-channel gains, the white balance the camera does not undo);
3. the camera: an auto-exposure that brings the mean to a target within its range
   (``max_exposure``), the sensor's shot and read noise at the level of that signal
   (:func:`sensor_noise`) and its saturation at full scale, then a digital gain (ISO, up to
   ``max_iso``) when the exposure could not reach the target, which amplifies the noise of a
   dark scene;
4. an exposure error, clipping, a tone curve ``S^(1/gamma)``, 8-bit quantization and JPEG.

:func:`relit_frames` relights one photograph several times, each copy optionally seen through a small random
homography (:func:`random_homography`): a scene of the real-light trainer, whose locations are their own classes
(Eq. 2's labels of ALCN, as SuperPoint's homographic adaptation labels one image). Everything draws from the given
``numpy`` generator only: the same seed gives the same images.

Example::

    >>> import numpy as np
    >>> image = np.random.default_rng(0).integers(0, 256, (64, 80, 3), dtype=np.uint8)
    >>> frames = relit_frames(image, 2, np.random.default_rng(1), jitter=2.0)
    >>> frames.shape, frames.dtype
    ((2, 64, 80, 3), dtype('uint8'))
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from alcn_cv.data.lighting import SHADOW_SHAPES, shadow_shape
from alcn_cv.errors import InputError

__all__ = [
    "LIGHTS",
    "LightChangeConfig",
    "random_homography",
    "relief_shading",
    "relight",
    "relit_frames",
    "sensor_noise",
    "shading_field",
    "shadow_mask",
]

#: The decoding gamma of the input photographs (sRGB, approximately).
DECODING_GAMMA = 2.2

Range = tuple[float, float]


@dataclass(frozen=True)
class LightChangeConfig:
    """The ranges the light changes are drawn from (uniform, or log-uniform where said);
    ``(a, a)`` fixes a value. Intensities are linear, relative to the photograph's.

    Attributes:
        gain: the light's global strength (log-uniform).
        shading: largest amplitude of the smooth shading field's log-gain (natural log).
        shading_cells: least and most cells per side of the shading field's random grid.
        ramp: largest log-ratio, end to end, of the linear gain ramp.
        shadows: least and most cast shadows (:func:`shadow_mask`).
        shadow_light: the light left inside a shadow (ambient / direct + ambient).
        penumbra: the penumbra's Gaussian sigma (pixels, log-uniform).
        colour: largest log-gain of a colour channel (the light's colour), colour images only.
        relief: the height, in pixels, of a full-scale intensity when the photograph is read as a
            relief lit from one direction (:func:`relief_shading`; log-uniform; ``(0, 0)``: off).
        relief_sigma: the blur of that height map (pixels, log-uniform).
        elevation: the directional light's elevation above the image plane (degrees).
        ambient: the share of ambient light in :func:`relief_shading`.
        target: the auto-exposure's target mean of the signal; ``None``: no auto-exposure, no ISO.
        max_exposure: the exposure's range ``[1 / max_exposure, max_exposure]``.
        max_iso: the largest digital gain.
        exposure_error: the exposure's error in stops (uniform).
        full_well: electrons at full scale (log-uniform): the shot noise.
        read_noise: the read noise in electrons.
        gamma: the tone curve's gamma ``S^(1/gamma)``.
        jpeg_probability: the chance of a JPEG compression.
        jpeg_quality: its quality range.
    """

    gain: Range = (0.05, 1.5)
    shading: float = 0.7
    shading_cells: tuple[int, int] = (2, 6)
    ramp: float = 1.4
    shadows: tuple[int, int] = (0, 3)
    shadow_light: Range = (0.1, 0.6)
    penumbra: Range = (0.5, 12.0)
    colour: float = 0.25
    relief: Range = (0.0, 0.0)
    relief_sigma: Range = (1.0, 4.0)
    elevation: Range = (20.0, 70.0)
    ambient: Range = (0.1, 0.5)
    target: float | None = 0.18
    max_exposure: float = 4.0
    max_iso: float = 16.0
    exposure_error: Range = (-1.0, 1.0)
    full_well: Range = (500.0, 20000.0)
    read_noise: Range = (1.0, 6.0)
    gamma: Range = (1.8, 2.6)
    jpeg_probability: float = 0.5
    jpeg_quality: tuple[int, int] = (40, 95)

    @classmethod
    def identity(cls) -> LightChangeConfig:
        """No change of light: :func:`relight` returns the photograph (to within one 8-bit level)."""
        return cls(
            gain=(1.0, 1.0),
            shading=0.0,
            ramp=0.0,
            shadows=(0, 0),
            colour=0.0,
            target=None,
            exposure_error=(0.0, 0.0),
            full_well=(np.inf, np.inf),
            read_noise=(0.0, 0.0),
            gamma=(DECODING_GAMMA, DECODING_GAMMA),
            jpeg_probability=0.0,
        )


#: Named light changes: the defaults; more shadows, shading and noise; the defaults plus the shading of the
#: photograph read as a relief under a directional light (the recipe of the permissive default).
LIGHTS: dict[str, LightChangeConfig] = {
    "default": LightChangeConfig(),
    "hard": LightChangeConfig(
        gain=(0.02, 1.5),
        shading=1.0,
        ramp=2.0,
        shadows=(1, 5),
        penumbra=(0.5, 6.0),
        full_well=(200.0, 5000.0),
        read_noise=(2.0, 10.0),
    ),
    "relief": LightChangeConfig(relief=(3.0, 30.0)),
}


def _log_uniform(rng: np.random.Generator, bounds: Range) -> float:
    lo, hi = bounds
    return float(np.exp(rng.uniform(np.log(lo), np.log(hi)))) if lo < hi else float(lo)


def _uniform(rng: np.random.Generator, bounds: Range) -> float:
    return float(rng.uniform(*bounds)) if bounds[0] < bounds[1] else float(bounds[0])


def shading_field(
    shape: tuple[int, int], rng: np.random.Generator, amplitude: float, ramp: float, cells: tuple[int, int] = (2, 6)
) -> np.ndarray:
    """A smooth positive gain field: ``exp(amplitude * s + ramp * u * t)``, ``s`` a random grid of
    ``cells`` per side in [-1, 1] upsampled bicubically, ``u`` uniform in [0, 1], ``t`` a linear ramp
    in a random direction, 1 per ``max(H, W)`` pixels and 0 at the centre (so ``ramp`` is the largest
    log-ratio across the frame's longer side).

    Returns:
        ``(H, W)`` float32, positive; all ones when ``amplitude`` and ``ramp`` are 0.
    """
    h, w = shape
    n = int(rng.integers(cells[0], cells[1] + 1))
    grid = rng.uniform(-1.0, 1.0, (n + 1, n + 1)).astype(np.float32)
    smooth = np.clip(cv2.resize(grid, (w, h), interpolation=cv2.INTER_CUBIC), -1.0, 1.0)
    angle = rng.uniform(0.0, 2.0 * np.pi)
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    t = ((x - w / 2) * np.cos(angle) + (y - h / 2) * np.sin(angle)) / np.float32(max(h, w))
    return np.exp(np.float32(amplitude) * smooth + np.float32(ramp * rng.uniform(0.0, 1.0)) * t).astype(np.float32)


def shadow_mask(
    shape: tuple[int, int],
    rng: np.random.Generator,
    count: int,
    light: Range = (0.1, 0.6),
    penumbra: Range = (0.5, 12.0),
    kinds: tuple[str, ...] = SHADOW_SHAPES,
) -> np.ndarray:
    """The light left by ``count`` cast shadows: each a hard shadow of a kind drawn from ``kinds``
    (:func:`alcn_cv.data.lighting.shadow_shape`: a straight edge, a polygon, blinds, a window,
    foliage) with a penumbra of Gaussian sigma ``penumbra`` (log-uniform), leaving ``light`` of
    the light inside; overlapping shadows multiply.

    Returns:
        ``(H, W)`` float32 in ``[min(light)^count, 1]``; all ones when ``count`` is 0.
    """
    mask = np.ones(shape, np.float32)
    for _ in range(count):
        kind = kinds[int(rng.integers(len(kinds)))]
        lit = shadow_shape(rng, shape, kind, penumbra=_log_uniform(rng, penumbra))
        mask *= 1.0 - np.float32(1.0 - _uniform(rng, light)) * (1.0 - lit)
    return mask


def relief_shading(
    luminance: np.ndarray,
    rng: np.random.Generator,
    depth: float,
    sigma: float = 2.0,
    elevation: float = 45.0,
    ambient: float = 0.3,
) -> np.ndarray:
    """Lambertian shading of the photograph read as a relief (bump mapping): the height is the
    luminance, blurred by ``sigma``, times ``depth`` pixels; a directional light of
    ``elevation`` degrees and random azimuth plus ``ambient`` light; relative to a flat surface
    (gain 1 where the relief is flat). The texture's own light changes with the light's
    direction, as on the relief of the photometric-stereo objects, which a smooth field cannot do.

    Args:
        luminance: ``(H, W)`` float32 linear intensities in [0, 1].

    Returns:
        ``(H, W)`` float32 gain in ``[ambient, 1 / sin(elevation)]``.
    """
    height = cv2.GaussianBlur(luminance.astype(np.float32), (0, 0), sigma) * np.float32(depth)
    gx = cv2.Sobel(height, cv2.CV_32F, 1, 0, ksize=3) / np.float32(8)
    gy = cv2.Sobel(height, cv2.CV_32F, 0, 1, ksize=3) / np.float32(8)
    azimuth, tilt = rng.uniform(0.0, 2.0 * np.pi), np.deg2rad(elevation)
    lx, ly, lz = np.cos(tilt) * np.cos(azimuth), np.cos(tilt) * np.sin(azimuth), np.sin(tilt)
    cosine = (-gx * np.float32(lx) - gy * np.float32(ly) + np.float32(lz)) / np.sqrt(1.0 + gx * gx + gy * gy)
    return (np.float32(ambient) + np.float32(1.0 - ambient) * np.maximum(cosine, 0.0) / np.float32(lz)).astype(
        np.float32
    )


def sensor_noise(signal: np.ndarray, rng: np.random.Generator, full_well: float, read_noise: float) -> np.ndarray:
    """The signal as a sensor records it: shot noise (Poisson, in the Gaussian limit, of
    ``signal * full_well`` electrons) plus Gaussian read noise of ``read_noise`` electrons,
    back in units of full scale: the standard deviation is
    ``sqrt(signal * full_well + read_noise^2) / full_well``, so the noise relative to the
    signal grows as the signal darkens.

    Args:
        signal: float32 in [0, 1] (fraction of full scale), any shape.

    Returns:
        float32 of ``signal``'s shape (not clipped); ``signal`` itself when ``full_well`` is infinite.
    """
    if not np.isfinite(full_well):
        return signal
    std = np.sqrt(np.maximum(signal, 0.0) * np.float32(full_well) + np.float32(read_noise**2)) / np.float32(full_well)
    return (signal + std * rng.standard_normal(signal.shape, dtype=np.float32)).astype(np.float32)


def relight(image: np.ndarray, rng: np.random.Generator, config: LightChangeConfig = LightChangeConfig()) -> np.ndarray:
    """The photograph under another light, filmed again (see the module).

    Args:
        image: uint8 grayscale ``HxW`` or BGR ``HxWx3``.
        rng: the generator of every draw.
        config: the ranges of the light changes.

    Returns:
        uint8 of ``image``'s shape.
    """
    if (
        not isinstance(image, np.ndarray)
        or image.dtype != np.uint8
        or image.ndim not in (2, 3)
        or (image.ndim == 3 and image.shape[2] != 3)
        or min(image.shape[:2]) < 2
    ):
        raise InputError(
            f"image must be uint8 HxW or HxWx3, got {getattr(image, 'dtype', type(image))} "
            f"{getattr(image, 'shape', '')}"
        )
    c = config
    h, w = image.shape[:2]
    linear = np.power(image.astype(np.float32) / np.float32(255), np.float32(DECODING_GAMMA))
    light = np.float32(_log_uniform(rng, c.gain)) * shading_field((h, w), rng, c.shading, c.ramp, c.shading_cells)
    light *= shadow_mask((h, w), rng, int(rng.integers(c.shadows[0], c.shadows[1] + 1)), c.shadow_light, c.penumbra)
    if c.relief[1] > 0:
        luminance = linear.mean(axis=2) if image.ndim == 3 else linear
        light *= relief_shading(
            luminance,
            rng,
            _log_uniform(rng, c.relief),
            _log_uniform(rng, c.relief_sigma),
            _uniform(rng, c.elevation),
            _uniform(rng, c.ambient),
        )
    irradiance = linear * (light[..., None] if image.ndim == 3 else light)
    if image.ndim == 3 and c.colour > 0:
        irradiance *= np.exp(rng.uniform(-c.colour, c.colour, 3)).astype(np.float32)
    exposure = iso = 1.0
    if c.target is not None:
        mean = max(float(irradiance.mean()), 1e-6)
        exposure = float(np.clip(c.target / mean, 1.0 / c.max_exposure, c.max_exposure))
        iso = float(np.clip(c.target / (mean * exposure), 1.0, c.max_iso))
    exposure *= 2.0 ** _uniform(rng, c.exposure_error)
    signal = np.clip(irradiance * np.float32(exposure), 0.0, 1.0)  # the sensor saturates at full scale
    signal = sensor_noise(signal, rng, _log_uniform(rng, c.full_well), _uniform(rng, c.read_noise))
    out = np.power(np.clip(signal * np.float32(iso), 0.0, 1.0), np.float32(1.0 / _uniform(rng, c.gamma)))
    out = np.rint(out * np.float32(255)).astype(np.uint8)
    if rng.random() < c.jpeg_probability:
        quality = int(rng.integers(c.jpeg_quality[0], c.jpeg_quality[1] + 1))
        out = cv2.imdecode(
            cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, quality])[1], cv2.IMREAD_UNCHANGED
        ).reshape(out.shape)
    return out


def relit_frames(
    image: np.ndarray,
    count: int,
    rng: np.random.Generator,
    config: LightChangeConfig = LightChangeConfig(),
    jitter: float = 0.0,
) -> np.ndarray:
    """``count`` relit copies of one photograph, registered to within ``jitter`` pixels: a scene
    in the layout of the real-light trainer (:mod:`alcn_cv.train.real_light`). With ``jitter``,
    each copy is seen through a :func:`random_homography` that moves each corner by up to
    ``jitter`` pixels (a fixed camera's registration error), so that the identification of a
    location is not pixel-exact.

    Returns:
        ``(count, *image.shape)`` uint8.
    """
    h, w = image.shape[:2]
    frames = []
    for _ in range(count):
        copy = image
        if jitter > 0:
            homography = random_homography((h, w), rng, jitter / max(h, w))
            copy = cv2.warpPerspective(
                image, homography, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT_101
            )
        frames.append(relight(copy, rng, config))
    return np.stack(frames)


def random_homography(shape: tuple[int, int], rng: np.random.Generator, shift: float = 0.06) -> np.ndarray:
    """A small homography: each corner of the ``(H, W)`` frame moved by up to ``shift`` times
    the frame's width in x and its height in y.

    Returns:
        ``(3, 3)`` float64 mapping pixel coordinates ``(x, y, 1)`` of the frame to the moved one.
    """
    h, w = shape
    corners = np.float32([[0, 0], [w - 1, 0], [w - 1, h - 1], [0, h - 1]])
    moved = corners + rng.uniform(-shift, shift, (4, 2)).astype(np.float32) * np.float32([w, h])
    return cv2.getPerspectiveTransform(corners, moved).astype(np.float64)
