"""Textures for albedos and backgrounds: procedural patterns and real photographs.

Photographs come from :mod:`skimage.data`, which ships them inside the installed package
(nothing is downloaded), and only those whose licence permits any use
(:data:`SKIMAGE_PHOTOGRAPHS`), so that whatever the data engine renders carries no photograph's
terms. Every function takes a :class:`numpy.random.Generator` and is deterministic for its
state. Textures are float32 RGB arrays of shape (H, W, 3) with values in [0, 1], in *linear*
reflectance (albedo), not gamma-encoded: photographs are linearised with gamma 2.2 so that the
renderer's lighting multiplies reflectances, not display values.
"""

from __future__ import annotations

import functools
import warnings

import cv2
import numpy as np

from alcn_cv.errors import DatasetError, InputError

__all__ = [
    "display_texture",
    "SKIMAGE_PHOTOGRAPHS",
    "PROCEDURAL_KINDS",
    "skimage_photograph",
    "photos",
    "fractal_noise",
    "procedural_texture",
    "photo_crop",
    "random_texture",
    "colour_jitter",
]

#: ``skimage.data`` function -> (licence, the phrase of its docstring that states it): the
#: photographs that permit any use and load without a download. Left out: ``cat`` (the same
#: photograph as ``chelsea``), ``clock`` (public domain, but motion-blurred: its patches are
#: alike), ``moon``, ``page``, ``stereo_motorcycle`` (no licence stated), ``horse``, ``logo``,
#: ``colorwheel`` (drawings), ``microaneurysms`` (102x102), ``eagle``, ``lily``, ``skin``,
#: ``kidney`` (need a download).
SKIMAGE_PHOTOGRAPHS: dict[str, tuple[str, str]] = {
    "astronaut": ("public domain", "released into the public domain"),
    "brick": ("CC0", "Creative Commons CC0 License"),
    "camera": ("CC0", "CC0 by the photographer"),
    "cell": ("CC0", "This image is CC0"),
    "chelsea": ("CC0", "CC0 by the photographer"),
    "coffee": ("CC0", "CC0 by the photographer"),
    "coins": ("no known copyright restrictions", "No known copyright restrictions"),
    "grass": ("CC0", "Creative Commons CC0 License"),
    "gravel": ("CC0", "Creative Commons CC0 License"),
    "hubble_deep_field": ("public domain", "may be freely used in the public domain"),
    "immunohistochemistry": ("no known copyright restrictions", "No known copyright restrictions"),
    "retina": ("CC0", "CC0 1.0 Universal Public Domain Dedication"),
    "rocket": ("public domain", "released in the public domain"),
    "text": ("public domain", "released into the public domain"),
}

#: Kinds of procedural textures :func:`procedural_texture` draws from.
PROCEDURAL_KINDS: tuple[str, ...] = ("noise", "stripes", "checker", "cells", "print", "wood", "marble", "blobs")


def skimage_photograph(name: str) -> np.ndarray:
    """``skimage.data.<name>()`` for a ``name`` of :data:`SKIMAGE_PHOTOGRAPHS`: uint8 RGB (H, W, 3) or gray (H, W).

    Raises:
        InputError: ``name`` is not listed.
        DatasetError: scikit-image is missing, or the docstring no longer states the recorded licence.
    """
    try:
        import skimage.data
    except ImportError as exc:
        raise DatasetError("the scikit-image photographs need scikit-image (pip install 'alcn-cv[data]')") from exc
    if name not in SKIMAGE_PHOTOGRAPHS:
        raise InputError(f"skimage.data.{name} is not among the photographs that permit any use (SKIMAGE_PHOTOGRAPHS)")
    loader = getattr(skimage.data, name)
    phrase = SKIMAGE_PHOTOGRAPHS[name][1]
    if phrase not in " ".join((loader.__doc__ or "").split()):
        raise DatasetError(f"skimage.data.{name}'s docstring no longer says {phrase!r}; check its licence")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # skimage's deprecation notes
        image = np.asarray(loader())
    if image.dtype != np.uint8:
        raise DatasetError(f"skimage.data.{name} is {image.dtype}, not uint8")
    return image[..., :3] if image.ndim == 3 else image


