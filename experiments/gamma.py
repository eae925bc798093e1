"""Experiment (issue 39): the gain Normalizer on compressed intensities, ``((I + offset) / (1 + offset)) ** gamma``
(in [0, 1], 1 kept), as Tan-Triggs compresses them before its DoG.

The divisive step makes ALCN's output ignore a gain that is constant over its window, but not a light that changes
within it: under hard directional light a cast shadow's edge outweighs the texture on either side, and the divisive
floor (``c * mean(e)`` over the image) flattens the texture in the shadow. A power below 1 shrinks both, as it
shrinks the ratio of the lit side to the shadowed one; the offset keeps it from amplifying the noise of the darkest
pixels (the `psm` objects' black backgrounds, where a bare power costs SIFT most of its matches). Parts
(``--part``; default: all, in this order), each writing under ``--out`` (default ``runs/gamma``):

* ``train``: the ``gain`` preset's recipe (``alcn train-real-light --conf gain``: relit photographs that permit any
  use) with every training crop compressed, for each seed of ``--train-seeds``, into ``OUT/trained_seed_<seed>`` (a
  seed whose weight file is there already is not trained again);
* ``start``: the recipe's untrained start (the DoG G1 - G2, the divisive step, the equalization), ``OUT/untrained.npz``;
* ``faces``: the rendered stand-in for faces under hard directional light (``_stand_in.render_stand_in``) at the most
  grazing light (12 degrees), outputs compared at 32 and 64 px;
* ``bench``: ``alcn bench relight``'s quick protocol, seeds 0-2, no tuning, on the test scenes and on the four webcams
  one by one (``--leave-one-out``);
* ``middlebury``: ``alcn pose eval --middlebury`` on the temple's and the dinosaur's photographs (each view posed
  from a model of SIFT keypoints built from the others), the views posed correctly, as taken and relit.

The compressed rows are :class:`CompressedALCN` (``alcn-gamma``, registered here): the weight file's ALCN on the
compressed image (:func:`compressed`); the rows "without the gain map's structure" take off what Eq. 3 gives a flat
image (:func:`eq3_without_gain_structure`), which tells what training changed that the divisive step does not
cancel. Nothing of it is in the product.

    python experiments/gamma.py     # about 20 min on 2 cores

Writes OUT/gamma.json; keeps docs/reports/gamma.json.
"""

from __future__ import annotations

import contextlib
import copy
import json
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import torch
from _run import (
    RUNS,
    SHARED_DATA,
    add_part_option,
    alcn,
    command_line,
    keep,
    recorded_settings,
    script_command,
    selected_parts,
    short_relight,
    untrained_start,
)
from _stand_in import render_stand_in
from tqdm.auto import tqdm

from alcn_cv.bench.directional import identify
from alcn_cv.cli import SEED, run_script
from alcn_cv.data.relief_settings import ELEVATIONS
from alcn_cv.enhance.alcn import ALCN, createALCN
from alcn_cv.enhance.base import Normalization
from alcn_cv.enhance.registry import register
from alcn_cv.errors import InputError
from alcn_cv.filters.gaussian_mixture import gaussian_blur_stack
from alcn_cv.filters.wide_band import wide_band
from alcn_cv.report import machine
from alcn_cv.runtime import MODELS, WindowRuntime
from alcn_cv.train import real_light

PARTS = ("train", "start", "faces", "bench", "middlebury")
#: The compression of the trained rows (:func:`compressed`).
GAMMA, OFFSET = 0.3, 0.2
#: The hand-made methods of the faces' table (those that lead there) and of the benches'.
FACE_BASELINES = ("tantriggs", "dlcn")
BENCH_BASELINES = ("none", "dlcn")
#: Middlebury's sets the ``middlebury`` part poses (every row and ``none``).
MIDDLEBURY_SETS = ("templeSparseRing", "dinoSparseRing")
#: The groups of scenes: ``alcn bench relight`` options beside the methods and the protocol.
GROUPS = {"test": [], "webcams": ["--leave-one-out"]}
METRICS = ("identification", "matching_orb", "matching_sift", "pose_orb", "pose_sift")
#: The stand-in's probes under the most grazing light (12 degrees).
GRAZING = f"elevation {ELEVATIONS[-1]}"


