"""The detection benchmark: its pieces against direct computations, its tuning, and a tiny end-to-end run."""

from __future__ import annotations

import json
import shlex
import shutil

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from alcn_cv.bench import detect as D  # noqa: E402
from alcn_cv.bench import detect_data, policies  # noqa: E402
from alcn_cv.bench import detect_settings as S  # noqa: E402
from alcn_cv.bench.methods import build_methods  # noqa: E402
from alcn_cv.cli import build_parser  # noqa: E402
from alcn_cv.cli import main as cli_main  # noqa: E402
from alcn_cv.enhance.registry import parameters  # noqa: E402
from alcn_cv.errors import DatasetError, InputError  # noqa: E402
from alcn_cv.filters.standardize import standardize_windows  # noqa: E402
from alcn_cv.nets import Detector  # noqa: E402

#: The smallest training and test that run every step: for tests of the benchmark's plumbing, not of its numbers.
TINY = dict(positives_per_object=4, negatives_ratio=0.5, epochs=1, batch_size=16, threads=1, max_test_images=1)


@pytest.fixture(scope="module")
def small_data(tmp_path_factory):
    from alcn_cv.data.detect import generate

    out = tmp_path_factory.mktemp("bench") / "detect_small"
    # as many validation images as test images would let a tuning scored on the test images pass for one on them
    generate(out, conf="small", n_test=2, n_val=3, progress=False)
    return out


def test_local_standardize_matches_direct():
    rng = np.random.default_rng(0)
    img = rng.random((40, 45)).astype(np.float32)
    out = policies.local_standardize(img, size=5)
    padded = np.pad(img.astype(np.float64), 2, mode="reflect")  # numpy "reflect" = reflect-101
    for y, x in [(0, 0), (10, 20), (39, 44), (20, 1)]:
        box = padded[y : y + 5, x : x + 5]
        assert out[y, x] == pytest.approx((img[y, x] - box.mean()) / (box.std() + 1e-6), rel=1e-3, abs=1e-3)


@pytest.mark.parametrize("policy", ["raw", "standardize", "local"])
def test_score_maps_equal_window_scores(policy):
    torch.manual_seed(0)
    net = Detector(3, hidden=16).eval()
    rng = np.random.default_rng(1)
    image = rng.random((48, 56)).astype(np.float32)
    pol = policies.InputPolicy(policy, rng.random((10, 64, 64)).astype(np.float32))
    probs = D.score_maps(net, image, pol)
    assert probs.shape == (3, 5, 7)
    np.testing.assert_allclose(probs.sum(0), 1, atol=1e-5)
    dense_input = None if policy == "standardize" else pol.image(image)
    for i, j in [(0, 0), (2, 3), (4, 6)]:
        window = image[4 * i : 4 * i + 32, 4 * j : 4 * j + 32]
        if policy == "standardize":
            x = (window - window.mean()) / (window.std() + 1e-6)
        else:
            x = dense_input[4 * i : 4 * i + 32, 4 * j : 4 * j + 32]
        with torch.no_grad():
            ref = torch.softmax(net(torch.from_numpy(np.ascontiguousarray(x, np.float32))[None, None]), 1)[0].numpy()
        np.testing.assert_allclose(probs[:, i, j], ref, atol=1e-5)


def test_detect_in_image_places_fixed_boxes():
    probs = np.zeros((2, 10, 12), np.float32)
    probs[1, 3, 5] = 0.9  # window with top-left (x=20, y=12) at the working scale
    probs[1, 3, 6] = 0.8  # its neighbour, suppressed
    probs[1, 8, 1] = 0.5
    boxes, scores = D.detect_in_image(probs, 1, sx=0.5, sy=0.25, box_size=36, nms_iou=0.3, max_detections=2)
    np.testing.assert_allclose(scores, [0.9, 0.5])
    # centre (20 + 16, 12 + 16) at the working scale -> (72, 112) at full resolution; 72 x 144 box
    np.testing.assert_allclose(boxes[0], [72 - 36, 112 - 72, 72, 144])


