"""Lighting conditions of the data engine: light sources, lighting families and their sampling.

A :class:`Lighting` is one lighting condition: its lights (directional, point and spot), an
ambient term, and the camera's response (exposure gain, gamma, sensor noise, gradient, hard
cast-shadow shape, motion blur) that :func:`alcn_cv.data.render.expose` applies. Point and spot
lights fall off as ``1 / (1 + (d / range)**2)``; spots have a smooth cone.

Lighting *families* (:data:`LIGHT_FAMILIES`) group the conditions of the paper's Fig. 1 and
Fig. 4 so that validation can hold some out: ``ambient`` (the reference, training-like light),
``dark``, ``bright`` (over-exposed, saturated), ``side`` (grazing directional light at 15-35
degrees elevation), ``shadow`` (hard cast shadow shapes and a strong gradient), ``spot``,
``point``, ``colour`` (several coloured lights) and ``mixed`` (random combinations of all).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from alcn_cv.errors import InputError

__all__ = [
    "Light",
    "directional",
    "LightArrays",
    "Lighting",
    "LIGHT_FAMILIES",
    "sample_lighting",
    "SHADOW_SHAPES",
    "shadow_shape",
]


@dataclass(frozen=True)
class Light:
    """One light source, in the scene's units (pixels for height fields, mm for meshes).

    Attributes:
        kind: ``"directional"``, ``"point"`` or ``"spot"``.
        vector: for ``directional``, the unit direction *towards* the light; otherwise its
            position (x, y, z).
        colour: linear RGB colour times intensity (3,), >= 0.
        range: distance at which point and spot lights fall to half intensity (inf: none).
        spot_direction: unit axis of a spot's cone (pointing away from the light).
        cone_deg: half-angle of the cone's outer edge in degrees.
        penumbra_deg: width of the cone's soft edge in degrees.
    """

    kind: str
    vector: tuple[float, float, float]
    colour: tuple[float, float, float] = (1.0, 1.0, 1.0)
    range: float = float("inf")
    spot_direction: tuple[float, float, float] = (0.0, 0.0, -1.0)
    cone_deg: float = 30.0
    penumbra_deg: float = 8.0

    def __post_init__(self) -> None:
        if self.kind not in ("directional", "point", "spot"):
            raise InputError(f"unknown light kind {self.kind!r}; use directional, point or spot")


def directional(azimuth_deg: float, elevation_deg: float, colour: Sequence[float] = (1.0, 1.0, 1.0)) -> Light:
    """A directional light from azimuth (degrees, 0 = +x, 90 = +y) and elevation above the plane."""
    a, e = np.deg2rad(azimuth_deg), np.deg2rad(elevation_deg)
    v = (float(np.cos(e) * np.cos(a)), float(np.cos(e) * np.sin(a)), float(np.sin(e)))
    return Light("directional", v, tuple(float(c) for c in colour))


@dataclass
class LightArrays:
    """Lights of a batch packed for vectorised shading; B items, L light slots each.

    Unused slots have zero colour. ``w`` is 0 for directional lights (``pos`` is then the
    direction towards the light) and 1 for point and spot lights.
    """

    pos: np.ndarray  # (B, L, 3) float32
    w: np.ndarray  # (B, L)
    colour: np.ndarray  # (B, L, 3)
    inv_range2: np.ndarray  # (B, L): 1 / range**2 (0: no fall-off)
    spot_dir: np.ndarray  # (B, L, 3)
    cos_outer: np.ndarray  # (B, L)
    cos_inner: np.ndarray  # (B, L)

    @classmethod
    def pack(cls, lights: Sequence[Sequence[Light]]) -> LightArrays:
        """Pack one list of lights per batch item."""
        b = len(lights)
        n = max(1, max(len(ls) for ls in lights))
        pos = np.zeros((b, n, 3), np.float32)
        pos[..., 2] = 1.0
        w = np.zeros((b, n), np.float32)
        colour = np.zeros((b, n, 3), np.float32)
        inv_r2 = np.zeros((b, n), np.float32)
        spot = np.zeros((b, n, 3), np.float32)
        spot[..., 2] = -1.0
        co = np.full((b, n), -3.0, np.float32)
        ci = np.full((b, n), -2.0, np.float32)
        for i, ls in enumerate(lights):
            for j, li in enumerate(ls):
                v = np.asarray(li.vector, np.float64)
                if li.kind == "directional":
                    pos[i, j] = v / np.linalg.norm(v)
                else:
                    pos[i, j] = v
                    w[i, j] = 1.0
                    inv_r2[i, j] = 0.0 if not np.isfinite(li.range) else 1.0 / li.range**2
                colour[i, j] = li.colour
                if li.kind == "spot":
                    d = np.asarray(li.spot_direction, np.float64)
                    spot[i, j] = d / np.linalg.norm(d)
                    co[i, j] = np.cos(np.deg2rad(li.cone_deg))
                    ci[i, j] = np.cos(np.deg2rad(max(li.cone_deg - li.penumbra_deg, 0.0)))
        return cls(pos, w, colour, inv_r2, spot, co, ci)


@dataclass
class Lighting:
    """One sampled lighting condition: lights plus the camera's response to them.

    Attributes:
        family: name in :data:`LIGHT_FAMILIES`.
        lights: the light sources.
        ambient: linear RGB ambient light (3,).
        gain: exposure gain (radiance 1 times gain 1 maps to white).
        gamma: encoding exponent applied as ``out = in ** (1 / gamma)`` (2.2 nominal).
        shot_noise: variance of the shot noise per unit linear intensity.
        read_noise: standard deviation of the read noise, in linear units.
        gradient: (gx, gy) log-gain change across the image (multiplies by ``exp(g . u)``,
            ``u`` the position in image halves, -1..1), or zeros.
        shadow_shape: kind of hard-edged cast-shadow shape on light 0 (see :func:`shadow_shape`)
            or None.
        motion_blur: (length px, angle deg) or None.
    """

    family: str
    lights: list[Light]
    ambient: np.ndarray
    gain: float = 1.0
    gamma: float = 2.2
    shot_noise: float = 0.0
    read_noise: float = 0.0
    gradient: tuple[float, float] = (0.0, 0.0)
    shadow_shape: str | None = None
    motion_blur: tuple[float, float] | None = None

    def describe(self) -> dict:
        """A JSON-serialisable summary (family, light kinds and directions, gain ...)."""
        return {
            "family": self.family,
            "lights": [
                {
                    "kind": li.kind,
                    "vector": [round(float(v), 4) for v in li.vector],
                    "colour": [round(float(c), 4) for c in li.colour],
                }
                for li in self.lights
            ],
            "ambient": [round(float(a), 4) for a in self.ambient],
            "gain": round(float(self.gain), 4),
            "gamma": round(float(self.gamma), 4),
            "gradient": [round(float(g), 4) for g in self.gradient],
            "shadow_shape": self.shadow_shape,
            "motion_blur": None if self.motion_blur is None else [round(float(v), 3) for v in self.motion_blur],
        }


#: Lighting families, in the order of their integer ids (``light_ids`` of the Phos windows).
LIGHT_FAMILIES: tuple[str, ...] = ("ambient", "dark", "bright", "side", "shadow", "spot", "point", "colour", "mixed")


def _light_colour(rng: np.random.Generator, saturation: float) -> np.ndarray:
    """A light colour of unit luminance: white at saturation 0, vivid hues at 1."""
    hue = rng.uniform(0, 2 * np.pi)
    c = 1.0 + saturation * np.array([np.cos(hue), np.cos(hue - 2.094), np.cos(hue + 2.094)])
    c = np.clip(c, 0.05, None)
    return c / (0.299 * c[0] + 0.587 * c[1] + 0.114 * c[2])


def _warm_cool(rng: np.random.Generator, amount: float = 0.12) -> np.ndarray:
    """A near-white light colour (tungsten to daylight) of unit luminance."""
    t = rng.uniform(-1, 1) * amount
    c = np.array([1 + t, 1.0, 1 - t])
    return c / (0.299 * c[0] + 0.587 * c[1] + 0.114 * c[2])


def sample_lighting(
    rng: np.random.Generator,
    family: str,
    width: float,
    height: float,
    *,
    relief: float = 8.0,
) -> Lighting:
    """Draw a lighting condition of ``family`` for a scene of ``width x height`` pixels.

    Args:
        rng: random generator.
        family: one of :data:`LIGHT_FAMILIES`.
        width, height: scene size in pixels (point and spot lights are placed relative to it and
            aim around its centre).
        relief: height of the relief in pixels; point and spot lights are raised by it so that
            they stay above the tallest object.

    Returns:
        A :class:`Lighting`. Intensities are scaled so that a white Lambertian surface facing
        the main light has a radiance of about 1 before the family's exposure gain.
    """
    if family not in LIGHT_FAMILIES:
        raise InputError(f"unknown lighting family {family!r}; known: {LIGHT_FAMILIES}")
    size = float(max(width, height))
    cx, cy = width / 2.0, height / 2.0
    az = rng.uniform(0, 360)
    lights: list[Light] = []
    ambient = np.full(3, rng.uniform(0.1, 0.3))
    gain = float(np.exp(rng.uniform(np.log(0.7), np.log(1.3))))
    gradient = (0.0, 0.0)
    shape = None
    blur = None

    def point_like(kind: str, dist_lo: float, dist_hi: float, colour: np.ndarray) -> Light:
        elev = np.deg2rad(rng.uniform(20, 80))
        d = rng.uniform(dist_lo, dist_hi) * size
        a = np.deg2rad(rng.uniform(0, 360))
        pos = (cx + d * np.cos(elev) * np.cos(a), cy + d * np.cos(elev) * np.sin(a), d * np.sin(elev) + relief)
        # Fall-off normalised so the point of interest receives about ``colour``.
        rng_ = d * rng.uniform(0.3, 1.0)
        scale = 1.0 + (d / rng_) ** 2
        target = np.array([cx + rng.normal(0, 0.25) * size, cy + rng.normal(0, 0.25) * size, 0.0])
        axis = target - np.array(pos)
        cone = rng.uniform(10, 35)
        return Light(
            kind,
            tuple(float(p) for p in pos),
            tuple(float(c) for c in colour * scale),
            float(rng_),
            tuple(float(a) for a in axis / np.linalg.norm(axis)),
            float(cone),
            float(rng.uniform(0.1, 0.6) * cone),
        )

    if family in ("ambient", "dark", "bright"):
        lights.append(directional(az, rng.uniform(50, 90), _warm_cool(rng) * rng.uniform(0.7, 1.0)))
        if family == "dark":
            gain = float(np.exp(rng.uniform(np.log(0.05), np.log(0.3))))
        elif family == "bright":
            gain = float(np.exp(rng.uniform(np.log(2.0), np.log(4.0))))
    elif family == "side":
        lights.append(directional(az, rng.uniform(15, 35), _warm_cool(rng) * rng.uniform(1.0, 1.6)))
        ambient = np.full(3, rng.uniform(0.01, 0.12))
    elif family == "shadow":
        lights.append(directional(az, rng.uniform(25, 80), _warm_cool(rng) * rng.uniform(0.9, 1.4)))
        ambient = np.full(3, rng.uniform(0.03, 0.2))
        shape = str(rng.choice(SHADOW_SHAPES))
        g = rng.uniform(1.0, 2.5)
        ga = rng.uniform(0, 2 * np.pi)
        gradient = (float(g * np.cos(ga)), float(g * np.sin(ga)))
    elif family == "spot":
        lights.append(point_like("spot", 0.6, 2.0, _warm_cool(rng, 0.2) * rng.uniform(1.0, 2.0)))
        ambient = np.full(3, rng.uniform(0.02, 0.15))
    elif family == "point":
        lights.append(point_like("point", 0.3, 1.5, _warm_cool(rng, 0.2) * rng.uniform(0.8, 1.6)))
        ambient = np.full(3, rng.uniform(0.02, 0.15))
    elif family == "colour":
        for _ in range(int(rng.integers(2, 4))):
            lights.append(
                directional(
                    rng.uniform(0, 360),
                    rng.uniform(20, 85),
                    _light_colour(rng, rng.uniform(0.5, 1.0)) * rng.uniform(0.4, 0.9),
                )
            )
        ambient = _light_colour(rng, rng.uniform(0.0, 0.8)) * rng.uniform(0.05, 0.25)
    else:  # mixed
        for _ in range(int(rng.integers(1, 4))):
            kind = str(rng.choice(["directional", "point", "spot"]))
            colour = _light_colour(rng, rng.uniform(0.0, 0.7)) * rng.uniform(0.4, 1.2)
            if kind == "directional":
                lights.append(directional(rng.uniform(0, 360), rng.uniform(12, 90), colour))
            else:
                lights.append(point_like(kind, 0.3, 2.0, colour))
        ambient = _light_colour(rng, rng.uniform(0.0, 0.5)) * rng.uniform(0.0, 0.3)
        gain = float(np.exp(rng.uniform(np.log(0.08), np.log(3.5))))
        if rng.random() < 0.3:
            shape = str(rng.choice(SHADOW_SHAPES))
        if rng.random() < 0.5:
            g = rng.uniform(0.3, 2.0)
            ga = rng.uniform(0, 2 * np.pi)
            gradient = (float(g * np.cos(ga)), float(g * np.sin(ga)))
    if rng.random() < 0.05:
        blur = (float(rng.uniform(1.5, 5.0)), float(rng.uniform(0, 180)))
    return Lighting(
        family=family,
        lights=lights,
        ambient=np.asarray(ambient, np.float32),
        gain=gain,
        gamma=float(2.2 * np.exp(rng.uniform(np.log(0.75), np.log(1.3)))),
        shot_noise=float(np.exp(rng.uniform(np.log(2e-4), np.log(4e-3)))),
        read_noise=float(np.exp(rng.uniform(np.log(5e-4), np.log(6e-3)))),
        gradient=gradient,
        shadow_shape=shape,
        motion_blur=blur,
    )


#: Kinds of hard-edged cast-shadow shapes of :func:`shadow_shape`.
SHADOW_SHAPES: tuple[str, ...] = ("edge", "polygon", "blinds", "window", "blob")


def shadow_shape(rng: np.random.Generator, shape: tuple[int, int], kind: str, *, penumbra: float = 1.0) -> np.ndarray:
    """A hard-edged shadow cast by an out-of-view occluder, float32 (H, W), 1 = lit, 0 = shadow.

    Kinds: ``edge`` (a straight shadow edge), ``polygon`` (a random polygon), ``blinds``
    (parallel bars), ``window`` (a window frame's cross), ``blob`` (foliage-like). The edge is
    blurred by a Gaussian of ``penumbra`` pixels.
    """
    h, w = shape
    m = np.ones((h, w), np.float32)
    s = max(h, w)
    if kind == "edge":
        a = rng.uniform(0, 2 * np.pi)
        yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
        off = rng.uniform(-0.3, 0.3) * s
        m[((xx - w / 2) * np.cos(a) + (yy - h / 2) * np.sin(a)) > off] = 0
    elif kind == "polygon":
        n = int(rng.integers(3, 7))
        c = rng.uniform(0.2, 0.8, 2) * (w, h)
        r = rng.uniform(0.3, 0.8) * s
        ang = np.sort(rng.uniform(0, 2 * np.pi, n))
        pts = np.stack(
            [c[0] + r * np.cos(ang) * rng.uniform(0.5, 1.5, n), c[1] + r * np.sin(ang) * rng.uniform(0.5, 1.5, n)], 1
        )
        cv2.fillPoly(m, [np.round(pts * 16).astype(np.int32)], 0.0, cv2.LINE_AA, 4)
    elif kind in ("blinds", "window"):
        a = rng.uniform(0, np.pi)
        yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
        period = rng.uniform(0.15, 0.5) * s
        duty = rng.uniform(0.2, 0.6)
        u = (xx * np.cos(a) + yy * np.sin(a)) / period + rng.uniform(0, 1)
        m[(u - np.floor(u)) < duty] = 0
        if kind == "window":
            v = (-xx * np.sin(a) + yy * np.cos(a)) / period + rng.uniform(0, 1)
            m[(v - np.floor(v)) < duty * 0.5] = 0
    elif kind == "blob":
        from alcn_cv.data.textures import fractal_noise

        n = fractal_noise(rng, (h, w), base=3, octaves=4)
        m[n > rng.uniform(0.4, 0.6)] = 0
    else:
        raise InputError(f"unknown shadow shape {kind!r}; known: {SHADOW_SHAPES}")
    if penumbra > 0:
        m = cv2.GaussianBlur(m, (0, 0), penumbra)
    return m
