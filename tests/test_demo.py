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
    assert (tmp_path / "demo" / demo.MARKER).is_file()  # the folder is the demo's: the next run may replace it
    demo.main(tmp_path / "demo", progress=False)
    assert report.stat().st_mtime_ns > first


@pytest.mark.parametrize("kind", ["a folder of the user's", "a file"])
def test_the_demo_replaces_nothing_of_the_users(kind, tmp_path, capsys):
    """``alcn demo --out DIR``, DIR an existing folder of other files, replaced DIR/normalized.png and
    DIR/bench/detect.md; it is refused before anything is written, as a file is."""
    from alcn_cv.cli import main

    out = tmp_path / "mine"
    if kind == "a file":
        out.write_text("mine")
    else:
        out.mkdir()
        (out / "normalized.png").write_text("mine")
    before = sorted(tmp_path.rglob("*"))
    assert main(["demo", "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert "not replaced; give another --out" in err and "\n" not in err
    assert (
        sorted(tmp_path.rglob("*")) == before
        and "mine" in (out if kind == "a file" else out / "normalized.png").read_text()
    )


def test_the_demo_writes_into_a_new_an_empty_or_its_own_folder(tmp_path):
    """The folders the demo takes (:func:`check_out_dir`): a new path, an empty folder, an earlier demo's (marked)."""
    from alcn_cv.commands.demo import MARKER, check_out_dir

    check_out_dir(tmp_path / "new")
    check_out_dir(tmp_path)
    (tmp_path / "normalized.png").write_text("an earlier demo's")
    (tmp_path / MARKER).write_text("{}")
    check_out_dir(tmp_path)


def test_an_earlier_demo_without_its_marker_is_replaced(tmp_path):
    """A demo run before `demo.json` marked its folder (`make demo` of an earlier version) left the demo's outputs
    alone: it is the demo's. A user's own data set in `DIR/data` (another kind or preset) is not, nor is a folder
    with a file of the user's beside the demo's outputs."""
    import json

    from alcn_cv.commands.demo import check_out_dir
    from alcn_cv.errors import InputError

    def manifest(kind: str, conf: str) -> None:
        (tmp_path / "data" / "manifest.json").write_text(
            json.dumps({"generator_version": "1", "kind": kind, "seed": 0, "parameters": {"conf": conf}})
        )

    (tmp_path / "data").mkdir()
    manifest("phos", "demo")
    with pytest.raises(InputError, match="not an earlier demo's output"):  # the user's data set alone
        check_out_dir(tmp_path)
    (tmp_path / "normalized.png").write_text("an earlier demo's")
    (tmp_path / "bench").mkdir()
    with pytest.raises(InputError, match="not an earlier demo's output"):
        check_out_dir(tmp_path)
    manifest("detect", "small")
    with pytest.raises(InputError, match="not an earlier demo's output"):
        check_out_dir(tmp_path)
    manifest("detect", "demo")
    check_out_dir(tmp_path)
    (tmp_path / "notes.txt").write_text("mine")
    with pytest.raises(InputError, match="not an earlier demo's output"):
        check_out_dir(tmp_path)


def test_row_labels_count_the_test_images_from_one():
    image = CocoImage(1, "0.png", 8, 8, Path("0.png"), {"light_family": "shadow", "lighting": {"gain": 0.86}})
    assert image_label(0, image) == "test image 1\nshadow light, gain 0.86"