@register
class CompressedALCN(Normalization):
    """ALCN of a weight file (default: the shipped default) on :func:`compressed` intensities.

    Args:
        gamma: the power.
        offset: added to the intensities before the power.
        weights: a gain Normalizer's weight file (empty: the shipped default); one without an ONNX export beside it
            runs its network in torch (``backend="fast"``).
        gain_structure: Eq. 3 as it is; False: with the gain map's own structure taken off
            (:func:`eq3_without_gain_structure`).
    """

    name = "alcn-gamma"
    summary = "ALCN on (I + offset) ** gamma (experiments/gamma.py)"

    def __init__(
        self, gamma: float = GAMMA, offset: float = OFFSET, weights: str = "", gain_structure: bool = True
    ) -> None:
        self.gamma, self.offset, self.weights, self.gain_structure = gamma, offset, weights, gain_structure
        self.alcn = createALCN(weights=weights or None)
        self.output_range = self.alcn.output_range

    def _normalize(self, gray: np.ndarray) -> np.ndarray:
        image = compressed(gray, self.gamma, self.offset)
        if self.gain_structure:
            return self.alcn.normalize(image)
        runtime = self.alcn.runtime
        if not isinstance(runtime, WindowRuntime):
            raise InputError("gain_structure=False takes Eq. 3 apart in OpenCV: backend 'opencv' or 'fast'")
        out = runtime.finish(eq3_without_gain_structure(self.alcn, image))
        spec = self.alcn.spec
        if spec.band and spec.tau is not None and spec.divisive is not None:  # as the gain runtime adds it
            out += np.float32(spec.band) * wide_band(image, spec.tau, spec.divisive[1], None)
        return out


def eq3_without_gain_structure(alcn: ALCN, image: np.ndarray) -> np.ndarray:
    """Eq. 3 of ``alcn`` less the part a flat image would give, ``sum_k G_k * (F_k I) - I sum_k G_k * F_k``: 0 where the
    image is flat, ``F * DoG(I)`` where the gain map is (the gain family's maps are ``F`` and ``-F``); Eq. 3 itself
    adds ``I`` times the DoG of the gain map, structure the map draws on its own."""
    response, own = np.zeros_like(image), np.zeros_like(image)
    for weights, sigma in zip(alcn.weight_maps(image), alcn.full_res_sigmas):
        response += gaussian_blur_stack(np.ascontiguousarray(weights * image), (sigma,))[0]
        own += gaussian_blur_stack(weights, (sigma,))[0]
    return response - image * own


def compressed(image: np.ndarray, gamma: float, offset: float) -> np.ndarray:
    """``((image + offset) / (1 + offset)) ** gamma`` of intensities in [0, 1], float32 in [0, 1]."""
    shifted = (image + np.float32(offset)) * np.float32(1 / (1 + offset))
    return np.minimum(np.power(shifted, np.float32(gamma), dtype=np.float32), np.float32(1))


@contextlib.contextmanager
def compressed_crops(gamma: float, offset: float) -> Iterator[None]:
    """Within it, the real-light training's crops (:func:`alcn_cv.train.real_light.crop_windows`) are compressed, as
    :class:`CompressedALCN` compresses a whole image."""
    crop_windows = real_light.crop_windows

    def crops(frame: np.ndarray, centres: np.ndarray, size: int) -> torch.Tensor:
        return torch.from_numpy(compressed(crop_windows(frame, centres, size).numpy(), gamma, offset))

    real_light.crop_windows = crops
    try:
        yield
    finally:
        real_light.crop_windows = crop_windows