@functools.lru_cache(maxsize=1)
def photos() -> tuple[np.ndarray, ...]:
    """The photographs of :data:`SKIMAGE_PHOTOGRAPHS`, in its order, as linear float32 RGB (H, W, 3) in [0, 1].

    Grayscale photographs are replicated to three channels. Cached after the first call.

    Raises:
        DatasetError: scikit-image is missing, or a docstring no longer states the recorded licence.
    """
    out = []
    for name in SKIMAGE_PHOTOGRAPHS:
        img = skimage_photograph(name)
        if img.ndim == 2:
            img = np.repeat(img[..., None], 3, axis=2)
        out.append(np.ascontiguousarray((img.astype(np.float32) / 255.0) ** 2.2))
    return tuple(out)


def fractal_noise(
    rng: np.random.Generator, shape: tuple[int, int], *, base: int = 4, octaves: int = 5, persistence: float = 0.55
) -> np.ndarray:
    """Smooth fractal (1/f-like) noise, float32 (H, W) rescaled to [0, 1].

    Sum of ``octaves`` layers of uniform noise on grids of ``base * 2**o`` cells, upsampled
    bicubically, with amplitudes ``persistence**o``.
    """
    h, w = shape
    acc = np.zeros((h, w), np.float32)
    amp = 1.0
    for o in range(octaves):
        cells = base * 2**o
        gh = max(2, int(round(cells * h / max(h, w))))
        gw = max(2, int(round(cells * w / max(h, w))))
        grid = rng.random((gh, gw), dtype=np.float32)
        acc += amp * cv2.resize(grid, (w, h), interpolation=cv2.INTER_CUBIC)
        amp *= persistence
        if cells >= max(h, w):
            break
    return cv2.normalize(acc, None, 0.0, 1.0, cv2.NORM_MINMAX)


def _height_width(size: int | tuple[int, int]) -> tuple[int, int]:
    """``(h, w)`` of a side (a NumPy integer too) or of an ``(h, w)`` pair."""
    if isinstance(size, (int, np.integer)):
        return int(size), int(size)
    h, w = size
    return int(h), int(w)


