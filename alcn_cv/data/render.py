"""Light, materials, shading, shadows and camera effects of the data engine.

The renderer is a vectorised numpy/OpenCV shader that works on batches of *G-buffers*: per
pixel a 3D position ``P``, a unit normal ``N``, a unit direction to the viewer ``V``, a linear
RGB albedo and a vector of material parameters (:data:`MATERIAL_FIELDS`). Two kinds of
G-buffers feed it:

- 2.5D *height fields* (:class:`Surface`): a textured plane seen from above whose relief is a
  height map, in pixel units (x right, y down, z up towards the viewer). Directional light then
  makes self-shading and cast shadows as on real objects on a table; this renders the
  Normalizer's training windows and the detection benchmark's scenes.
- Rasterised triangle meshes (:mod:`alcn_cv.data.raster`), for the pose sequences.

Reflectance (per light, all terms multiplied by the light's colour, fall-off, spot cone and
shadow visibility)::

    diffuse  = kd * albedo * ((1 - f) * max(n.l, 0) + f * sqrt(max(n.l, 0)))    f = "flatten"
    specular = ks * mix(1, albedo, metallic) * (s + 8) / 16 * max(n.h, 0)**s        (Blinn-Phong)
    sheen    = sheen * mix(1, albedo, 0.5) * (sqrt(max(n.l, 0)) * 2 (1 - n.v)**2 + (1 - l.h)**5)

``flatten`` and ``sheen`` give a velvet-like look (a soft, flat fall-off and bright rims and
grazing light, neither Lambertian nor specular; after Koenderink & Pont's and Ashikhmin's
velvet models); metals have strong, tight, albedo-tinted highlights. Point and spot lights fall
off as ``1 / (1 + (d / range)**2)``; spots have a smooth cone. Height fields also get an
ambient-occlusion term (crevices receive less ambient light). The camera model applies an
exposure gain, signal-dependent sensor noise (shot + read noise, in linear units), clipping
(saturation), a gamma curve, optional motion blur and 8-bit quantisation.

Lighting *families* (:data:`LIGHT_FAMILIES`) group the conditions of the paper's Fig. 1 and
Fig. 4 so that validation can hold some out: ``ambient`` (the reference, training-like light),
``dark``, ``bright`` (over-exposed, saturated), ``side`` (grazing directional light at 15-35
degrees elevation), ``shadow`` (hard cast shadow shapes and a strong gradient), ``spot``,
``point``, ``colour`` (several coloured lights) and ``mixed`` (random combinations of all).
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass
from typing import Sequence

import cv2
import numpy as np

from alcn_cv.errors import InputError

logger = logging.getLogger(__name__)

__all__ = [
    "MATERIAL_FIELDS",
    "Material",
    "MATERIALS",
    "sample_material",
    "Light",
    "directional",
    "LightArrays",
    "Lighting",
    "LIGHT_FAMILIES",
    "sample_lighting",
    "Surface",
    "heightfield_geometry",
    "heightfield_shadows",
    "shadow_shape",
    "shade",
    "expose",
    "render_surfaces",
]

#: Order of the per-pixel material parameters in :attr:`Surface.material`.
MATERIAL_FIELDS: tuple[str, ...] = ("diffuse", "specular", "shininess", "sheen", "flatten", "metallic")


@dataclass(frozen=True)
class Material:
    """Reflectance parameters of one material (see the module docstring for the model).

    Attributes:
        name: family name (``matte``, ``plastic``, ``velvet`` or ``metal``).
        diffuse: diffuse gain kd (0-1).
        specular: Blinn-Phong gain ks (0-2).
        shininess: Blinn-Phong exponent s (1-500).
        sheen: velvet sheen gain (0-1).
        flatten: 0 = Lambertian fall-off, 1 = flat sqrt fall-off (velvet).
        metallic: 0 = white highlights, 1 = highlights tinted by the albedo.
    """

    name: str
    diffuse: float = 1.0
    specular: float = 0.0
    shininess: float = 10.0
    sheen: float = 0.0
    flatten: float = 0.0
    metallic: float = 0.0

    def vector(self) -> np.ndarray:
        """The parameters in :data:`MATERIAL_FIELDS` order, float32 (6,)."""
        return np.array([getattr(self, f) for f in MATERIAL_FIELDS], np.float32)


#: Reference materials; :func:`sample_material` jitters them.
MATERIALS: dict[str, Material] = {
    "matte": Material("matte", diffuse=1.0, specular=0.02, shininess=6.0),
    "plastic": Material("plastic", diffuse=0.9, specular=0.3, shininess=40.0),
    "velvet": Material("velvet", diffuse=0.8, specular=0.0, shininess=1.0, sheen=0.5, flatten=0.8),
    "metal": Material("metal", diffuse=0.25, specular=0.6, shininess=200.0, metallic=0.85),
}


def sample_material(rng: np.random.Generator, name: str | None = None) -> Material:
    """A random material of family ``name`` (random family when None), parameters jittered."""
    name = name or str(rng.choice(list(MATERIALS)))
    if name not in MATERIALS:
        raise InputError(f"unknown material {name!r}; known: {sorted(MATERIALS)}")
    m = MATERIALS[name]
    j = lambda v, r: float(v * np.exp(rng.uniform(-r, r)))  # noqa: E731
    return dataclasses.replace(
        m,
        diffuse=min(1.0, j(m.diffuse, 0.15)),
        specular=j(m.specular, 0.5),
        shininess=j(m.shininess, 0.5),
        sheen=j(m.sheen, 0.4),
        flatten=float(np.clip(m.flatten + rng.uniform(-0.15, 0.15), 0, 1)) if m.flatten else 0.0,
    )


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
    def pack(cls, lights: Sequence[Sequence[Light]]) -> "LightArrays":
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
                {"kind": li.kind, "vector": [round(float(v), 4) for v in li.vector],
                 "colour": [round(float(c), 4) for c in li.colour]}
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
    centre: tuple[float, float] | None = None,
    relief: float = 8.0,
) -> Lighting:
    """Draw a lighting condition of ``family`` for a scene of ``width x height`` pixels.

    Args:
        rng: random generator.
        family: one of :data:`LIGHT_FAMILIES`.
        width, height: scene size in pixels (point and spot lights are placed relative to it).
        centre: point of interest (x, y) that spots and point lights aim around; the scene
            centre when None.
        relief: height of the relief in pixels; point and spot lights are raised by it so that
            they stay above the tallest object.

    Returns:
        A :class:`Lighting`. Intensities are scaled so that a white Lambertian surface facing
        the main light has a radiance of about 1 before the family's exposure gain.
    """
    if family not in LIGHT_FAMILIES:
        raise InputError(f"unknown lighting family {family!r}; known: {LIGHT_FAMILIES}")
    size = float(max(width, height))
    cx, cy = centre if centre is not None else (width / 2.0, height / 2.0)
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
        return Light(kind, tuple(float(p) for p in pos), tuple(float(c) for c in colour * scale), float(rng_),
                     tuple(float(a) for a in axis / np.linalg.norm(axis)), float(cone),
                     float(rng.uniform(0.1, 0.6) * cone))

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
            lights.append(directional(rng.uniform(0, 360), rng.uniform(20, 85),
                                      _light_colour(rng, rng.uniform(0.5, 1.0)) * rng.uniform(0.4, 0.9)))
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


@dataclass
class Surface:
    """A batch of 2.5D height-field scenes (the G-buffer source of :func:`render_surfaces`).

    Attributes:
        albedo: float32 (B, H, W, 3) linear RGB reflectance in [0, 1].
        height: float32 (B, H, W) relief height in pixels (z towards the viewer).
        material: float32 (B, H, W, 6) per-pixel :data:`MATERIAL_FIELDS`.
    """

    albedo: np.ndarray
    height: np.ndarray
    material: np.ndarray


def heightfield_geometry(height: np.ndarray, camera: tuple[float, float, float] | None = None):
    """Positions, normals and view directions of height fields.

    Args:
        height: float32 (B, H, W) heights in pixels.
        camera: viewer position (x, y, z) in pixels for perspective view directions; None for
            an orthographic viewer straight above.

    Returns:
        ``(P, N, V)``: float32 (B, H, W, 3) positions, unit normals and unit view directions
        (V is (1, 1, 1, 3) for the orthographic viewer).
    """
    b, h, w = height.shape
    gy, gx = np.gradient(height, axis=(1, 2))
    inv = 1.0 / np.sqrt(gx * gx + gy * gy + 1.0)
    N = np.stack([-gx * inv, -gy * inv, inv], axis=-1).astype(np.float32)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    P = np.stack([np.broadcast_to(xx, (b, h, w)), np.broadcast_to(yy, (b, h, w)), height], axis=-1)
    if camera is None:
        V = np.array([0, 0, 1], np.float32).reshape(1, 1, 1, 3)
    else:
        V = np.asarray(camera, np.float32) - P
        V /= np.linalg.norm(V, axis=-1, keepdims=True)
    return P, N, V


def heightfield_shadows(
    height: np.ndarray, lights: LightArrays, *, steps: int = 12, max_dist: float | None = None, softness: float = 0.7
) -> np.ndarray:
    """Cast and self shadows of height fields by marching towards each light.

    A pixel is shadowed from a light when the relief along the ray towards it rises above the
    ray (nearest-neighbour samples at ``steps`` equally spaced horizontal distances up to
    ``max_dist``; the occlusion fades over ``softness`` pixels of height, which gives a narrow
    penumbra).

    Args:
        height: float32 (B, H, W) heights in pixels.
        lights: packed lights of the batch.
        steps: samples per ray.
        max_dist: longest shadow in pixels; default ``max(H, W) / 2``.
        softness: height difference (px) over which occlusion goes from 0 to 1.

    Returns:
        float32 (B, L, H, W) visibility in [0, 1] (1 = lit).
    """
    b, h, w = height.shape
    nl = lights.pos.shape[1]
    max_dist = float(max_dist or max(h, w) / 2)
    step = max_dist / steps
    hflat = height.reshape(-1)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    base = (np.arange(b, dtype=np.int64) * (h * w)).reshape(b, 1, 1)
    hrange = float(height.max() - height.min()) if height.size else 0.0
    vis = np.ones((b, nl, h, w), np.float32)
    if hrange < 1e-3:
        return vis
    for li in range(nl):
        active = np.any(lights.colour[:, li] > 0, axis=-1)
        if not active.any():
            continue
        pos = lights.pos[:, li].reshape(b, 1, 1, 3)
        wgt = lights.w[:, li].reshape(b, 1, 1)
        lx = pos[..., 0] - wgt * xx
        ly = pos[..., 1] - wgt * yy
        lz = pos[..., 2] - wgt * height
        hl = np.sqrt(lx * lx + ly * ly) + 1e-6
        dx, dy, slope = lx / hl, ly / hl, lz / hl
        # Point lights: stop at the light's horizontal distance; directional: never.
        reach = np.where(wgt > 0, hl, np.inf)
        occ = np.zeros((b, h, w), np.float32)
        min_slope = float(np.min(np.where(active.reshape(b, 1, 1), slope, np.inf)))
        for k in range(1, steps + 1):
            d = k * step
            if min_slope * d > hrange:
                break
            sx = np.rint(xx + dx * d).astype(np.int64)
            sy = np.rint(yy + dy * d).astype(np.int64)
            inside = (sx >= 0) & (sx < w) & (sy >= 0) & (sy < h) & (d < reach)
            np.clip(sx, 0, w - 1, out=sx)
            np.clip(sy, 0, h - 1, out=sy)
            hs = hflat[base + sy * w + sx]
            o = np.clip((hs - height - slope * d) / softness, 0.0, 1.0) * inside
            np.maximum(occ, o, out=occ)
        vis[:, li] = 1.0 - occ
    return vis


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
        pts = np.stack([c[0] + r * np.cos(ang) * rng.uniform(0.5, 1.5, n),
                        c[1] + r * np.sin(ang) * rng.uniform(0.5, 1.5, n)], 1)
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


def shade(
    P: np.ndarray,
    N: np.ndarray,
    V: np.ndarray,
    albedo: np.ndarray,
    material: np.ndarray,
    lights: LightArrays,
    ambient: np.ndarray,
    visibility: np.ndarray | None = None,
    ambient_occlusion: np.ndarray | None = None,
) -> np.ndarray:
    """Radiance of a batch of G-buffers (see the module docstring for the model).

    Args:
        P: float32 (B, H, W, 3) positions.
        N: float32 (B, H, W, 3) unit normals.
        V: float32 (B, H, W, 3) or broadcastable unit directions to the viewer.
        albedo: float32 (B, H, W, 3) linear RGB in [0, 1].
        material: float32 (B, H, W, 6) :data:`MATERIAL_FIELDS`.
        lights: packed lights (B items, L slots).
        ambient: float32 (B, 3) ambient light.
        visibility: float32 (B, L, H, W) shadow visibility, or None (all lit).
        ambient_occlusion: float32 (B, H, W) ambient occlusion in [0, 1], or None.

    Returns:
        float32 (B, H, W, 3) linear radiance (unbounded; the camera clips it).
    """
    comp = lambda x: [np.ascontiguousarray(x[..., i], dtype=np.float32) for i in range(3)]  # noqa: E731
    px, py, pz = comp(P)
    nx, ny, nz = comp(N)
    vx, vy, vz = comp(V)
    kd, ks, shin, sheen, flat, metal = (np.ascontiguousarray(material[..., i]) for i in range(6))
    alb = comp(albedo)
    amb = np.asarray(ambient, np.float32).reshape(-1, 3)
    ao = np.float32(1.0) if ambient_occlusion is None else ambient_occlusion
    out = [amb[:, c].reshape(-1, 1, 1) * alb[c] * ao for c in range(3)]
    nv = np.clip(nx * vx + ny * vy + nz * vz, 0.0, 1.0)
    rim = 2.0 * (1.0 - nv) ** 2
    any_spec = bool(np.any(ks > 0))
    any_sheen = bool(np.any(sheen > 0))
    any_metal = bool(np.any(metal > 0))
    shp = (-1, 1, 1)
    for li in range(lights.pos.shape[1]):
        active = np.any(lights.colour[:, li] > 0, axis=1)
        if not active.any():
            continue
        # Shade only the items that have a light in this slot (slots 2 and 3 are often empty).
        sel = slice(None) if active.all() else np.nonzero(active)[0]

        def g(a):
            return a if a.shape[0] == 1 else a[sel]

        Px, Py, Pz, Nx, Ny, Nz, Vx, Vy, Vz = (g(a) for a in (px, py, pz, nx, ny, nz, vx, vy, vz))
        Kd, Ks, Shin, Sheen, Flat, Metal, Rim = (g(a) for a in (kd, ks, shin, sheen, flat, metal, rim))
        Alb = [g(a) for a in alb]
        col = lights.colour[sel, li]
        w = lights.w[sel, li].reshape(shp)
        lx = lights.pos[sel, li, 0].reshape(shp) - w * Px
        ly = lights.pos[sel, li, 1].reshape(shp) - w * Py
        lz = lights.pos[sel, li, 2].reshape(shp) - w * Pz
        d2 = lx * lx + ly * ly + lz * lz
        inv = 1.0 / np.sqrt(d2)
        lx *= inv
        ly *= inv
        lz *= inv
        factor = None
        if np.any(lights.inv_range2[sel, li] > 0):
            factor = 1.0 / (1.0 + d2 * lights.inv_range2[sel, li].reshape(shp))
        if np.any(lights.cos_outer[sel, li] > -1.0):
            sd = lights.spot_dir[sel, li]
            cos_a = -(lx * sd[:, 0].reshape(shp) + ly * sd[:, 1].reshape(shp) + lz * sd[:, 2].reshape(shp))
            co = lights.cos_outer[sel, li].reshape(shp)
            ci = lights.cos_inner[sel, li].reshape(shp)
            t = np.clip((cos_a - co) / np.maximum(ci - co, 1e-6), 0.0, 1.0)
            cone = t * t * (3.0 - 2.0 * t)
            factor = cone if factor is None else factor * cone
        if visibility is not None:
            vis = visibility[sel, li]
            factor = vis if factor is None else factor * vis
        nl = np.maximum(Nx * lx + Ny * ly + Nz * lz, 0.0)
        snl = np.sqrt(nl)
        diff = Kd * (nl + Flat * (snl - nl))
        spec = sh = None
        if any_spec or any_sheen:
            hx, hy, hz = lx + Vx, ly + Vy, lz + Vz
            hinv = 1.0 / (np.sqrt(hx * hx + hy * hy + hz * hz) + 1e-12)
            lit = nl > 0
        if any_spec:
            nh = np.clip((Nx * hx + Ny * hy + Nz * hz) * hinv, 0.0, 1.0)
            spec = Ks * (Shin + 8.0) / 16.0 * np.power(nh, Shin) * lit
        if any_sheen:
            lh = np.clip((lx * hx + ly * hy + lz * hz) * hinv, 0.0, 1.0)
            gl = 1.0 - lh
            gl2 = gl * gl
            sh = Sheen * (snl * Rim + gl2 * gl2 * gl * lit)
        for c in range(3):
            term = Alb[c] * diff
            if spec is not None:
                term += (spec * (1.0 - Metal + Metal * Alb[c])) if any_metal else spec
            if sh is not None:
                term += sh * (0.5 + 0.5 * Alb[c])
            scale = col[:, c].reshape(shp)
            contrib = (term * scale) if factor is None else term * (factor * scale)
            if isinstance(sel, slice):
                out[c] += contrib
            else:
                out[c][sel] += contrib
    return np.stack(out, axis=-1).astype(np.float32, copy=False)


def expose(
    radiance: np.ndarray,
    lightings: Sequence[Lighting],
    rng: np.random.Generator,
) -> np.ndarray:
    """Camera response: gradient, exposure gain, sensor noise, saturation, gamma, blur, 8 bits.

    Args:
        radiance: float32 (B, H, W) or (B, H, W, C) linear radiance.
        lightings: one :class:`Lighting` per batch item (gain, gamma, noise, gradient, blur).
        rng: random generator for the noise.

    Returns:
        uint8 array of the same shape (channels in the input's order).
    """
    b, h, w = radiance.shape[:3]
    shp = (b, 1, 1) + (1,) * (radiance.ndim - 3)
    gain = np.array([lt.gain for lt in lightings], np.float32).reshape(shp)
    x = radiance * gain
    grad = np.array([lt.gradient for lt in lightings], np.float32)
    if np.any(grad != 0):
        u = np.linspace(-1, 1, w, dtype=np.float32).reshape(1, 1, w)
        v = np.linspace(-1, 1, h, dtype=np.float32).reshape(1, h, 1)
        ramp = np.exp(grad[:, 0].reshape(b, 1, 1) * u + grad[:, 1].reshape(b, 1, 1) * v)
        x = x * ramp.reshape(b, h, w, *([1] * (radiance.ndim - 3)))
    shot = np.array([lt.shot_noise for lt in lightings], np.float32).reshape(shp)
    read = np.array([lt.read_noise for lt in lightings], np.float32).reshape(shp)
    sigma = np.sqrt(shot * np.clip(x, 0.0, 1.0) + read * read)
    x = x + sigma * rng.standard_normal(x.shape, dtype=np.float32)
    np.clip(x, 0.0, 1.0, out=x)
    inv_gamma = (1.0 / np.array([lt.gamma for lt in lightings], np.float32)).reshape(shp)
    x = np.power(x, inv_gamma)
    for i, lt in enumerate(lightings):
        if lt.motion_blur is not None:
            x[i] = _motion_blur(x[i], *lt.motion_blur)
    return np.rint(x * 255.0).astype(np.uint8)


def _motion_blur(img: np.ndarray, length: float, angle_deg: float) -> np.ndarray:
    k = int(max(3, np.ceil(length))) | 1
    kernel = np.zeros((k, k), np.float32)
    c = k // 2
    a = np.deg2rad(angle_deg)
    dx, dy = np.cos(a) * length / 2, np.sin(a) * length / 2
    cv2.line(kernel, (int(round(c * 16 - dx * 16)), int(round(c * 16 - dy * 16))),
             (int(round(c * 16 + dx * 16)), int(round(c * 16 + dy * 16))), 1.0, 1, cv2.LINE_AA, 4)
    kernel /= kernel.sum()
    return cv2.filter2D(img, -1, kernel, borderType=cv2.BORDER_REFLECT_101)


def render_surfaces(
    surface: Surface,
    lightings: Sequence[Lighting],
    rng: np.random.Generator,
    *,
    gray: bool = False,
    camera_height: float | None = None,
    shadow_steps: int = 12,
    shadow_scale: int = 1,
) -> np.ndarray:
    """Render a batch of height fields, each under its own lighting, to 8-bit images.

    Args:
        surface: the batch (B, H, W).
        lightings: one :class:`Lighting` per item.
        rng: random generator (shadow shapes, noise).
        gray: return (B, H, W) grayscale (luminance of the linear RGB radiance, before noise)
            instead of (B, H, W, 3) BGR.
        camera_height: perspective viewer at (W/2, H/2, camera_height) px for view-dependent
            highlights; orthographic when None.
        shadow_steps: ray-marching samples per light.
        shadow_scale: compute shadows on a grid downsampled by this factor (then upsampled),
            for large scenes.

    Returns:
        uint8 (B, H, W) grayscale or (B, H, W, 3) BGR.
    """
    b, h, w = surface.height.shape
    if len(lightings) != b:
        raise InputError(f"need one lighting per batch item: {len(lightings)} for {b}")
    # Independent streams for the shadow shapes and the noise: item i's output does not depend
    # on the batch size (the first m items of a batch equal a batch of those m items).
    shape_rng, noise_rng = rng.spawn(2)
    lights = LightArrays.pack([lt.lights for lt in lightings])
    cam = None if camera_height is None else (w / 2.0, h / 2.0, float(camera_height))
    P, N, V = heightfield_geometry(surface.height, cam)
    if shadow_scale > 1:
        hs, ws = h // shadow_scale, w // shadow_scale
        small = np.stack([cv2.resize(x, (ws, hs), interpolation=cv2.INTER_AREA) for x in surface.height])
        small = small / shadow_scale
        ls = dataclasses.replace(lights, pos=lights.pos * np.where(lights.w[..., None] > 0, 1.0 / shadow_scale, 1.0)
                                 .astype(np.float32))
        vs = heightfield_shadows(small.astype(np.float32), ls, steps=shadow_steps)
        vis = np.stack([np.stack([cv2.resize(v, (w, h), interpolation=cv2.INTER_LINEAR) for v in vb]) for vb in vs])
    else:
        vis = heightfield_shadows(surface.height, lights, steps=shadow_steps)
    for i, lt in enumerate(lightings):
        if lt.shadow_shape is not None:
            vis[i, 0] *= shadow_shape(shape_rng, (h, w), lt.shadow_shape, penumbra=max(0.6, 0.006 * max(h, w)))
    # Ambient occlusion: crevices (below the local mean height) receive less ambient light.
    ao = np.empty((b, h, w), np.float32)
    sig = 3.0 if max(h, w) <= 128 else 6.0
    for i in range(b):
        ao[i] = cv2.GaussianBlur(surface.height[i], (0, 0), sig)
    ao = np.clip(1.0 - 0.08 * np.maximum(ao - surface.height, 0.0), 0.3, 1.0)
    ambient = np.stack([lt.ambient for lt in lightings]).astype(np.float32)
    rad = shade(P, N, V, surface.albedo, surface.material, lights, ambient, vis, ao)
    if gray:
        rad = rad[..., 0] * 0.299 + rad[..., 1] * 0.587 + rad[..., 2] * 0.114
        return expose(rad, lightings, noise_rng)
    return expose(rad[..., ::-1].copy(), lightings, noise_rng)
