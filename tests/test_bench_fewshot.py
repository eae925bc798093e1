"""``alcn bench fewshot``: every registered normalization reaches the same detector the same way."""

from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from alcn_cv.bench import fewshot as B  # noqa: E402
from alcn_cv.bench.detect import create_normalization  # noqa: E402
from alcn_cv.bench.methods import build_methods  # noqa: E402
from alcn_cv.bench.policies import InputPolicy  # noqa: E402
from alcn_cv.cli import main as cli_main  # noqa: E402
from alcn_cv.data.phos import PhosBatch  # noqa: E402
from alcn_cv.errors import InputError  # noqa: E402
from alcn_cv.train import fewshot as F  # noqa: E402


def _tiny_data(setup):
    rng = np.random.default_rng(setup.seed)
    n, m = 24, 16
    test = PhosBatch(
        windows=rng.integers(0, 256, (m, 64, 64), dtype=np.uint8),
        labels=np.arange(m) % 3,
        light_ids=np.arange(m) % 2,
        kinds=np.zeros(m, np.int64),
        offsets=np.zeros((m, 2), np.float32),
        extents=np.zeros(m, np.float32),
        n_objects=2,
        object_seed=setup.object_seed,
        seed=setup.seed,
        light_families=["dark", "side"],
    )
    return rng.integers(0, 256, (n, 64, 64), dtype=np.uint8), np.arange(n) % 3, test


@pytest.mark.parametrize("policy", ["raw", "local"])
def test_every_spec_reaches_the_detector_through_normalize_windows(policy, monkeypatch):
    seen = {}

    def record(name, train_inputs, train_labels, test_inputs, test, setup, progress=False):
        seen[name.split(" ")[0]] = (train_inputs, test_inputs, setup)
        return {"accuracy": 0.5, "auc": 0.5, "by_family": {}}

    monkeypatch.setattr(F, "make_fewshot_data", _tiny_data)
    monkeypatch.setattr(F, "score_inputs", record)
    settings = B.FewShotSettings(methods=["none", "dog", "alcn:model=gain"], policies=[policy], seeds=[0], n_objects=2)
    runs = {policy: {m: [] for m in settings.methods}}
    B._run_seed(settings, 0, build_methods(settings.methods, create_normalization), runs, B.tqdm(disable=True))
    train_x, _, test = _tiny_data(settings.setup(0))
    for method in settings.methods:
        norm = create_normalization(method, {})
        train_n, test_n = norm.normalize_windows(train_x), norm.normalize_windows(test.windows)
        pol = InputPolicy(policy, train_n)
        train_inputs, test_inputs, setup = seen[method]
        np.testing.assert_allclose(train_inputs, pol.windows(train_n), atol=1e-6)
        np.testing.assert_allclose(test_inputs, pol.windows(test_n), atol=1e-6)
        assert train_inputs.shape[1:] == (32, 32) and (setup.seed, setup.n_objects) == (0, 2)
    assert create_normalization("alcn:model=gain", {}).scale == 1.0


def test_seeds_differ_and_settings_check(tmp_path):
    s = B.FewShotSettings(seeds=[0, 5])
    assert (s.setup(5).seed, s.setup(5).object_seed) == (5, s.object_seed + 5)
    assert B.FewShotSettings().seeds == [0, 1, 2]  # the repetitions of the former default --draws 3, seed for seed
    for bad in (
        dict(methods=["nope"]),
        dict(policies=["sideways"]),
        dict(seeds=[]),
        dict(seeds=[1, 1]),
        dict(seeds=[-1]),
        dict(methods=[]),
    ):
        with pytest.raises(InputError):
            B.FewShotSettings(**bad).check()
    with pytest.raises(InputError, match="method 'dog' is listed twice"):  # by build_methods, before any seed runs
        B.main(tmp_path / "out", B.FewShotSettings(methods=["dog", "dog"]))


