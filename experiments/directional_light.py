"""Whole-image identification under hard directional light: a rendered stand-in for faces under Yale-B-like light.

A face set under hard directional light (nearest-neighbour identification against a frontal gallery) is one of
the real test sets kept outside the repository; it ranks Tan-Triggs and the self-quotient image above ALCN, most
of all under the most grazing light. No such real set is in `../shared/data` (the `psm` objects' 12 lights are
within 40 degrees of the camera's axis, where every normalization but `none` identifies their tiles), so this
script renders one (`alcn data scenes --lighting directional`, `alcn_cv.data.relief_scenes`): relief scenes of the
data engine, each an identity, seen under a frontal light (the gallery) and under directional light at elevations
of 75 to 12 degrees above the ground (the probes, 4 random azimuths each, cast shadows, gain and sensor noise). Every
image is normalized by its method's `apply()` (float output), resized to `SIZE x SIZE` (area), made zero-mean and
unit-norm, and identified as its most correlated gallery image (`alcn_cv.bench.directional`); the table gives the
percentage identified per elevation.

The rows `alcn, band W` are the shipped default with another weight of its wide band (`alcn_cv.filters.wide_band`;
0: without it): the band carries the relief's shading at 8 to 32 pixels, which a larger weight lets into the output.
The hand-made methods run with their default parameters (the real face set's protocol).

Writes runs/directional_light/directional_light.json; keeps docs/reports/directional_light.json.
"""

from __future__ import annotations

import json

import cv2
import numpy as np
from _run import RUNS, band_variant, command_line, keep, recorded_settings, script_command
from _stand_in import IDENTITIES, SEED, SIZE, render_stand_in
from tqdm.auto import tqdm

from alcn_cv.bench.directional import SIZES, identify
from alcn_cv.data.relief_scenes import AZIMUTHS, ELEVATIONS
from alcn_cv.report import machine

BASELINES = ("none", "clahe", "dog", "dlcn", "tantriggs", "sqi", "alcn")
BAND_WEIGHTS = (0.0, 0.3)


def main() -> None:
    parser = command_line(__doc__)
    parser.add_argument("--identities", type=int, default=IDENTITIES, help=f"rendered scenes (default: {IDENTITIES})")
    parser.add_argument("--size", type=int, default=SIZE, help=f"side of the rendered images (default: {SIZE})")
    parser.add_argument("--seed", type=int, default=SEED, help=f"rendering seed (default: {SEED})")
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
        "settings": {**recorded_settings(args), "elevations": ELEVATIONS, "azimuths": AZIMUTHS, "sizes": SIZES},
    }
    path = out / "directional_light.json"
    path.write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")
    keep(path, "directional_light")


if __name__ == "__main__":
    main()
