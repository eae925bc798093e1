"""``alcn demo``'s figure: distinct row labels and full method names in the column titles."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from alcn_cv.commands.demo import image_label, method_title, normalization_grid
from alcn_cv.enhance import create
from alcn_cv.formats.coco import CocoImage


def test_row_labels_differ_for_images_of_the_same_light_family():
    images = [
        CocoImage(
            k + 1,
            f"{k}.png",
            8,
            8,
            Path(f"{k}.png"),
            {"light_family": "shadow", "lighting": {"family": "shadow", "gain": gain}},
        )
        for k, gain in enumerate([0.86, 0.93])
    ]
    labels = [image_label(k, im) for k, im in enumerate(images)]
    assert len(set(labels)) == 2 and all("shadow light" in label for label in labels)


def test_column_titles_spell_out_the_methods():
    assert method_title(create("dog")) == "dog: Difference of Gaussians"
    assert method_title(create("dlcn")) == "dlcn: Divisive local contrast normalization"
    assert method_title(create("clahe")) == "clahe: Contrast-limited adaptive histogram equalization"


def test_grid_is_written(tmp_path):
    rng = np.random.default_rng(0)
    images = [rng.integers(0, 256, (40, 64, 3), dtype=np.uint8) for _ in range(2)]
    path = normalization_grid(images, ["a", "b"], ["none", "dog"], tmp_path / "grid.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_demo_runs_twice_into_one_folder(tmp_path, monkeypatch):
    """``make demo`` twice in a row: the second run replaces the first's data and benchmark report (the benchmark
    refuses an earlier report but where the demo asks it to replace its own)."""
    pytest.importorskip("skimage")
    pytest.importorskip("torch")
    from alcn_cv.bench import detect_settings
    from alcn_cv.commands import demo
    from alcn_cv.data import detect

    tiny = dict(methods=["none"], real_images=[1], positives_per_object=4, epochs=1, seeds=[0], max_test_images=1)
    monkeypatch.setitem(detect_settings.CONFS, "demo", dataclasses.replace(detect_settings.CONFS["demo"], **tiny))
    render = detect.generate
    monkeypatch.setattr(detect, "generate", lambda out, **kwargs: render(out, **{**kwargs, "n_test": 1, "n_train": 1}))
    monkeypatch.setattr(demo, "normalization_grid", lambda *args, **kwargs: tmp_path / "normalized.png")
    report = tmp_path / "demo" / "bench" / "detect.json"
    demo.main(tmp_path / "demo", progress=False)
    first = report.stat().st_mtime_ns
    demo.main(tmp_path / "demo", progress=False)
    assert report.stat().st_mtime_ns > first