def train(out: Path, seed: int, command: str) -> Path:
    """The ``gain`` preset's recipe at ``seed`` on compressed crops, into ``out``; its weight file."""
    from alcn_cv.train.config import REAL_LIGHT_CONFS

    cfg = copy.deepcopy(REAL_LIGHT_CONFS["gain"])
    cfg.seed = seed
    with compressed_crops(GAMMA, OFFSET):
        return real_light.train_real_light(cfg, out, command=command, conf="gain", overwrite=True)


def main() -> None:
    parser = command_line(__doc__)
    parser.add_argument("--out", type=Path, default=RUNS / "gamma", help="run folder (default: runs/gamma)")
    parser.add_argument(
        "--train-seeds", nargs="+", type=SEED, default=[0, 1, 2], help="training seeds (default: 0 1 2)"
    )
    add_part_option(parser, PARTS)
    args = parser.parse_args()
    args.part = selected_parts(args, PARTS)
    command = script_command()
    args.out.mkdir(parents=True, exist_ok=True)
    untrained = args.out / "untrained.npz"
    trained = {seed: args.out / f"trained_seed_{seed}" / "gain_normalizer.npz" for seed in args.train_seeds}
    if "train" in args.part:
        for seed, path in trained.items():
            if not path.exists():
                train(path.parent, seed, command)
    if "start" in args.part:
        untrained_start(MODELS["gain"], untrained, "the default's untrained start")
    compression = f"gamma={GAMMA}:offset={OFFSET}"
    specs = {
        "shipped": "alcn",
        "untrained start": f"alcn:weights={untrained}",
        "shipped, compressed": f"alcn-gamma:{compression}",
        "untrained start, compressed": f"alcn-gamma:{compression}:weights={untrained}",
    } | {f"trained compressed, seed {s}": f"alcn-gamma:{compression}:weights={p}" for s, p in trained.items()}
    specs |= {
        f"trained compressed, seed {s}, without the gain map's structure": (
            f"alcn-gamma:{compression}:weights={p}:gain_structure=False"
        )
        for s, p in trained.items()
    }
    summary: dict[str, dict[str, float]] = {}
    if "faces" in args.part:
        images = render_stand_in()
        for name, spec in tqdm((specs | {m: m for m in FACE_BASELINES}).items(), desc="faces", unit="method"):
            per_size = identify(spec, images)
            summary.setdefault(name, {}).update({f"faces {size} px": r[GRAZING] for size, r in per_size.items()})
    if "bench" in args.part:
        benched = specs | {m: m for m in BENCH_BASELINES}
        for group, options in GROUPS.items():
            out = args.out / f"bench_{group}"
            short_relight(out, list(benched.values()), seeds=(0, 1, 2), options=options)
            report = json.loads((out / "relight.json").read_text(encoding="utf-8"))
            for name, spec in benched.items():
                means = report["methods"][spec]["mean_test"]
                summary.setdefault(name, {}).update(
                    {f"{group} {m.replace('_', ' ')}": means[m]["mean"] for m in METRICS}
                )
    if "middlebury" in args.part:
        rows = {"none": "none"} | specs
        out = args.out / "middlebury"
        sets = [str(SHARED_DATA / "middlebury" / name) for name in MIDDLEBURY_SETS]
        normalizations = ["--normalizations", *rows.values()]
        alcn("pose", "eval", "--middlebury", *sets, *normalizations, "--out", str(out), "--overwrite")
        posed = json.loads((out / "middlebury.json").read_text(encoding="utf-8"))
        for name, spec in rows.items():
            summary.setdefault(name, {}).update(
                {
                    f"middlebury {ring.removesuffix('SparseRing')} {light}": posed[f"{ring}/{spec}/{light}"]["correct"]
                    for ring in MIDDLEBURY_SETS
                    for light in ("original", "relit")
                }
            )
    result = {"summary": summary, "command": command, "machine": machine(), "settings": recorded_settings(args)}
    path = args.out / "gamma.json"
    path.write_text(json.dumps(result, indent=1) + "\n", encoding="utf-8")
    keep(path, "gamma")


if __name__ == "__main__":
    run_script(main)