def test_input_policy():
    rng = np.random.default_rng(2)
    windows = (3 + 2 * rng.standard_normal((20, 64, 64))).astype(np.float32)
    raw = policies.InputPolicy("raw", windows).windows(windows)
    assert raw.shape == (20, 32, 32) and abs(raw.mean()) < 1e-3 and abs(raw.std() - 1) < 1e-3
    std = policies.InputPolicy("standardize", windows).windows(windows)
    np.testing.assert_allclose(std.mean((1, 2)), 0, atol=1e-4)
    with pytest.raises(InputError):
        policies.InputPolicy("standardize", windows).image(windows[0])
    with pytest.raises(InputError):
        policies.InputPolicy("whiten", windows)


def test_relight_is_deterministic_and_in_range():
    w = np.random.default_rng(0).random((4, 64, 64)).astype(np.float32)
    a = detect_data.relight_windows(w, np.random.default_rng(3))
    np.testing.assert_array_equal(a, detect_data.relight_windows(w, np.random.default_rng(3)))
    assert a.dtype == np.float32 and a.min() >= 0 and a.max() <= 1
    assert not np.allclose(a, w)


def test_standardize_windows_with_the_benchmarks_eps():
    w = np.random.default_rng(1).random((4, 64, 64)).astype(np.float32)
    s = standardize_windows(w * 3 + 1, eps=policies.BENCH_STANDARDIZE_EPS)
    np.testing.assert_allclose(s.mean((1, 2)), 0, atol=1e-4)
    np.testing.assert_allclose(s.std((1, 2)), 1, atol=1e-3)


def test_training_set_is_shared_and_labelled(small_data):
    data = detect_data.load_data(small_data)
    settings = S.DetectSettings(positives_per_object=12, negatives_ratio=1.0)
    a = detect_data.training_set(data, 1, settings)
    b = detect_data.training_set(data, 1, settings)
    np.testing.assert_array_equal(a.windows, b.windows)  # every method trains on the same windows
    assert a.windows.shape == (72, 64, 64) and a.windows.dtype == np.uint8
    assert np.bincount(a.labels).tolist() == [36, 12, 12, 12]
    assert a.images_used == {"matte_box": 1, "velvet_toy": 1, "specular_can": 1}
    assert detect_data.training_set(data, 10, settings).images_used["matte_box"] == 3  # all the small set has


def test_end_to_end_small(small_data, tmp_path, monkeypatch):
    out = tmp_path / "out"
    out.mkdir()
    (out / "pr_matte_box_10real.png").write_bytes(b"")  # an earlier run's curve (other real images): removed

    def broken(*args, **kwargs):
        raise RuntimeError("boom")

    # a run failing once its method is built (not the spec's fault: out of memory, a device error)
    real_normalize = D._normalize_training
    monkeypatch.setattr(
        D, "_normalize_training", lambda norm, ts: broken() if norm.name == "he" else real_normalize(norm, ts)
    )
    built = []
    real_create = D.create_normalization
    monkeypatch.setattr(D, "create_normalization", lambda m, p=None: built.append(m) or real_create(m, p))
    settings = S.DetectSettings(
        methods=["none", "dog", "he"],
        real_images=[1],
        policies=["raw", "local"],
        positives_per_object=8,
        epochs=1,
        batch_size=32,
        threads=1,
        tune=True,
    )
    result = D.main(small_data, out, settings, progress=False)
    assert (out / "detect.md").is_file() and (out / "detect.json").is_file()
    assert not (out / "detect.partial.json").exists()
    assert sorted(p.name for p in out.glob("pr_*.png")) == sorted(
        f"pr_{n}_1real.png" for n in ("matte_box", "velvet_toy", "specular_can")
    )
    saved = json.loads((out / "detect.json").read_text())
    assert saved["runs"]["he|1|raw|0"]["error"] == "RuntimeError: boom"  # reported, the run went on
    # each method built once, DoG once per setting of its grid: its runs take the chosen one's
    assert built == ["none", "dog", "he"] + ["dog"] * len(D.TUNING_GRIDS["dog"])
    for key in ("none|1|raw|0", "dog|1|local|0"):
        aucs = [obj["auc"] for obj in saved["runs"][key]["objects"].values()]
        assert any(a is not None for a in aucs) and all(a is None or 0 <= a <= 1 for a in aucs), aucs
    tuned = saved["tuned"]["1"]["dog"]
    assert [t["params"] for t in tuned["trials"]] == D.TUNING_GRIDS["dog"]
    assert all(0 <= t["val_auc"] <= 1 and set(t["val_auc_by_policy"]) == {"raw", "local"} for t in tuned["trials"])
    assert saved["runs"]["dog|1|local|0"]["params"] == tuned["params"] and saved["val_images"] == [1, 2, 3]
    assert "error" in saved["summary"]["he|1|raw"]
    assert saved["summary"]["dog|1|local"]["seeds"] == [0]
    md = (out / "detect.md").read_text()
    instances = {name: obj["num_gt"] for name, obj in saved["runs"]["none|1|raw|0"]["objects"].items()}
    assert (
        "failed" in md
        and "- **Test instances per object:** " + ", ".join(f"{n} {k}" for n, k in instances.items()) in md
    )
    assert [round(v, 4) for v in saved["window_agreement"]["dog"].values()] == [
        1.0
    ]  # DoG looks no further than a window
    assert result["machine"]["cpu_count"] >= 1


