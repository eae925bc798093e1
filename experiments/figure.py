"""The README's figure: one photograph under two lights (rows), normalized by several methods (columns), each
through its own ``apply()`` with its default parameters.

Data: the still of OpenCV's cookie box (``../shared/data/cookie_box/resized_IMG_3875.JPG``, from OpenCV's samples,
Apache-2.0), relit by the data engine's light changes (:func:`alcn_cv.data.light_changes.relight`) under two fixed
lights: a dim one with a cast shadow of blinds and the noise of a dark exposure, and a bright one with a soft shading
ramp (:data:`LIGHTS`; the shadow's shape is drawn from the seed). A figure of real light changes would need frames
whose terms allow redistribution, which no multi-light set of the project's data has (the Webcam frames are for
academic research only). Time: a few seconds. Deterministic but for another CPU's float rounding (a few pixels, a
few grey levels): tests/test_docs.py renders it again and compares it with the published one within that, so a change
to a method's output shows up there.

    python experiments/figure.py --publish                # runs/figure.png, then docs/figure.png (the README's)
    python experiments/figure.py --image my.jpg           # runs/figure.png only (--publish: the cookie box only)
"""

from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import numpy as np
from _run import ROOT, RUNS, SHARED_DATA, command_line

from alcn_cv.cli import run_script
from alcn_cv.data.light_changes import LightChangeConfig, relight

#: The README's figure, which --publish replaces, and its photograph (the README's caption names it).
PUBLISHED = ROOT / "docs" / "figure.png"
IMAGE = SHARED_DATA / "cookie_box" / "resized_IMG_3875.JPG"
METHODS = {"input": "none", "CLAHE": "clahe", "DoG": "dog", "Tan-Triggs": "tantriggs", "ALCN": "alcn"}
TILE_WIDTH = 256


#: The rows' lights and the seeds they are drawn with: every range fixed, only the shadow's shape and the shading's
#: field drawn. No auto-exposure: the dim light stays dim (a quarter of the photograph's light, 20% of it in the
#: shadow), with the shot and read noise of a small sensor; the bright one is 1.2 times the photograph's.
def _light(
    gain: float, shading: float, ramp: float, shadows: int, full_well: float, read_noise: float
) -> LightChangeConfig:
    """A light of fixed strength filmed without auto-exposure, exposure error or JPEG (a shadow leaves 20% of it, its
    penumbra 3 px)."""
    return LightChangeConfig(
        gain=(gain, gain),
        shading=shading,
        ramp=ramp,
        shadows=(shadows, shadows),
        shadow_light=(0.2, 0.2),
        penumbra=(3.0, 3.0),
        target=None,
        exposure_error=(0.0, 0.0),
        full_well=(full_well, full_well),
        read_noise=(read_noise, read_noise),
        jpeg_probability=0.0,
    )


LIGHTS: dict[str, tuple[int, LightChangeConfig]] = {
    "dim, cast shadow": (1, _light(0.25, 0.6, 1.5, 1, 5000.0, 3.0)),
    "bright": (0, _light(1.2, 0.3, 0.8, 0, 20000.0, 1.0)),
}


def frames(path: Path) -> list[np.ndarray]:
    """The photograph under each of :data:`LIGHTS`, gray uint8."""
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        raise SystemExit(f"{path}: not a readable image")
    return [
        cv2.cvtColor(relight(image, np.random.default_rng(seed), light), cv2.COLOR_BGR2GRAY)
        for seed, light in LIGHTS.values()
    ]


def label(tile: np.ndarray, text: str) -> np.ndarray:
    out = cv2.copyMakeBorder(tile, 22, 0, 0, 0, cv2.BORDER_CONSTANT, value=255)
    cv2.putText(out, text, (6, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.5, 0, 1, cv2.LINE_AA)
    return out


def figure(path: Path) -> np.ndarray:
    import alcn_cv

    rows = []
    for frame in frames(path):
        height = round(frame.shape[0] * TILE_WIDTH / frame.shape[1])
        small = cv2.resize(frame, (TILE_WIDTH, height), interpolation=cv2.INTER_AREA)
        tiles = []
        for title, name in METHODS.items():
            out = alcn_cv.create(name).apply(frame)
            tile = cv2.resize(out, (TILE_WIDTH, height), interpolation=cv2.INTER_AREA) if name != "none" else small
            tiles.append(label(tile, title))
        rows.append(np.hstack([np.pad(t, ((2, 2), (2, 2)), constant_values=255) for t in tiles]))
    return np.vstack(rows)


def main() -> None:
    parser = command_line(__doc__, keeps=False)
    parser.add_argument(
        "--image", type=Path, default=IMAGE, help="the photograph to relight (default: the cookie box's)"
    )
    parser.add_argument("--out", type=Path, default=RUNS / "figure.png", help="PNG to write (default: runs/figure.png)")
    parser.add_argument("--publish", action="store_true", help=f"then copy it to {PUBLISHED.relative_to(ROOT)}")
    args = parser.parse_args()
    if args.out.suffix.lower() != ".png":
        parser.error(f"--out is a PNG file (.png), got {args.out}")
    if args.publish and args.image.resolve() != IMAGE.resolve():  # the README's caption names its photograph
        parser.error(f"--publish: the README's figure is of {IMAGE.name}; --image {args.image} writes --out only")
    image = figure(args.image)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(args.out), image, [cv2.IMWRITE_PNG_COMPRESSION, 9]):
        raise OSError(f"cannot write {args.out}")
    print(f"wrote {args.out} ({args.out.stat().st_size // 1024} KB)")
    if args.publish:
        if args.out.resolve() != PUBLISHED.resolve():  # --out docs/figure.png wrote it already
            shutil.copyfile(args.out, PUBLISHED)
        print(f"published {PUBLISHED.relative_to(ROOT)}")


if __name__ == "__main__":
    run_script(main)
