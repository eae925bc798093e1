"""Tests of the shading model, shadows and camera response of the data engine."""

from __future__ import annotations

import numpy as np
import pytest

from alcn_cv.data.lighting import (
    LIGHT_FAMILIES,
    Light,
    LightArrays,
    Lighting,
    directional,
    sample_lighting,
    shadow_shape,
)
from alcn_cv.data.render import (
    MATERIALS,
    Surface,
    expose,
    heightfield_geometry,
    heightfield_shadows,
    render_surfaces,
    shade,
)
from alcn_cv.errors import InputError


def _flat(h=16, w=16, material="matte", albedo=0.5):
    alb = np.full((1, h, w, 3), albedo, np.float32)
    mat = np.broadcast_to(MATERIALS[material].vector(), (1, h, w, 6)).copy()
    mat[..., 1] = 0.0 if material == "matte" else mat[..., 1]
    return alb, np.zeros((1, h, w), np.float32), mat


@pytest.mark.parametrize("elev", [90.0, 60.0, 30.0])
def test_lambert_cosine_law(elev):
    alb, hgt, mat = _flat()
    P, N, V = heightfield_geometry(hgt)
    lights = LightArrays.pack([[directional(0.0, elev)]])
    rad = shade(P, N, V, alb, mat, lights, np.zeros((1, 3), np.float32))
    np.testing.assert_allclose(rad, 0.5 * np.sin(np.deg2rad(elev)), rtol=1e-4)


@pytest.mark.parametrize("axis", ["x", "y"])
def test_a_slope_facing_the_light_is_the_brighter(axis):
    """A plane rising along +x (or +y), height ``0.5 * x``: its normal is ``(-0.5, 0, 1) / sqrt(1.25)``, so a light
    from -x (azimuth 180, it faces) lights it more than one from +x, each by the cosine law with that normal."""
    alb, hgt, mat = _flat()
    ramp = 0.5 * np.arange(16, dtype=np.float32)
    hgt[0] = np.broadcast_to(ramp, (16, 16)) if axis == "x" else np.broadcast_to(ramp[:, None], (16, 16))
    P, N, V = heightfield_geometry(hgt)
    normal = np.array([-0.5, 0.0, 1.0] if axis == "x" else [0.0, -0.5, 1.0]) / np.sqrt(1.25)
    facing, away = (180.0, 0.0) if axis == "x" else (270.0, 90.0)
    centre = {}
    for azimuth in (facing, away):
        light = directional(azimuth, 45.0)
        rad = shade(P, N, V, alb, mat, LightArrays.pack([[light]]), np.zeros((1, 3), np.float32))
        centre[azimuth] = rad[0, 8, 8, 0]
        assert centre[azimuth] == pytest.approx(0.5 * max(0.0, float(normal @ light.vector)), rel=1e-4)
    assert centre[facing] > centre[away] > 0


def test_point_light_falls_off_and_spot_has_a_cone():
    alb, hgt, mat = _flat(64, 64)
    P, N, V = heightfield_geometry(hgt)
    point = Light("point", (0.0, 0.0, 10.0), (1.0, 1.0, 1.0), 10.0)
    rad = shade(P, N, V, alb, mat, LightArrays.pack([[point]]), np.zeros((1, 3), np.float32))[0, ..., 0]
    assert rad[0, 0] > rad[0, 20] > rad[20, 20] > rad[63, 63] > 0
    spot = Light("spot", (32.0, 32.0, 40.0), (1.0, 1.0, 1.0), spot_direction=(0, 0, -1), cone_deg=20, penumbra_deg=2)
    rad = shade(P, N, V, alb, mat, LightArrays.pack([[spot]]), np.zeros((1, 3), np.float32))[0, ..., 0]
    assert rad[32, 32] > 0.3 and rad[32, 0] == 0.0 and rad[0, 0] == 0.0  # tan(20 deg) * 40 = 14.6 px