def test_fewshot_setup_owns_the_names_and_defaults():
    """The bench settings and the training config's [fewshot] name each setup field as FewShotSetup does and
    default to its value."""
    from dataclasses import fields

    from alcn_cv.train.config import FewShotConfig

    own = {f.name for f in fields(F.FewShotSetup)}
    for settings, extra in (
        (B.FewShotSettings(), {"methods", "policies", "seeds", "tune", "threads"}),
        (FewShotConfig(), {"enabled", "dog"}),
    ):
        assert {f.name for f in fields(settings)} - own == extra
        assert F.FewShotSetup.of(settings) == F.FewShotSetup()
    assert B.FewShotSettings(n_objects=3, n_test=40).setup(2) == F.FewShotSetup(
        n_objects=3, n_test=40, object_seed=F.FewShotSetup.object_seed + 2, seed=2
    )


def test_compare_to_dog_takes_the_best_dog_per_seed():
    settings = B.FewShotSettings(methods=["dog", "dog:sigma1=1:sigma2=2", "alcn"], policies=["raw"], seeds=[4, 5, 6])
    runs = {
        "raw": {
            "dog": [{"auc": 0.7}, {"auc": 0.8}, {"auc": 0.6}],
            "dog:sigma1=1:sigma2=2": [{"auc": 0.75}, {"error": "x"}, {"auc": 0.5}],
            "alcn": [{"auc": 0.74}, {"auc": 0.81}, {"error": "y"}],
        }
    }
    rows = B.compare_to_dog(runs, settings)["raw"]["alcn"]
    assert [r["above"] for r in rows] == [False, True, None] and [r["seed"] for r in rows] == [4, 5, 6]
    assert rows[0]["dog"] == "dog:sigma1=1:sigma2=2" and rows[0]["margin"] == pytest.approx(-0.01)
    assert B.compare_to_dog(runs, B.FewShotSettings(methods=["dog"], policies=["raw"], seeds=[4, 5, 6])) == {}


def test_fewshot_validation_is_score_inputs_of_each_method():
    setup = F.FewShotSetup(n_objects=2, epochs=1, seed=0)
    data = _tiny_data(setup)
    none = lambda x: x[..., 16:48, 16:48]  # noqa: E731
    result = F.fewshot_validation({"none": none}, setup, data)
    train_x, train_y, test = data
    centre = lambda w: np.ascontiguousarray(w[:, 16:48, 16:48], np.float32) / np.float32(255)  # noqa: E731
    assert result["none"] == F.score_inputs("none", centre(train_x), train_y, centre(test.windows), test, setup)


def test_cli_end_to_end(tmp_path):
    out = tmp_path / "fs"
    code = cli_main(
        [
            "bench",
            "fewshot",
            "--out",
            str(out),
            "--methods",
            "none,dog,alcn",
            "--policy",
            "raw",
            "--seeds",
            "3",
            "--objects",
            "2",
            "--per-image",
            "6",
            "--n-test",
            "30",
            "--epochs",
            "1",
            "--threads",
            "1",
        ]
    )
    assert code == 0
    saved = json.loads((out / "fewshot.json").read_text())
    assert set(saved["runs"]["raw"]) == {"none", "dog", "alcn"}
    assert 0 <= saved["runs"]["raw"]["alcn"][0]["auc"] <= 1 and saved["runs"]["raw"]["alcn"][0]["seed"] == 3
    assert saved["settings"]["seeds"] == [3] and "draws" not in saved["settings"]
    assert saved["alcn_vs_dog"]["raw"]["alcn"][0]["above"] in (True, False)
    # the recorded command spells --seeds as `alcn bench detect` does, and runs again
    assert saved["command"].startswith(f"alcn bench fewshot --out {out} --seeds 3 ")
    text = (out / "fewshot.md").read_text()
    assert "ALCN against the best DoG" in text and "--seeds 3" in text and "| seed 3 |" in text
    assert "±" not in text  # one seed has no spread: "± 0.000" would read as a measured one
    assert (out / "fewshot.png").stat().st_size > 0
    assert cli_main(["bench", "fewshot", "--out", str(out), "--methods", "nope"]) == 2


