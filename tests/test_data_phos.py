"""Tests of the Phos-like Normalizer training windows."""

from __future__ import annotations

import json
import zipfile

import jsonschema
import numpy as np
import pytest

from alcn_cv.data import phos
from alcn_cv.data.lighting import LIGHT_FAMILIES
from alcn_cv.data.manifest import MANIFEST_SCHEMA
from alcn_cv.errors import DatasetError, InputError
from alcn_cv.io import read_json


@pytest.fixture(scope="module")
def batch():
    return phos.render_windows(300, seed=3, n_objects=12)


def test_shapes_dtypes_and_labels(batch):
    assert batch.windows.shape == (300, 64, 64) and batch.windows.dtype == np.uint8
    for a in (batch.labels, batch.light_ids, batch.kinds):
        assert a.shape == (300,) and a.dtype == np.int64
    assert batch.labels.min() >= 0 and batch.labels.max() <= 12
    assert set(np.unique(batch.light_ids)) <= set(range(len(LIGHT_FAMILIES)))
    obj = batch.labels > 0
    assert 0.45 < obj.mean() < 0.85  # background_fraction 0.35
    assert (batch.kinds[obj] == 0).all() and (batch.kinds[~obj] > 0).all()
    # Object windows: centred within 3 px, extent in the requested range.
    assert np.abs(batch.offsets[obj]).max() <= 3.0
    assert ((batch.extents[obj] >= 34) & (batch.extents[obj] <= 46)).all()
    # Off-centre negatives keep their object out of the centre.
    off = batch.kinds == 3
    assert (np.hypot(*batch.offsets[off].T) >= 14).all()
    assert np.isnan(batch.offsets[batch.kinds == 1]).all()


def test_windows_are_varied(batch):
    w = batch.windows.reshape(len(batch), -1).astype(np.float32)
    means = w.mean(1)
    assert means.min() < 40 and means.max() > 180  # dark and bright lightings
    assert (w.std(1) > 2).mean() > 0.95  # hardly any flat window
    assert (batch.windows == 255).any(axis=(1, 2)).mean() > 0.05  # some saturation


def test_deterministic_and_prefix_stable(batch):
    again = phos.render_windows(300, seed=3, n_objects=12)
    assert np.array_equal(again.windows, batch.windows) and np.array_equal(again.labels, batch.labels)
    first = phos.render_windows(40, seed=3, n_objects=12)
    assert np.array_equal(first.windows, batch.windows[:40])
    assert np.array_equal(phos.render_windows(300, seed=3, n_objects=12, workers=2).windows, batch.windows)
    other = phos.render_windows(40, seed=4, n_objects=12)
    assert not np.array_equal(other.windows, first.windows)


def test_lighting_selection_and_subset():
    b = phos.render_windows(20, seed=0, n_objects=4, lighting="side,dark")
    assert set(np.unique(b.light_ids)) <= {LIGHT_FAMILIES.index("side"), LIGHT_FAMILIES.index("dark")}
    s = b.subset(b.labels > 0)
    assert len(s) == int((b.labels > 0).sum()) and s.windows.shape[1:] == (64, 64)
    with pytest.raises(InputError):
        phos.render_windows(4, seed=0, lighting="sunset")
    with pytest.raises(InputError):
        phos.render_windows(4, seed=0, background_fraction=2.0)
    assert len(phos.render_windows(0, seed=0, n_objects=2)) == 0


def test_generate_load_roundtrip_bytes_identical(tmp_path):
    a = phos.generate(tmp_path / "a", 70, 5, n_objects=6, progress=False)
    b = phos.generate(tmp_path / "b", 70, 5, n_objects=6, progress=False)
    for name in ("windows.npz", "manifest.json"):
        assert (a / name).read_bytes() == (b / name).read_bytes()
    loaded = phos.load(a)
    ref = phos.render_windows(70, 5, n_objects=6)
    assert np.array_equal(loaded.windows, ref.windows) and np.array_equal(loaded.light_ids, ref.light_ids)
    assert loaded.n_objects == 6 and loaded.light_families == LIGHT_FAMILIES
    man = json.loads((a / "manifest.json").read_text())
    jsonschema.validate(man, read_json(MANIFEST_SCHEMA))
    assert man["kind"] == "phos" and man["seed"] == 5 and man["parameters"]["n"] == 70
    with pytest.raises(FileExistsError):
        phos.generate(a, 5, 5, n_objects=6, progress=False)
    assert not list(tmp_path.glob(".*tmp"))  # nothing half-written left behind


