"""Whole-image identification under hard directional light: a rendered stand-in for faces under Yale-B-like light.

A face set under hard directional light (nearest-neighbour identification against a frontal gallery) is one of
the real test sets kept outside the repository; it ranks Tan-Triggs and the self-quotient image above ALCN, most
of all under the most grazing light. No such real set is in `../shared/data` (the `psm` objects' 12 lights are
within 40 degrees of the camera's axis, where every normalization but `none` identifies their tiles), so this
script renders one: relief scenes of the data engine (`alcn_cv.data.relief_scenes.relief_surface`), each an
identity, seen under a frontal light (the gallery) and under directional light at elevations of 75 to 12 degrees
above the ground (the probes, 4 random azimuths each, cast shadows, gain and sensor noise). Every image is
normalized by its method's `apply()` (float output), resized to `SIZE x SIZE` (area), made zero-mean and unit-norm,
and identified as its most correlated gallery image; the table gives the percentage identified per elevation.

The rows `alcn, band W` are the shipped default with another weight of its wide band (`alcn_cv.filters.wide_band`;
0: without it): the band carries the relief's shading at 8 to 32 pixels, which a larger weight lets into the output.
The hand-made methods run with their default parameters (the real face set's protocol).

Writes runs/directional_light/directional_light.json; keeps docs/reports/directional_light.json.
"""

from __future__ import annotations

import json

import cv2
import numpy as np
from _run import RUNS, command_line, keep, script_command
from orb_orientation import band_variant
from tqdm.auto import tqdm

from alcn_cv.data.lighting import Lighting, directional
from alcn_cv.data.objects import to_surface
from alcn_cv.data.relief_scenes import relief_surface
from alcn_cv.data.render import render_surfaces
from alcn_cv.enhance.registry import from_spec
from alcn_cv.report import machine

#: Elevations of the probes' light above the ground (degrees); the gallery is lit from 90.
ELEVATIONS = (75, 55, 35, 20, 12)
AZIMUTHS = 4
BASELINES = ("none", "clahe", "dog", "dlcn", "tantriggs", "sqi", "alcn")
BAND_WEIGHTS = (0.0, 0.3)
#: Sides of the compared images (pixels).
SIZES = (32, 64)


def render_identity(index: int, size: int, seed: int) -> np.ndarray:
    """``(1 + len(ELEVATIONS) * AZIMUTHS, size, size)`` uint8: scene ``index`` under the gallery's light, then
    under the probes'."""
    rng = np.random.default_rng([seed, index])
    albedo, height, material = relief_surface(rng, size)
    lightings = [Lighting("ambient", [directional(0.0, 90.0)], np.full(3, 0.05), gain=0.9)]
    for elevation in ELEVATIONS:
        for _ in range(AZIMUTHS):
            light = directional(rng.uniform(0.0, 360.0), elevation)
            gain = rng.uniform(0.6, 1.4)
            lightings.append(Lighting("side", [light], np.full(3, 0.02), gain=gain, shot_noise=5e-4, read_noise=3e-3))
    surface = to_surface([(albedo, height, material)] * len(lightings))
    return render_surfaces(surface, lightings, rng, gray=True, shadow_steps=24)


def render_stand_in(identities: int = 80, size: int = 128, seed: int = 7) -> np.ndarray:
    """``(identities, 1 + len(ELEVATIONS) * AZIMUTHS, size, size)`` uint8: :func:`render_identity` of each."""
    return np.stack([render_identity(i, size, seed) for i in tqdm(range(identities), desc="render", unit="scene")])


def identify(spec: str, images: np.ndarray) -> dict[int, dict[str, float]]:
    """:func:`identification` of the images of :func:`render_stand_in` normalized by the method ``spec``'s
    ``apply()`` (float output), for each side of :data:`SIZES`."""
    norm = from_spec(spec)
    normalized = np.stack([[norm.apply(im, out_dtype=np.float32) for im in scene] for scene in images])
    return {size: identification(normalized, size) for size in SIZES}


def descriptors(images: np.ndarray, size: int) -> np.ndarray:
    """``(..., H, W)`` float -> ``(..., size * size)``: area-resized, zero-mean, unit-norm."""
    flat = images.reshape(-1, *images.shape[-2:])
    small = np.stack([cv2.resize(im, (size, size), interpolation=cv2.INTER_AREA).ravel() for im in flat])
    small -= small.mean(axis=1, keepdims=True)
    small /= np.linalg.norm(small, axis=1, keepdims=True) + 1e-9
    return small.reshape(*images.shape[:-2], size * size)


def identification(normalized: np.ndarray, size: int) -> dict[str, float]:
    """Per elevation, the percentage of probes whose most correlated gallery image is their own scene's."""
    features = descriptors(normalized, size)
    gallery, identities = features[:, 0], np.arange(len(features))
    result = {}
    for j, elevation in enumerate(ELEVATIONS):
        probes = features[:, 1 + j * AZIMUTHS : 1 + (j + 1) * AZIMUTHS]
        nearest = np.argmax(probes @ gallery.T, axis=-1)
        result[f"elevation {elevation}"] = float(100 * np.mean(nearest == identities[:, None]))
    return result


def main() -> None:
    parser = command_line(__doc__)
    parser.add_argument("--identities", type=int, default=80, help="rendered scenes (default: 80)")
    parser.add_argument("--size", type=int, default=128, help="side of the rendered images (default: 128)")
    parser.add_argument("--seed", type=int, default=7, help="rendering seed (default: 7)")
    args = parser.parse_args()
    out = RUNS / "directional_light"
    out.mkdir(parents=True, exist_ok=True)
    images = render_stand_in(args.identities, args.size, args.seed)
    cv2.imwrite(str(out / "identity_0.png"), np.hstack(list(images[0, ::AZIMUTHS])))
    methods = {m: m for m in BASELINES} | {
        f"alcn, band {w}": band_variant(w, out / f"band_{w}.npz") for w in BAND_WEIGHTS
    }
    summary: dict[str, dict[str, float]] = {}
    for name, spec in tqdm(methods.items(), desc="methods", unit="method"):
        for size, result in identify(spec, images).items():
            summary[f"{name}, {size} px"] = result
    report = {
        "summary": summary,
        "command": script_command(),
        "machine": machine(),
        "settings": {**vars(args), "elevations": ELEVATIONS, "azimuths": AZIMUTHS, "sizes": SIZES},
    }
    path = out / "directional_light.json"
    path.write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")
    keep(path, "directional_light")


if __name__ == "__main__":
    main()