def _palette(rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` random RGB colours (n, 3) in [0.02, 0.95], varied in hue and value."""
    hsv = np.stack([rng.uniform(0, 180, n), rng.uniform(0, 255, n), rng.uniform(30, 250, n)], axis=1).astype(np.float32)
    rgb = cv2.cvtColor(hsv[None].astype(np.uint8), cv2.COLOR_HSV2RGB)[0].astype(np.float32) / 255.0
    return np.clip(rgb**2.2, 0.02, 0.95)


def _map_palette(t: np.ndarray, colours: np.ndarray) -> np.ndarray:
    """Map scalar field ``t`` in [0, 1] through a piecewise-linear colour ramp."""
    xs = np.linspace(0.0, 1.0, len(colours))
    return np.stack([np.interp(t, xs, colours[:, c]) for c in range(3)], axis=-1).astype(np.float32)


def procedural_texture(rng: np.random.Generator, size: int | tuple[int, int], kind: str | None = None) -> np.ndarray:
    """A procedural texture, float32 (H, W, 3) linear RGB in [0, 1].

    Args:
        rng: random generator.
        size: side or (height, width) in pixels.
        kind: one of :data:`PROCEDURAL_KINDS`, random when None.
    """
    h, w = _height_width(size)
    kind = kind or str(rng.choice(PROCEDURAL_KINDS))
    if kind not in PROCEDURAL_KINDS:  # before any draw
        raise InputError(f"unknown procedural texture kind {kind!r}; known: {PROCEDURAL_KINDS}")
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    colours = _palette(rng, int(rng.integers(2, 5)))
    if kind == "noise":
        t = fractal_noise(rng, (h, w), base=int(rng.integers(2, 8)), persistence=float(rng.uniform(0.4, 0.7)))
        return _map_palette(t, colours)
    if kind == "stripes":
        ang = rng.uniform(0, np.pi)
        period = rng.uniform(4, 24)
        warp = fractal_noise(rng, (h, w), base=3) * rng.uniform(0, 12)
        phase = (xx * np.cos(ang) + yy * np.sin(ang) + warp) / period
        t = 0.5 + 0.5 * np.sin(2 * np.pi * phase)
        if rng.random() < 0.5:
            t = (t > 0.5).astype(np.float32)
        return _map_palette(t, colours)
    if kind == "checker":
        cell = rng.uniform(4, 20)
        ang = rng.uniform(0, np.pi / 2)
        u = (xx * np.cos(ang) + yy * np.sin(ang)) / cell
        v = (-xx * np.sin(ang) + yy * np.cos(ang)) / cell
        t = ((np.floor(u) + np.floor(v)) % 2).astype(np.float32)
        return _map_palette(t, colours[:2])
    if kind == "cells":
        n = int(rng.integers(8, 60))
        pts = rng.uniform(0, 1, (n, 2)) * (w, h)
        labels = np.zeros((h, w), np.int32)
        best = np.full((h, w), np.inf, np.float32)
        for i, (px, py) in enumerate(pts):
            d = (xx - px) ** 2 + (yy - py) ** 2
            closer = d < best
            best[closer] = d[closer]
            labels[closer] = i
        cols = _palette(rng, n)
        img = cols[labels]
        edges = cv2.morphologyEx(labels.astype(np.float32), cv2.MORPH_GRADIENT, np.ones((3, 3), np.uint8)) > 0
        img[edges] *= rng.uniform(0.1, 0.6)
        return img.astype(np.float32)
    if kind == "print":
        # OpenCV draws text on 8-bit images only: draw gamma-encoded, then linearise.
        enc = lambda c: tuple(float(v) for v in 255.0 * c ** (1 / 2.2))  # noqa: E731
        canvas = np.empty((h, w, 3), np.uint8)
        canvas[:] = np.round(enc(colours[0]))
        for _ in range(int(rng.integers(3, 12))):
            col = enc(_palette(rng, 1)[0])
            choice = rng.integers(0, 3)
            p1 = (int(rng.integers(0, w)), int(rng.integers(0, h)))
            if choice == 0:
                text = "".join(chr(int(c)) for c in rng.integers(65, 91, int(rng.integers(1, 6))))
                cv2.putText(
                    canvas,
                    text,
                    p1,
                    int(rng.integers(0, 8)),
                    rng.uniform(0.3, 2.0) * h / 64,
                    col,
                    int(rng.integers(1, 4)),
                    cv2.LINE_AA,
                )
            elif choice == 1:
                p2 = (int(rng.integers(0, w)), int(rng.integers(0, h)))
                cv2.rectangle(canvas, p1, p2, col, -1 if rng.random() < 0.6 else int(rng.integers(1, 4)), cv2.LINE_AA)
            else:
                cv2.circle(
                    canvas, p1, int(rng.integers(2, max(3, h // 3))), col, -1 if rng.random() < 0.6 else 2, cv2.LINE_AA
                )
        return (canvas.astype(np.float32) / 255.0) ** 2.2
    if kind == "wood":
        cx, cy = rng.uniform(-w, 2 * w), rng.uniform(-h, 2 * h)
        r = np.sqrt((xx - cx) ** 2 + ((yy - cy) * rng.uniform(0.2, 1.0)) ** 2)
        r += fractal_noise(rng, (h, w), base=4) * rng.uniform(2, 10)
        t = 0.5 + 0.5 * np.sin(r / rng.uniform(1.5, 6.0))
        return _map_palette(t**1.5, colours[:2])
    if kind == "marble":
        n = fractal_noise(rng, (h, w), base=3, octaves=6)
        ang = rng.uniform(0, np.pi)
        t = 0.5 + 0.5 * np.sin((xx * np.cos(ang) + yy * np.sin(ang)) / rng.uniform(6, 20) + 8 * n)
        return _map_palette(t, colours)
    # blobs
    t = fractal_noise(rng, (h, w), base=int(rng.integers(3, 10)), persistence=0.3)
    t = (t > rng.uniform(0.35, 0.65)).astype(np.float32)
    t = cv2.GaussianBlur(t, (0, 0), 0.7)
    return _map_palette(t, colours[:2])


def colour_jitter(rng: np.random.Generator, img: np.ndarray, strength: float = 1.0) -> np.ndarray:
    """Random per-channel gains, saturation change and occasional inversion (float32 RGB)."""
    gains = np.exp(rng.normal(0, 0.25 * strength, 3)).astype(np.float32)
    out = img * gains
    grey = out.mean(axis=2, keepdims=True)
    sat = np.float32(rng.uniform(1 - 0.8 * strength, 1 + 0.6 * strength))
    out = grey + sat * (out - grey)
    if rng.random() < 0.15 * strength:
        out = 1.0 - out
    return np.clip(out, 0.0, 1.0).astype(np.float32)


def photo_crop(rng: np.random.Generator, size: int | tuple[int, int]) -> np.ndarray:
    """A random crop of a random :func:`photos` photograph, float32 (H, W, 3) linear RGB.

    The crop has random scale (0.25x to 1.5x, more for outputs larger than the photograph),
    rotation by multiples of 90 degrees (square outputs only) and flips.

    Args:
        rng: random generator.
        size: side or (height, width) of the output.
    """
    h, w = _height_width(size)
    pool = photos()
    img = pool[int(rng.integers(len(pool)))]
    # Outputs larger than the photograph magnify a random part of it (between 1x and 3x the
    # smallest magnification that fits), so large scenes still get varied crops.
    lo = max(0.25, h / img.shape[0], w / img.shape[1])
    hi = max(1.5, 3.0 * lo)
    scale = float(np.exp(rng.uniform(np.log(lo), np.log(hi))))
    ch, cw = min(img.shape[0], int(h / scale) + 1), min(img.shape[1], int(w / scale) + 1)
    y0 = int(rng.integers(0, img.shape[0] - ch + 1))
    x0 = int(rng.integers(0, img.shape[1] - cw + 1))
    interp = cv2.INTER_AREA if scale < 1 else cv2.INTER_CUBIC
    crop = np.clip(cv2.resize(img[y0 : y0 + ch, x0 : x0 + cw], (w, h), interpolation=interp), 0.0, 1.0)
    crop = np.rot90(crop, int(rng.integers(4))) if h == w else crop
    if rng.random() < 0.5:
        crop = crop[:, ::-1]
    return np.ascontiguousarray(crop, dtype=np.float32)


def random_texture(rng: np.random.Generator, size: int | tuple[int, int], *, p_photo: float = 0.5) -> np.ndarray:
    """A photograph crop (probability ``p_photo``) or a procedural texture, colour-jittered."""
    if rng.random() < p_photo:
        return colour_jitter(rng, photo_crop(rng, size), 0.6)
    return procedural_texture(rng, size)


def display_texture(rng: np.random.Generator, size: int | tuple[int, int], *, p_photo: float = 0.5) -> np.ndarray:
    """:func:`random_texture` gamma-encoded (1/2.2) to display values, as a photograph stores
    them, in luma: float32 ``(h, w)`` in [0, 1]."""
    bgr = np.ascontiguousarray(random_texture(rng, size, p_photo=p_photo)[..., ::-1] ** (1 / 2.2), dtype=np.float32)
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