def test_tuning_grids_have_one_size_start_at_the_default_and_stay_within_the_window():
    assert len({len(grid) for grid in D.TUNING_GRIDS.values()}) == 1 and set(D.TUNING_GRIDS) == {"dog", "slcn", "dlcn"}
    for method, grid in D.TUNING_GRIDS.items():
        defaults = {k: v for k, v in parameters(method).items() if k in grid[0]}
        assert grid[0] == defaults, method  # a tie keeps the default
        assert len({tuple(p.values()) for p in grid}) == len(grid)
        assert all(3 * max(p.values()) <= S.RESNET_CONTEXT for p in grid), method  # a Gaussian reaches 3 sigma


def test_tuning_chooses_the_best_validation_auc_and_the_runs_use_it(small_data, tmp_path, monkeypatch):
    grid = D.TUNING_GRIDS["dog"]
    # per number of real images, the AUC of each setting: the best neither first nor last, tied with a later one
    known = {1: [0.5, 0.6, 0.8, 0.7, 0.8, 0.4], 2: [0.5, 0.9, 0.3, 0.3, 0.3, 0.6]}
    calls = []

    data = detect_data.load_data(small_data)
    validation = detect_data.read_images(data.val, data.working_scale)

    def scored(state, method, n_real, params, val_images):
        calls.append((method, n_real, params, len(val_images)))
        # the validation images, normalized with the setting scored
        expected = D._normalize_images(D.create_normalization(method, params), validation)
        assert [t.id for t in val_images] == [t.id for t in expected]
        assert all(np.array_equal(t.image, e.image) for t, e in zip(val_images, expected))
        auc = known[n_real][grid.index(params)]
        return {"local": auc, "raw": auc - 0.2}

    monkeypatch.setattr(D, "_validation_aucs", scored)
    settings = S.DetectSettings(
        methods=["none", "dog"], real_images=[1, 2], policies=["local", "raw"], tune=True, **TINY
    )
    result = D.main(small_data, tmp_path / "out", settings, progress=False)
    assert calls == [("dog", n, p, 3) for n in (1, 2) for p in grid]  # every setting, on the 3 validation images
    for n_real, best in ((1, 2), (2, 1)):
        tuned = result["tuned"][str(n_real)]["dog"]
        assert tuned["params"] == grid[best]
        assert [t["val_auc"] for t in tuned["trials"]] == pytest.approx([a - 0.1 for a in known[n_real]])
        for policy in ("local", "raw"):
            assert result["runs"][S.run_key("dog", n_real, policy, 0)]["params"] == grid[best]
    assert result["runs"][S.run_key("none", 1, "local", 0)]["params"] == {}
    md = (tmp_path / "out" / "detect.md").read_text()
    assert "dog tuned by detection on the validation images" in md and "the 3 validation images (`val.json`" in md
    assert "| 1 | `dog:sigma1=1.0:sigma2=2.0` | 0.700 | 0.400 | 0.300-0.700 |" in md
    saved = json.loads((tmp_path / "out" / "detect.json").read_text())
    assert saved["tuned"]["2"]["dog"]["params"] == grid[1] and saved["val_images"] == [1, 2, 3]