def test_specular_and_velvet_differ_from_lambert():
    h = 32
    yy, xx = np.mgrid[0:h, 0:h].astype(np.float32)
    dome = np.sqrt(np.clip(15.0**2 - (xx - 15.5) ** 2 - (yy - 15.5) ** 2, 0, None))[None]
    P, N, V = heightfield_geometry(dome)
    lights = LightArrays.pack([[directional(0.0, 60.0)]])
    out = {}
    for name in ("matte", "metal", "velvet"):
        alb, _, mat = _flat(h, h, name)
        out[name] = shade(P, N, V, alb, mat, lights, np.zeros((1, 3), np.float32))[0, ..., 0]
    assert out["metal"].max() > 2 * out["matte"].max()  # tight, strong highlight
    # Velvet: flatter fall-off towards the grazing rim than Lambert.
    rim = (np.hypot(xx - 15.5, yy - 15.5) > 12) & (np.hypot(xx - 15.5, yy - 15.5) < 14.5)
    assert out["velvet"][rim].mean() / out["velvet"].max() > out["matte"][rim].mean() / out["matte"].max()


def test_heightfield_casts_shadow_away_from_light():
    h = np.zeros((1, 40, 40), np.float32)
    h[0, 18:22, 18:22] = 10.0  # a pillar
    lights = LightArrays.pack([[directional(0.0, 30.0)]])  # light from +x
    vis = heightfield_shadows(h, lights, steps=20, max_dist=30)[0, 0]
    assert vis[20, 10] < 0.1  # shadow on the -x side
    assert vis[20, 30] == 1.0  # lit on the light's side
    assert vis[20, 4] < 0.1  # within the shadow length 10 / tan(30) = 17.3 px of the edge at x = 18
    assert vis[20, 0] == 1.0  # beyond it


def test_shadow_shapes_are_hard_and_in_range():
    rng = np.random.default_rng(0)
    for kind in ("edge", "polygon", "blinds", "window", "blob"):
        m = shadow_shape(rng, (64, 64), kind, penumbra=0.5)
        assert m.shape == (64, 64) and m.min() >= 0 and m.max() <= 1
        assert (m < 0.05).mean() > 0.02 and (m > 0.95).mean() > 0.02
    with pytest.raises(InputError):
        shadow_shape(rng, (8, 8), "nope")


def test_exposure_saturates_and_quantises():
    lt = Lighting("bright", [], np.zeros(3, np.float32), gain=4.0, gamma=2.2)
    rad = np.full((1, 4, 4), 0.5, np.float32)
    out = expose(rad, [lt], np.random.default_rng(0))
    assert out.dtype == np.uint8 and (out == 255).all()
    lt.gain = 1.0
    out = expose(rad, [lt], np.random.default_rng(0))
    assert abs(int(out[0, 0, 0]) - round(255 * 0.5 ** (1 / 2.2))) <= 1


def test_every_family_renders_within_range():
    rng = np.random.default_rng(1)
    n = len(LIGHT_FAMILIES)
    alb = np.full((n, 32, 32, 3), 0.4, np.float32)
    surf = Surface(
        alb, np.zeros((n, 32, 32), np.float32), np.broadcast_to(MATERIALS["plastic"].vector(), (n, 32, 32, 6)).copy()
    )
    lts = [sample_lighting(rng, f, 32, 32) for f in LIGHT_FAMILIES]
    img = render_surfaces(surf, lts, rng, gray=True)
    assert img.shape == (n, 32, 32) and img.dtype == np.uint8
    means = dict(zip(LIGHT_FAMILIES, img.reshape(n, -1).mean(1)))
    assert means["dark"] < means["ambient"] < means["bright"]
    with pytest.raises(InputError):
        sample_lighting(rng, "moonlight", 8, 8)
    with pytest.raises(InputError):
        render_surfaces(surf, lts[:2], rng)