def test_load_errors_name_the_file_and_field(tmp_path):
    d = phos.generate(tmp_path / "d", 10, 0, n_objects=3, progress=False)
    npz = d / "windows.npz"
    data = npz.read_bytes()
    npz.write_bytes(data[: len(data) // 2])
    with pytest.raises(DatasetError, match="windows.npz"):
        phos.load(d)
    npz.write_bytes(data)
    man = json.loads((d / "manifest.json").read_text())
    del man["seed"]
    (d / "manifest.json").write_text(json.dumps(man))
    with pytest.raises(DatasetError, match="manifest.json.*seed"):
        phos.load(d)
    man["seed"] = 0
    labels = np.load(npz)["labels"]
    assert labels.max() >= 1
    man["parameters"]["n_objects"] = int(labels.max()) - 1
    (d / "manifest.json").write_text(json.dumps(man))
    with pytest.raises(DatasetError, match="labels"):
        phos.load(d)
    (d / "manifest.json").write_text("{ truncated")
    with pytest.raises(DatasetError, match="malformed or truncated"):
        phos.load(d)
    with zipfile.ZipFile(npz, "w") as z:
        z.writestr("labels.npy", b"")
    (d / "manifest.json").write_text(json.dumps({**man, "parameters": {"n_objects": 3}}))
    with pytest.raises(DatasetError, match="windows.npz"):
        phos.load(d)


def test_overwrite_replaces_an_earlier_output_only(tmp_path):
    """--overwrite replaces a folder an earlier run wrote (its manifest.json) or an empty one, never other files."""
    from alcn_cv.data.manifest import atomic_output_dir

    def write(out, **kwargs):
        with atomic_output_dir(out, **kwargs) as tmp:
            (tmp / "manifest.json").write_text("{}")

    write(tmp_path / "data")
    with pytest.raises(FileExistsError, match="--overwrite"):
        write(tmp_path / "data")
    write(tmp_path / "data", overwrite=True)
    (tmp_path / "empty").mkdir()
    write(tmp_path / "empty")  # an empty folder counts as absent
    (tmp_path / "empty2").mkdir()
    write(tmp_path / "empty2", overwrite=True)
    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "notes.txt").write_text("mine")
    (tmp_path / "file.json").write_text("mine")
    for out, why in ((tmp_path / "notes", "is not an earlier output"), (tmp_path / "file.json", "is a file")):
        with pytest.raises(FileExistsError, match=why):
            write(out, overwrite=True)
    assert (tmp_path / "notes" / "notes.txt").read_text() == (tmp_path / "file.json").read_text() == "mine"


def test_an_output_folder_gets_the_permissions_of_any_new_folder(tmp_path):
    import os

    from alcn_cv.data.manifest import atomic_output_dir

    with atomic_output_dir(tmp_path / "data") as tmp:
        (tmp / "manifest.json").write_text("{}")
    (tmp_path / "plain").mkdir()
    assert os.stat(tmp_path / "data").st_mode == os.stat(tmp_path / "plain").st_mode


def test_user_errors_are_told_before_the_rendering(tmp_path, monkeypatch):
    """An existing folder, a folder under a file and an empty dataset fail at once, not after minutes of rendering
    (at the default 100000 windows) or, under a file, with a bare "[Errno 17] File exists"."""
    phos.generate(tmp_path / "data", 5, 0, n_objects=2, progress=False)
    blocker = tmp_path / "file.json"
    blocker.write_text("mine")
    monkeypatch.setattr(phos, "parallel_map", lambda *args, **kwargs: pytest.fail("rendered"))
    with pytest.raises(FileExistsError, match="--overwrite"):
        phos.generate(tmp_path / "data", 5, 0, n_objects=2, progress=False)
    with pytest.raises(InputError, match="is a file"):
        phos.generate(blocker / "p", 5, 0, n_objects=2, progress=False)
    with pytest.raises(InputError, match=r"\(-n\) must be at least 1, got 0"):
        phos.generate(tmp_path / "empty", 0, 0, progress=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["data", "file.json"]