def test_a_grid_that_scores_alike_says_the_validation_cannot_tell(small_data, tmp_path, monkeypatch):
    """Every setting at AUC 1.000 on two easy validation images kept the default without a word."""
    monkeypatch.setattr(D, "_validation_aucs", lambda *a: {"local": 1.0})
    settings = S.DetectSettings(methods=["none", "dog"], real_images=[1], policies=["local"], tune=True, **TINY)
    D.main(small_data, tmp_path / "out", settings, progress=False)
    md = (tmp_path / "out" / "detect.md").read_text()
    assert "Every setting scored the same for dog (1): the default was kept" in md


def test_validation_aucs_train_as_the_first_seeds_runs(small_data, monkeypatch):
    data = detect_data.load_data(small_data)
    settings = S.DetectSettings(
        methods=["slcn"], seeds=[3, 4], policies=["raw", "local"], positives_per_object=4, epochs=1, batch_size=16
    )
    state = D._Run(data, settings, [])
    fitted, evaluated = [], []
    fit, evaluate = D._fit, D._evaluate
    monkeypatch.setattr(
        D, "_fit", lambda st, m, n, pol, seed, nz: fitted.append((m, n, pol, seed)) or fit(st, m, n, pol, seed, nz)
    )
    monkeypatch.setattr(D, "_evaluate", lambda d, coco, *a: evaluated.append(coco) or evaluate(d, coco, *a))
    params = D.TUNING_GRIDS["slcn"][1]
    val = D._normalize_images(
        D.create_normalization("slcn", params), detect_data.read_images(data.val, data.working_scale)
    )
    aucs = D._validation_aucs(state, "slcn", 1, params, val)
    assert fitted == [("slcn", 1, "raw", 3), ("slcn", 1, "local", 3)]  # the first seed's windows, each policy
    assert evaluated == [data.val, data.val] and set(state.training_sets) == {(3, 1)}
    assert set(aucs) == {"raw", "local"} and all(0 <= a <= 1 for a in aucs.values())


def test_tuning_without_validation_images_is_one_line_before_any_work(small_data, tmp_path, capsys):
    data = tmp_path / "data"
    shutil.copytree(small_data, data)
    (data / "val.json").unlink()
    out = tmp_path / "o"
    argv = ["bench", "detect", "--data", str(data), "--out", str(out), "--conf", "small", "--tune"]
    assert cli_main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err == (
        f"alcn bench detect: error: {data}: no val.json, the validation images --tune scores its settings on: render "
        "the data again with `alcn data detect`, or add test-like images of the objects as val.json (COCO, as "
        "test.json)"
    )
    assert not out.exists()
    # without --tune, or with no method to tune, the data need no validation images
    quick = dict(real_images=[1], **TINY)
    D.main(data, tmp_path / "untuned", S.DetectSettings(methods=["dog"], **quick), progress=False)
    D.main(data, tmp_path / "nothing to tune", S.DetectSettings(methods=["none"], tune=True, **quick), progress=False)
    (data / "val.json").write_text(json.dumps({"images": [], "annotations": [], "categories": []}))
    with pytest.raises(InputError, match="no object in val.json"):
        D.main(data, out, S.DetectSettings(methods=["dlcn"], tune=True))
    assert not out.exists()
    # data rendered with --n-test 0: refused before the training, whose every run failed after it
    test = json.loads((data / "test.json").read_text())
    (data / "test.json").write_text(json.dumps({**test, "images": [], "annotations": []}))
    with pytest.raises(InputError, match="no test image in test.json: render the data again with `--n-test` 1"):
        D.main(data, out, S.DetectSettings(methods=["none"], **quick), progress=False)
    assert not out.exists()


def test_cli_and_bad_input(small_data, tmp_path):
    assert cli_main(["bench", "detect", "--data", str(tmp_path), "--out", str(tmp_path / "o")]) == 2
    assert (
        cli_main(
            [
                "bench",
                "detect",
                "--data",
                str(small_data),
                "--out",
                str(tmp_path / "o"),
                "--methods",
                "none,nonexistent",
            ]
        )
        == 2
    )
    with pytest.raises(DatasetError, match="no train.json nor manifest.json: not a detection set"):
        detect_data.load_data(tmp_path)  # a folder of another kind: its missing manifest was blamed
    with pytest.raises(DatasetError, match="not a folder"):
        detect_data.load_data(tmp_path / "missing")
    with pytest.raises(SystemExit):
        cli_main(["bench", "--help"])