def test_a_bad_weight_file_is_one_line_before_any_seed_runs(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(F, "make_fewshot_data", lambda *a: pytest.fail("a seed's run started"))
    out = tmp_path / "fs"
    assert cli_main(["bench", "fewshot", "--out", str(out), "--methods", "none,alcn:weights=some/detector.pt"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (
        "alcn bench fewshot: error: method 'alcn:weights=some/detector.pt': weight file not found: some/detector.pt"
    )
    assert not out.exists()


def test_cells_give_the_spread_over_seeds():
    from alcn_cv.report import spread_cell

    assert spread_cell({"mean": 0.75, "std": 0.05, "values": [0.7, 0.8]}) == "0.750 ± 0.050"
    assert spread_cell({"mean": 0.75, "std": 0.0, "values": [0.75]}) == "0.750"
    assert spread_cell({"mean": 75.0, "std": 0.0, "values": [75.0, 75.0]}, 1, runs=1) == "75.0"  # one seed of two


def test_seeds_is_the_option_of_bench_detect(tmp_path):
    """--seeds as `alcn bench detect` takes it (space or comma form); not given, the settings' default holds."""
    from alcn_cv.bench.cli import _run_fewshot
    from alcn_cv.cli import build_parser

    parser = build_parser()
    args = parser.parse_args(["bench", "fewshot", "--out", str(tmp_path), "--seeds", "0,1", "4"])
    assert args.seeds == [0, 1, 4] and args.func is _run_fewshot
    assert parser.parse_args(["bench", "fewshot", "--out", str(tmp_path)]).seeds is None
    with pytest.raises(SystemExit):
        parser.parse_args(["bench", "fewshot", "--out", str(tmp_path), "--draws", "3"])


def test_tune_chooses_each_setting_on_a_validation_draw_of_its_own(tmp_path, monkeypatch):
    """--tune scores every setting of DoG's and DLCN's grids on new objects and windows that no seed's run uses; the
    first best serves the runs (a tie keeps the default, the grid's first)."""
    setups, built = [], []

    def data(setup):
        setups.append(setup)
        return _tiny_data(setup)

    def score(name, train, labels, test, batch, setup):
        best = "sigma=3.0" in name or "sigma1=1.0:sigma2=3.0" in name
        return {"auc": 0.9 if "validation" in name and best else 0.5, "accuracy": 0.5}

    real = B.create_normalization
    monkeypatch.setattr(F, "make_fewshot_data", data)
    monkeypatch.setattr(F, "score_inputs", score)
    monkeypatch.setattr(B, "create_normalization", lambda m, p=None: built.append((m, p)) or real(m, p))
    settings = B.FewShotSettings(methods=["none", "dog", "dlcn"], policies=["raw", "local"], seeds=[0, 1], tune=True)
    result = B.main(tmp_path / "fs", settings, progress=False)

    validation, *runs = setups
    assert (validation.object_seed, validation.seed) == (settings.object_seed - 1, B.VALIDATION_SEED)
    assert [(s.object_seed, s.seed) for s in runs] == [(settings.object_seed, 0), (settings.object_seed + 1, 1)]
    assert result["tuned"]["dlcn"]["params"] == {"sigma": 3.0} and len(result["tuned"]["dlcn"]["trials"]) == 6
    assert result["tuned"]["dog"]["params"] == {"sigma1": 1.0, "sigma2": 3.0}
    # built once to be tried, once more for the runs
    assert built.count(("dlcn", {"sigma": 3.0})) == built.count(("dog", {"sigma1": 1.0, "sigma2": 3.0})) == 2
    md = (tmp_path / "fs" / "fewshot.md").read_text()
    assert "--tune" in result["command"] and "## Tuned on the validation draw" in md
    assert "| dlcn:sigma=3.0 (tuned) |" in md  # the rows say which setting ran
    settings.tune = False
    assert B.main(tmp_path / "untuned", settings, progress=False)["tuned"] == {} and len(setups) == 5


def test_a_setting_whose_auc_cannot_be_computed_is_never_chosen(tmp_path, monkeypatch):
    monkeypatch.setattr(F, "make_fewshot_data", _tiny_data)
    monkeypatch.setattr(
        F, "score_inputs", lambda name, *a: {"auc": float("nan") if "sigma=2.0" in name else 0.5, "accuracy": 0.5}
    )
    settings = B.FewShotSettings(methods=["dlcn"], policies=["raw"], seeds=[0], tune=True)
    result = B.main(tmp_path / "fs", settings, progress=False)
    assert result["tuned"]["dlcn"]["params"] == {"sigma": 1.0}  # the default (NaN) passed over for the next
    assert json.loads((tmp_path / "fs" / "fewshot.json").read_text())["tuned"]["dlcn"]["trials"][0]["val_auc"] is None
