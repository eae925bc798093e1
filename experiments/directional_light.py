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

Each hand-made method runs at its default parameters (the real face set's protocol), and tuned: `method (tuned)`
runs at the setting of `alcn bench relight`'s grid for it (`alcn_cv.bench.relight.TUNING_GRIDS`: 8 settings for
each, the default first, so every method has the same budget) with the best mean identification over the elevations
at both compared sides, 32 and 64 px (`alcn_cv.bench.directional.tune` and `score`; the first best wins) on a validation
rendering: the same stand-in from another seed (`--validation-seed`), never the test rendering, with half its
identities (`--validation-identities`: the self-quotient image's grid is the slow one). The report records each chosen
setting and the validation score of every setting (`tuning`).

The row `alcn` is the shipped default, not tuned here; the rows `alcn, band W` are diagnostics, not a tuned ALCN: the
shipped default with another weight of its wide band (`alcn_cv.filters.wide_band`; 0: without it), which carries the
relief's shading at 8 to 32 pixels and which a larger weight lets into the output.

Writes runs/directional_light/directional_light.json; keeps docs/reports/directional_light.json.
"""

from __future__ import annotations

import json

import cv2
import numpy as np
from _run import RUNS, band_variant, command_line, keep, recorded_settings, script_command
from _stand_in import IDENTITIES, SEED, SIZE, render_stand_in
from tqdm.auto import tqdm

from alcn_cv.bench.directional import SIZES, identify, tune
from alcn_cv.bench.relight import TUNING_GRIDS
from alcn_cv.cli import SEED as SEED_TYPE
from alcn_cv.cli import number_at_least, number_in, run_script
from alcn_cv.data.relief_settings import AZIMUTHS, ELEVATIONS, MAX_SIDE, MIN_SIDE
from alcn_cv.report import machine

BASELINES = ("none", "clahe", "dog", "dlcn", "tantriggs", "sqi", "alcn")
#: The methods tuned: the hand-made ones that `alcn bench relight` tunes, with its grids.
TUNED = tuple(m for m in BASELINES if m in TUNING_GRIDS)
BAND_WEIGHTS = (0.0, 0.3)
#: The validation rendering's seed (not the stand-in's) and identities.
VALIDATION_SEED, VALIDATION_IDENTITIES = SEED + 1, IDENTITIES // 2


def main() -> None:
    parser = command_line(__doc__)
    scenes = number_at_least(int, 1)
    parser.add_argument(
        "--identities", type=scenes, default=IDENTITIES, help=f"rendered scenes (default: {IDENTITIES})"
    )
    parser.add_argument(
        "--size",
        type=number_in(int, MIN_SIDE, MAX_SIDE),
        default=SIZE,
        help=f"side of the rendered images, {MIN_SIDE} to {MAX_SIDE} px (default: {SIZE})",
    )
    parser.add_argument("--seed", type=SEED_TYPE, default=SEED, help=f"rendering seed (default: {SEED})")
    parser.add_argument(
        "--validation-seed",
        type=SEED_TYPE,
        default=VALIDATION_SEED,
        help=f"the tuning rendering's seed (default: {VALIDATION_SEED})",
    )
    parser.add_argument(
        "--validation-identities",
        type=scenes,
        default=VALIDATION_IDENTITIES,
        help=f"the tuning rendering's scenes (default: {VALIDATION_IDENTITIES})",
    )
    args = parser.parse_args()
    if args.validation_seed == args.seed:
        parser.error("--validation-seed must differ from --seed: the methods are tuned on other scenes than the test's")
    out = RUNS / "directional_light"
    out.mkdir(parents=True, exist_ok=True)
    images = render_stand_in(args.identities, args.size, args.seed)
    cv2.imwrite(str(out / "identity_0.png"), np.hstack(list(images[0, ::AZIMUTHS])))
    validation = render_stand_in(args.validation_identities, args.size, args.validation_seed)
    tuning = {m: tune(m, validation, TUNING_GRIDS[m]) for m in tqdm(TUNED, desc="tuning", unit="method")}
    methods: dict[str, str] = {}
    for m in BASELINES:
        methods[m] = m
        if m in tuning:
            methods[f"{m} (tuned)"] = tuning[m]["chosen"]
    methods |= {f"alcn, band {w}": band_variant(w, out / f"band_{w}.npz") for w in BAND_WEIGHTS}
    summary: dict[str, dict[str, float]] = {}
    for name, spec in tqdm(methods.items(), desc="methods", unit="method"):
        for size, result in identify(spec, images).items():
            summary[f"{name}, {size} px"] = result
    report = {
        "summary": summary,
        "tuning": tuning,
        "command": script_command(),
        "machine": machine(),
        "settings": {**recorded_settings(args), "elevations": ELEVATIONS, "azimuths": AZIMUTHS, "sizes": SIZES},
    }
    path = out / "directional_light.json"
    path.write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")
    keep(path, "directional_light")


if __name__ == "__main__":
    run_script(main)
