"""The README's figure: one fixed outdoor camera under two real lights (rows), normalized by several
methods (columns), each through its own ``apply()`` with its default parameters.

Data: a scene of ../shared/data/webcam (the Webcam data set of TILDE, Verdie et al., CVPR 2015, from
AMOS: academic research only; cite TILDE and AMOS). The frames are the scene's darkest and brightest
by mean intensity. Time: a few seconds. Deterministic up to one grey level (another CPU's float rounding):
tests/test_docs.py renders it again and compares it with the published one within that level, so a change to a
method's output shows up there.

    python experiments/figure.py --publish                # runs/figure.png, then docs/figure.png (the README's)
    python experiments/figure.py --scene courbevoie       # runs/figure.png only (--publish: mexico only)
"""

from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import numpy as np
from _run import ROOT, RUNS, SHARED_DATA, command_line

from alcn_cv.cli import run_script

#: The README's figure, which --publish replaces, and its scene (the README's caption names it).
PUBLISHED = ROOT / "docs" / "figure.png"
SCENE = "mexico"
METHODS = {"input": "none", "CLAHE": "clahe", "DoG": "dog", "Tan-Triggs": "tantriggs", "ALCN": "alcn"}
TILE_WIDTH = 256


def frames(scene: Path) -> list[np.ndarray]:
    """The scene's darkest and brightest frames (mean intensity), gray uint8."""
    images = []
    for path in sorted(scene.glob("*.jpg")):
        image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        if image is None:
            raise SystemExit(f"{path}: not a readable image")
        images.append(image)
    if not images:
        raise SystemExit(f"no frames in {scene}")
    order = np.argsort([img.mean() for img in images])
    return [images[order[0]], images[order[-1]]]


def label(tile: np.ndarray, text: str) -> np.ndarray:
    out = cv2.copyMakeBorder(tile, 22, 0, 0, 0, cv2.BORDER_CONSTANT, value=255)
    cv2.putText(out, text, (6, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.5, 0, 1, cv2.LINE_AA)
    return out


def figure(scene: Path) -> np.ndarray:
    import alcn_cv

    rows = []
    for frame in frames(scene):
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
    parser.add_argument("--scene", default=SCENE, help=f"a scene of ../shared/data/webcam (default {SCENE})")
    parser.add_argument("--out", type=Path, default=RUNS / "figure.png", help="PNG to write (default: runs/figure.png)")
    parser.add_argument("--publish", action="store_true", help=f"then copy it to {PUBLISHED.relative_to(ROOT)}")
    args = parser.parse_args()
    if args.out.suffix.lower() != ".png":
        parser.error(f"--out is a PNG file (.png), got {args.out}")
    if args.publish and args.scene != SCENE:  # the README's caption names its scene
        parser.error(f"--publish: the README's figure is of {SCENE}; --scene {args.scene} writes --out only")
    image = figure(SHARED_DATA / "webcam" / args.scene)
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