def test_a_bad_weight_file_is_one_line_before_any_work(small_data, tmp_path, capsys, monkeypatch):
    bad = tmp_path / "detector.pt"
    bad.write_bytes(b"not an npz")
    monkeypatch.setattr(D, "read_images", lambda *a: pytest.fail("the benchmark started"))
    out = tmp_path / "o"
    argv = ["bench", "detect", "--data", str(small_data), "--out", str(out), "--conf", "small"]
    assert cli_main([*argv, "--methods", f"none,alcn:weights={bad}"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"alcn bench detect: error: method 'alcn:weights={bad}': weight file {bad} is not a .npz archive"
    assert not out.exists()
    with pytest.raises(InputError, match="'alcn:scale=-1'"):  # a bad parameter, too
        build_methods(["alcn:scale=-1"], D.create_normalization)


def _report_result(settings, runs, names=("a", "b")):
    from dataclasses import asdict

    from alcn_cv.bench.detect_report import detect_command
    from alcn_cv.report import machine

    return {
        "settings": asdict(settings),
        "summary": D.summarize(runs, settings, list(names)),
        "runs": runs,
        "machine": machine(),
        "command": detect_command("d", "o", settings),
        "data": "/d",
        "test_images": [1],
        "working_scale": 0.5,
        "box_size": 36.0,
        "seconds": 1.0,
    }


def test_tables_and_curves_say_how_many_real_images_were_used(tmp_path, monkeypatch):
    from alcn_cv.bench import plots
    from alcn_cv.bench.detect_report import detect_markdown, real_images_label

    methods = ["none", "he", "clahe", "ns", "dog", "slcn", "dlcn", "lrn", "whitening", "alcn:weights=out/x/y.npz"]
    settings = S.DetectSettings(methods=methods, real_images=[1, 10], policies=["raw"])
    curve = {"auc": 0.5, "num_gt": 1, "pr": {"recall": [0.0, 1.0], "precision": [1.0, 0.5]}}
    runs = {
        S.run_key(m, n, "raw", 0): {
            "real_images": n,
            "images_used": {"a": min(n, 3), "b": min(n, 3)},
            "objects": {"a": curve, "b": {"auc": None, "num_gt": 0}},  # b: no instance in the test images
        }
        for m in methods
        for n in (1, 10)
    }
    md = detect_markdown(_report_result(settings, runs), ["a", "b"])
    assert "## 1 real image(s) per object, input policy `raw`" in md
    assert "## 3 real image(s) per object (10 requested), input policy `raw`" in md
    assert "10 requested: a 3, b 3" in md and "no instance of b" in md
    assert real_images_label(10, {"a": 3, "b": 10}) == "3-10 real image(s) (10 requested; a 3)"
    figures = {}
    monkeypatch.setattr(plots, "save_figure", lambda plt, fig, path: figures.setdefault(path.name, fig))
    names = plots.pr_figure_names(["a", "b"], settings.real_images)
    plots.plot_pr_curves(_report_result(settings, runs), ["a", "b"], [tmp_path / name for name in names])
    ax = figures["pr_a_10real.png"].axes[0]
    assert ax.get_title().startswith("a, 3 real image(s) (10 requested), input raw")
    # every method's curve is the same: one entry names them all, on lines that keep the legend narrow
    (entry,) = [t.get_text() for t in ax.get_legend().get_texts()]
    assert "alcn:weights=out/x/y.npz" in entry.replace("\n", "") and max(map(len, entry.splitlines())) <= 40
    assert "no instance of b" in figures["pr_b_1real.png"].axes[0].texts[0].get_text()


@pytest.mark.parametrize("policy", ["raw", "local"])
def test_batched_score_maps_equal_single(policy):
    torch.manual_seed(0)
    net = Detector(3, hidden=16).eval()
    rng = np.random.default_rng(4)
    images = [
        rng.random((40, 44)).astype(np.float32),
        rng.random((36, 40)).astype(np.float32),
        rng.random((40, 44)).astype(np.float32),
    ]
    pol = policies.InputPolicy(policy, rng.random((4, 64, 64)).astype(np.float32))
    batched = D._all_score_maps(net, images, pol, "cpu", batch=2)
    for img, p in zip(images, batched):
        np.testing.assert_allclose(p, D.score_maps(net, img, pol), atol=1e-5)


def test_method_specs_and_seeds(tmp_path):
    norm = D.create_normalization("alcn:model=lite:mixture=pyramid", {})
    assert (norm.mixture, norm.scale, norm.net.stride) == ("pyramid", 1.0, 8)
    assert D.create_normalization("dog:sigma2=2.5", {"sigma1": 1.0}).sigma2 == 2.5
    S.DetectSettings(methods=["alcn", "alcn:model=lite"], seeds=[0, 1]).check()
    for bad in (
        dict(methods=["nope:x=1"]),
        dict(methods=["cnn:depth=2"]),
        dict(seeds=[]),
        dict(seeds=[1, 1]),
    ):
        with pytest.raises(InputError):
            S.DetectSettings(**bad).check()
    with pytest.raises(InputError, match="method 'dog' is listed twice"):  # by build_methods, before any work
        D.main(tmp_path / "no data", tmp_path / "out", settings=S.DetectSettings(methods=["dog", "none", "dog"]))


def test_summarize_over_seeds():
    settings = S.DetectSettings(methods=["dog"], real_images=[1], policies=["local"], seeds=[0, 1, 2])
    objects = lambda a, b: {"a": {"auc": a}, "b": {"auc": b}}  # noqa: E731
    runs = {
        S.run_key("dog", 1, "local", 0): {"objects": objects(0.2, 0.4)},
        S.run_key("dog", 1, "local", 1): {"objects": objects(0.4, None)},
        S.run_key("dog", 1, "local", 2): {"error": "RuntimeError: boom"},
    }
    cell = D.summarize(runs, settings, ["a", "b"])["dog|1|local"]
    assert cell["seeds"] == [0, 1] and cell["failed_seeds"] == [2]
    assert cell["objects"]["a"]["mean"] == pytest.approx(0.3)
    assert cell["objects"]["a"]["std"] == pytest.approx(0.1 * 2**0.5)  # the sample deviation (ddof=1)
    assert cell["objects"]["b"]["values"] == [0.4]
    assert cell["mean"]["values"] == pytest.approx([0.3, 0.4])


def test_training_is_reproducible_whatever_ran_before(small_data):
    data = detect_data.load_data(small_data)
    settings = S.DetectSettings(positives_per_object=6, epochs=1, batch_size=16)
    ts = detect_data.training_set(data, 1, settings, seed=3)
    windows = ts.windows[:, 16:48, 16:48].astype(np.float32) / 255

    def weights():
        net = D._train("none", windows, ts.labels, 4, settings, 3, (windows[:4], ts.labels[:4]))
        return torch.cat([p.detach().flatten() for p in net.parameters()])

    first = weights()
    torch.rand(100)  # other work drawing from the global generator in between
    np.testing.assert_array_equal(weights().numpy(), first.numpy())


def test_resnets_train_with_context_under_dense_policies(small_data):
    data = detect_data.load_data(small_data)
    settings = S.DetectSettings(positives_per_object=4, epochs=1, batch_size=16)
    ts = detect_data.training_set(data, 1, settings)
    windows = ts.windows.astype(np.float32) / 255
    policy = policies.InputPolicy("local", windows)
    assert D._context("resnet20", "local") == S.RESNET_CONTEXT == 16 and D._context("resnet20", "standardize") == 0
    assert D._context("cnn", "local") == 0
    inputs = policy.windows(windows, 32 + 2 * S.RESNET_CONTEXT)
    assert inputs.shape == (len(windows), 64, 64)
    np.testing.assert_array_equal(inputs[:, 16:48, 16:48], policy.windows(windows))
    net = D._train("resnet20", inputs, ts.labels, 4, settings, 0, (inputs[:4], ts.labels[:4]))
    assert net.context == 16
    with pytest.raises(InputError, match="context"):
        policies.InputPolicy("standardize", windows).windows(windows, 64)


def test_alcn_opencv_backend_runs_end_to_end(small_data, tmp_path):
    """The cv2.dnn backend normalizes the training windows through ALCN.normalize_windows (it
    once failed with "'OpenCVNormalizer' object is not callable")."""
    settings = S.DetectSettings(methods=["alcn:backend=opencv"], real_images=[1], policies=["local"], **TINY)
    result = D.main(small_data, tmp_path / "out", settings, progress=False)
    run = result["runs"][S.run_key("alcn:backend=opencv", 1, "local", 0)]
    assert "error" not in run, run.get("error")
    md = (tmp_path / "out" / "detect.md").read_text()
    assert "**Machine:**" in md and "alcn bench detect" in md and "`local`" in md and "no spread" in md


def test_pr_curves_stop_at_the_last_true_positive_and_ties_are_grouped():
    from alcn_cv.bench import plots

    recall, precision = plots.trim_pr_curve([0.2, 0.5, 0.5, 0.8, 0.8, 0.8], [1.0, 0.9, 0.6, 0.7, 0.3, 0.03])
    np.testing.assert_array_equal(recall, [0.2, 0.5, 0.5, 0.8])
    np.testing.assert_array_equal(precision, [1.0, 0.9, 0.6, 0.7])
    same = ([0.1, 0.4], [1.0, 0.5])
    assert plots._ties({"none": ([0.2], [1.0]), "dlcn": same, "alcn": ([0.3], [0.9]), "whitening": same}) == {
        "none": ["none"],
        "dlcn": ["dlcn", "whitening"],
        "alcn": ["alcn"],
    }
    styles = plots.method_styles(["none", "alcn", "ns", "dog", "slcn", "dlcn", "lrn", "whitening"])
    assert styles["none"][0] != styles["alcn"][0] and styles["dlcn"][0] != styles["whitening"][0]


def test_report_gives_mean_and_spread_over_seeds():
    from alcn_cv.bench.detect_report import detect_command, detect_markdown

    settings = S.DetectSettings(methods=["dog"], real_images=[1], policies=["raw"], seeds=[0, 1])
    runs = {
        S.run_key("dog", 1, "raw", 0): {"objects": {"a": {"auc": 0.2}}},
        S.run_key("dog", 1, "raw", 1): {"objects": {"a": {"auc": 0.4}}},
    }
    md = detect_markdown(_report_result(settings, runs, names=["a"]), ["a"])
    assert md.startswith("# Detection benchmark (rendered objects") and "(data)" not in md.splitlines()[0]
    assert "| dog | 0.300 ± 0.141 | 0.300 ± 0.141 |" in md and "2 (0, 1)" in md  # the sample deviation
    # recorded in the space form of --seeds, which parses back to the same seeds
    assert "--seeds 0 1 --methods dog" in md and "`raw`: the normalized windows" in md
    assert build_parser().parse_args(shlex.split(detect_command("d", "o", settings))[1:]).seeds == [0, 1]


@pytest.mark.parametrize("given", [["0", "1", "2"], ["0,1,2"], ["0,1", "2"]])
def test_seeds_take_spaces_and_commas_as_relight(given):
    parsed = build_parser().parse_args(["bench", "detect", "--data", "d", "--out", "o", "--seeds", *given])
    assert parsed.seeds == [0, 1, 2]
    assert build_parser().parse_args(["bench", "detect", "--data", "d", "--out", "o"]).seeds is None  # the preset's


def test_a_seed_that_is_no_integer_is_one_clear_error(capsys):
    with pytest.raises(SystemExit) as exit_:
        build_parser().parse_args(["bench", "detect", "--data", "d", "--out", "o", "--seeds", "0,a"])
    assert exit_.value.code == 2
    assert (
        capsys.readouterr()
        .err.splitlines()[-1]
        .endswith("argument --seeds: a seed is an integer (e.g. --seeds 0 1 2 or 0,1,2), got 'a'")
    )


def test_the_cnn_sweep_keeps_the_most_accurate_then_the_lowest_loss(monkeypatch):
    from alcn_cv.train import stage2

    scores = {(1, 32): (0.40, 0.9), (2, 32): (0.30, 0.9), (3, 32): (0.20, 0.8)}  # (loss, accuracy)
    monkeypatch.setattr(D, "_train", lambda method, train, labels, n, settings, seed, val, config: config)
    monkeypatch.setattr(stage2, "evaluate_detector", lambda net, *val: scores[net])
    net, record = D._train_cnn_sweep(None, None, 3, S.DetectSettings(cnn_sweep=list(scores)), 0, (None, None))
    assert net == (2, 32) and record["chosen"] == {"depth": 2, "width": 32}
