"""The experiment scripts of ``experiments/`` without their long runs: the rerun line docs/results.md gives runs the
command its report records, a GPU run's report is written where it ran and published here, ``--part`` runs each part
once in its order, and a report records what was measured."""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import json
import sys
import types
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import alcn_cv

ROOT = Path(__file__).resolve().parents[1]
EXPERIMENTS = ROOT / "experiments"
REPORTS = ROOT / "docs" / "reports"


@pytest.fixture
def experiments(monkeypatch: pytest.MonkeyPatch) -> types.ModuleType:
    """experiments/_run.py, imported as the scripts import it."""
    monkeypatch.syspath_prepend(str(EXPERIMENTS))
    return importlib.import_module("_run")


def _report_module() -> types.ModuleType:
    spec = importlib.util.spec_from_file_location("experiments_report", EXPERIMENTS / "report.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _kept(name: str) -> dict[str, Any]:
    return json.loads((REPORTS / f"{name}.json").read_text(encoding="utf-8"))


@pytest.mark.parametrize(
    ("script", "name"),
    [
        ("relight", "relight_split"),
        ("relight", "relight_leave_one_out"),
        ("learning", "relight_learning"),
        ("gain_lite", "relight_gain_lite_split"),
        ("gain_lite", "relight_gain_lite_leave_one_out"),
    ],
)
def test_the_rerun_line_runs_the_published_command(
    experiments: types.ModuleType,
    monkeypatch: pytest.MonkeyPatch,
    tmp_path: Path,
    script: str,
    name: str,
) -> None:
    """The quick protocol's options came from copies in each script and relight.py's seeds default to the published
    ones: the arguments a kept report records (as docs/results.md renders them) run exactly the command it
    records, replacing the run's earlier report (``--overwrite``, which the report's command leaves out)."""
    module = importlib.import_module(script)
    commands: list[tuple[str, ...]] = []
    monkeypatch.setattr(module, "RUNS", tmp_path)
    for runs in (module, experiments):  # the script's own calls, and _run.short_relight's
        if hasattr(runs, "alcn"):
            monkeypatch.setattr(runs, "alcn", lambda *argv: commands.append(("alcn", *argv)))
    monkeypatch.setattr(module, "keep", lambda *args, **kwargs: None)
    if hasattr(module, "untrained_start"):
        monkeypatch.setattr(module, "untrained_start", lambda trained, path, description: Path(path))
    report = _kept(name)
    exp = report["experiment"]
    monkeypatch.setattr(sys, "argv", [f"{script}.py", *exp["argv"]])
    module.main()
    benches = [c for c in commands if c[1:3] == ("bench", "relight")]
    assert benches and all("--overwrite" in c for c in benches)
    recorded = [" ".join(a for a in c if a != "--overwrite").replace(str(tmp_path), "OUT") for c in benches]
    assert report["command"] in recorded


def _keep_gpu_check(monkeypatch: pytest.MonkeyPatch, *argv: str) -> None:
    """experiments/keep_gpu_check.py ``argv``, in this process."""
    module = importlib.import_module("keep_gpu_check")
    monkeypatch.setattr(sys, "argv", ["keep_gpu_check.py", *argv])
    module.main()


def test_a_gpu_runs_report_is_written_where_it_ran_and_published_here(
    experiments: types.ModuleType, monkeypatch: pytest.MonkeyPatch, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    """experiments/gpu_check.sh kept its report into docs/reports on the GPU machine, whence only $GPU_CHECK_OUT comes
    back, with that folder's absolute path in it, and could not replace a published one: it writes the report to
    publish into $GPU_CHECK_OUT (the folder written OUT), and keep_gpu_check.py publishes it here, under keep's rule;
    the results page renders it with a rerun line that runs the shell script."""
    out = tmp_path / "came_back"  # $GPU_CHECK_OUT on the GPU machine: any folder
    machine = _kept("speed")["machine_before"]
    rows = [{"batch": 8, "end to end fps": 900.0, "on device fps": 2000.0, "kornia dog fps": 5000.0}]
    device = {"device": "cuda", "size": [1280, 800], "half_max_abs": 0.002, "device_vs_cpu_max_abs": 1e-5}
    speed = {"machine_before": machine, "machine_after": machine, "rows": rows, "device": device}

    def gpu_run(command: str) -> Path:
        """The report gpu_check.sh writes after a run of the bench ``command``."""
        (out / "speed_cuda").mkdir(parents=True, exist_ok=True)
        report = out / "speed_cuda" / "speed.json"
        report.write_text(json.dumps({**speed, "command": command}), encoding="utf-8")
        (out / "cuda_tests.xml").write_text(
            f'<testsuites><testsuite tests="8" failures="{failures}" errors="0"/></testsuites>'
        )
        return experiments.write_for_keeping(report, "speed_gpu", out, script="experiments/gpu_check.sh")

    failures = 0

    written = gpu_run(f"alcn bench speed --device cuda --out {out}/speed_cuda")
    assert written == out / "speed_gpu.json" and str(tmp_path) not in written.read_text()
    monkeypatch.setattr(experiments, "ROOT", tmp_path)
    monkeypatch.setattr(experiments, "REPORTS", tmp_path / "reports")
    _keep_gpu_check(monkeypatch, str(out))
    kept = json.loads((tmp_path / "reports" / "speed_gpu.json").read_text())
    assert kept["experiment"]["script"] == "experiments/gpu_check.sh" and kept["experiment"]["argv"] == []
    assert kept["command"] == "alcn bench speed --device cuda --out OUT/speed_cuda"
    text = _report_module().RENDERERS["speed_gpu"](kept)
    assert text.startswith("## Speed on a GPU\n") and "Rerun: `bash experiments/gpu_check.sh`." in text
    assert "| batch | end to end fps | on device fps | kornia dog fps |\n|---|---|---|---|\n| 8 | 900.0 |" in text
    # a run of another command replaces it only with --keep, as an experiment's report
    gpu_run(f"alcn bench speed --device cuda --device-batches 1,8 --out {out}/speed_cuda")
    _keep_gpu_check(monkeypatch, str(out))
    said = capsys.readouterr().out
    assert "not kept" in said and "`bash experiments/gpu_check.sh`" in said and "--keep" in said
    assert json.loads((tmp_path / "reports" / "speed_gpu.json").read_text()) == kept
    _keep_gpu_check(monkeypatch, str(out), "--keep")
    assert "--device-batches 1,8" in json.loads((tmp_path / "reports" / "speed_gpu.json").read_text())["command"]
    # a run whose CUDA tests failed: refused, whatever it measured
    failures = 1
    gpu_run(f"alcn bench speed --device cuda --out {out}/speed_cuda")
    with pytest.raises(SystemExit):
        _keep_gpu_check(monkeypatch, str(out), "--keep")
    assert "cuda_tests.xml: 1 CUDA test(s) failed: not published" in capsys.readouterr().err
    failures = 0
    # every CUDA test skipped (torch saw no GPU): refused too
    gpu_run(f"alcn bench speed --device cuda --out {out}/speed_cuda")
    (out / "cuda_tests.xml").write_text(
        '<testsuites><testsuite tests="8" skipped="8" failures="0" errors="0"/></testsuites>'
    )
    with pytest.raises(SystemExit):
        _keep_gpu_check(monkeypatch, str(out), "--keep")
    assert "cuda_tests.xml: no CUDA test ran (8 skipped): not published" in capsys.readouterr().err
    # the CPU rehearsal's report measured no GPU: refused
    device["device"] = "cpu"
    gpu_run(f"alcn bench speed --device cpu --out {out}/speed_cpu")
    with pytest.raises(SystemExit):
        _keep_gpu_check(monkeypatch, str(out), "--keep")
    assert "the CPU rehearsal's report" in capsys.readouterr().err


def test_a_machine_without_alcn_cv_installed_gets_its_commands(
    experiments: types.ModuleType, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """On the GPU machine the checkout runs from PYTHONPATH, alcn-cv not installed: `alcn bench speed --device cuda`
    found no subcommand ("invalid choice: 'bench' (choose from )"), since they are entry points of the installed
    distribution. gpu_check.sh writes its metadata first (install_metadata), and nothing where it is installed."""
    from importlib import metadata

    assert experiments.install_metadata(tmp_path / "installed") is None  # this environment's alcn-cv has them
    with monkeypatch.context() as patched:
        patched.setattr(metadata, "entry_points", lambda **kwargs: [])
        written = experiments.install_metadata(tmp_path / "site")
    assert written == tmp_path / "site" / f"alcn_cv-{alcn_cv.__version__}.dist-info"
    (dist,) = metadata.distributions(path=[str(tmp_path / "site")])
    commands = {e.name: e.value for e in dist.entry_points if e.group == "alcn_cv.commands"}
    ours = {e.name: e.value for e in metadata.entry_points(group="alcn_cv.commands")}
    assert commands == ours and {"bench", "normalize", "pose"} <= set(commands)
    assert [e.value for e in dist.entry_points if e.group == "console_scripts"] == ["alcn_cv.cli:main"]


class _StopError(Exception):
    """Raised by a stand-in where the test has seen what it needs."""


def test_the_quick_protocol_is_the_benchs_preset(
    monkeypatch: pytest.MonkeyPatch, experiments: types.ModuleType
) -> None:
    """The scripts spell out ``alcn bench relight --conf quick``'s settings: the bench's own command line, given them
    or ``--conf quick``, runs the benchmark with the same settings."""
    from alcn_cv.bench import relight
    from alcn_cv.cli import build_parser

    def settings(*options: str) -> tuple[Any, ...]:
        calls: list[tuple[Any, ...]] = []

        def record(*args: Any, **kwargs: Any) -> None:
            calls.append(args)
            raise _StopError

        monkeypatch.setattr(relight, "main", record)
        args = build_parser().parse_args(["bench", "relight", "--out", "x", *options])
        with pytest.raises(_StopError):
            args.func(args)
        return calls[0][1:]  # all but the output folder

    assert settings(*experiments.quick_protocol()) == settings("--conf", "quick") != settings()


def test_part_runs_each_part_once_in_its_order(
    experiments: types.ModuleType, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """relight.py and pose_planar.py ran --part's parts as typed (--part a a ran a twice, --part b a in that order):
    the five experiments with parts share one option, whose parts run once each in the experiment's order."""
    parts = ("data", "features", "corners")
    parser = experiments.command_line("doc")
    experiments.add_part_option(parser, parts)
    assert experiments.selected_parts(parser.parse_args(["--part", "corners", "data", "corners"]), parts) == [
        "data",
        "corners",
    ]
    assert experiments.selected_parts(parser.parse_args([]), parts) == list(parts)
    module = importlib.import_module("pose_planar")
    commands: list[tuple[str, ...]] = []
    monkeypatch.setattr(module, "RUNS", tmp_path)
    monkeypatch.setattr(module, "alcn", lambda *argv: commands.append(argv))
    monkeypatch.setattr(module, "keep", lambda *args, **kwargs: None)
    monkeypatch.setattr(sys, "argv", ["pose_planar.py", "--part", "corners", "features", "corners"])
    module.main()
    assert [c[3].rsplit("/", 1)[-1] for c in commands] == ["features", "corners"]
    for script in (
        "relight",
        "pose_planar",
        "pose_table1",
        "relief_training",
        "unet_baseline",
        "dog_band",
        "gain_lite",
    ):
        source = (EXPERIMENTS / f"{script}.py").read_text(encoding="utf-8")
        assert "add_part_option(parser" in source and "selected_parts(args" in source, script


def test_figure_publishes_only_the_readmes_photograph_and_out_may_be_the_published_path(
    experiments: types.ModuleType, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """figure.py --out docs/figure.png --publish ended in shutil.SameFileError; --publish with another photograph than
    the README's caption names published it."""
    import numpy as np

    module = importlib.import_module("figure")
    published = tmp_path / "figure.png"
    monkeypatch.setattr(module, "PUBLISHED", published)
    monkeypatch.setattr(module, "ROOT", tmp_path)
    monkeypatch.setattr(module, "figure", lambda path: np.full((8, 8), 128, np.uint8))
    monkeypatch.setattr(sys, "argv", ["figure.py", "--out", str(published), "--publish"])
    module.main()
    assert published.is_file()
    out = tmp_path / "other.png"
    monkeypatch.setattr(sys, "argv", ["figure.py", "--image", str(tmp_path / "my.jpg"), "--out", str(out), "--publish"])
    with pytest.raises(SystemExit):
        module.main()
    assert not out.exists()


def test_a_report_records_what_was_measured_not_keep(experiments: types.ModuleType) -> None:
    """relief_training.py's report recorded ``keep`` among its settings."""
    args = argparse.Namespace(keep=True, out=Path("/x/y"), identities=40)
    assert experiments.recorded_settings(args) == {"out": "/x/y", "identities": 40}


def test_relight_titles_say_their_protocol_and_the_speed_headline_its_cores() -> None:
    """The leave-one-scene-out section did not say it ran the quick protocol; the speed headline said 2 shared cores
    whatever the report's machine."""
    report = _report_module()
    loo = _kept("relight_leave_one_out")
    assert report.relight(loo).startswith(
        "## Real light, leave-one-scene-out (each scene with parameters tuned on the others; quick protocol: "
        "12 frames per scene, 150 patches, 12 pairs)\n"
    )
    assert report.relight(_kept("relight_split")).startswith(
        "## Real light, test scenes (tuned on courbevoie, frankfurt, panorama)\n"
    )
    speed = _kept("speed")
    speed["machine_before"] = {**speed["machine_before"], "cpus_available": 16}
    assert " on 16 cores, " in report.speed_headline(speed)


def test_unet_baselines_objective_part_is_the_bench_stage(
    experiments: types.ModuleType, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """unet_baseline.py's ``objective`` part calls alcn_cv.bench.objective.main with both files; the stage takes
    each network from its file's architecture and refuses another."""
    import numpy as np

    from alcn_cv.bench import objective
    from alcn_cv.data.relief_scenes import render_scenes
    from alcn_cv.data.scenes import Scene
    from alcn_cv.errors import InputError
    from alcn_cv.runtime import resolve_weights
    from alcn_cv.train.unet_normalizer import UNetNormalizer
    from alcn_cv.weight_file import save_normalizer_file

    calls: list[tuple[Any, ...]] = []
    module = importlib.import_module("unet_baseline")
    monkeypatch.setattr(objective, "main", lambda *args: calls.append(args))
    monkeypatch.setattr(sys, "argv", ["unet_baseline.py", "--out", str(tmp_path), "--part", "objective"])
    module.main()
    assert calls == [
        (
            tmp_path,
            {"unet": tmp_path / "train/unet_normalizer.npz", "gain": tmp_path / "gain/gain_normalizer.npz"},
            "gain",
            8,
        )
    ]
    monkeypatch.undo()

    frames = [f for f, _ in render_scenes(2, frames=3, side=96, seed=1, progress=False)]
    scenes = [Scene("courbevoie", "webcam", frames[0], ()), Scene("mexico", "webcam", frames[1], ())]
    monkeypatch.setattr(objective, "load_scenes", lambda roots: scenes)
    monkeypatch.setattr(objective, "TRAIN_SCENES", ("courbevoie",))
    monkeypatch.setattr(objective, "TEST_SCENES", ("mexico",))
    net = UNetNormalizer()
    unet = save_normalizer_file(tmp_path / "unet.npz", net.state_arrays(), net.file_meta(trained=False))
    gain = resolve_weights("gain", None)
    result = objective.main(tmp_path / "out", {"unet": unet, "gain": gain}, "gain", 1)
    assert set(result["scenes"]) == {"courbevoie", "mexico"} and set(result["mean_test"]) == {"unet", "gain"}
    assert json.loads((tmp_path / "out" / "objective.json").read_text()) == result
    assert all(np.isfinite(v) for v in result["mean_train"].values())
    with pytest.raises(InputError, match="architecture"):
        objective.main(tmp_path / "out", {"paper": resolve_weights("paper", None)})


def test_a_protocol_that_is_neither_preset_is_not_called_quick() -> None:
    report = _report_module()
    loo = _kept("relight_leave_one_out")
    loo["settings"] = {**loo["settings"], "patches": 77}
    title = report.relight(loo).splitlines()[0]
    assert "quick protocol" not in title and "77 patches" in title


def test_dog_band_starts_are_the_dogs_they_name_and_its_benches_take_the_quick_protocol_untuned(
    experiments: types.ModuleType, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """dog_band.py's untrained starts hold the default recipe's network with the mixture starting as the DoG its
    name says (the kernels and weights of Eq. 3), and each group of scenes is benched once, untuned, on the quick
    protocol, the leave-one-scene-out one over the webcams."""
    import torch

    from alcn_cv.nets.gain import GainNormalizer
    from alcn_cv.weight_file import load_normalizer_file

    module = importlib.import_module("dog_band")
    from alcn_cv.runtime import MODELS

    path = experiments.untrained_start(
        MODELS["gain"], tmp_path / "start.npz", "a start", **module.STARTS["start G0.5 - G2"]
    )
    net = GainNormalizer.from_file(load_normalizer_file(path))
    assert net.sigmas == pytest.approx([0.5, 1.0, 1.5, 2.0])
    image = torch.rand(1, 1, 48, 48)
    weights = net.dense_grid(image)[0, :, 2, 2]
    assert (weights / weights[0]).tolist() == pytest.approx([1.0, 0.0, 0.0, -1.0], abs=1e-6)
    summary = _benched_quick_and_left_out(experiments, module, "dog_band", monkeypatch, tmp_path)
    assert set(summary) == {*module.BASELINES, *module.STARTS, *module.TRAINED}
    assert summary["dlcn"]["webcams identification"] == 50.0


def _benched_quick_and_left_out(
    experiments: types.ModuleType,
    module: types.ModuleType,
    name: str,
    monkeypatch: pytest.MonkeyPatch,
    tmp_path: Path,
) -> dict[str, Any]:
    """Run the experiment ``module``'s part ``bench`` with a bench that reports 50 for every metric, check that it
    benched the test scenes, then the webcams left out one by one, each once, untuned, on the quick protocol over
    seeds 0-2, and return its report's summary."""
    commands: list[tuple[str, ...]] = []
    monkeypatch.setattr(module, "keep", lambda *args, **kwargs: None)
    monkeypatch.setattr(module, "script_command", lambda: f"python experiments/{name}.py --part bench")

    def bench_report(*argv: str) -> None:
        commands.append(argv)
        out = Path(argv[argv.index("--out") + 1])
        out.mkdir(parents=True)
        methods = argv[argv.index("--methods") + 1].split(",")
        means = {m: {"mean": 50.0} for m in module.METRICS}
        (out / "relight.json").write_text(json.dumps({"methods": {m: {"mean_test": means} for m in methods}}))

    monkeypatch.setattr(experiments, "alcn", bench_report)  # short_relight's
    monkeypatch.setattr(sys, "argv", [f"{name}.py", "--out", str(tmp_path / "run"), "--part", "bench"])
    module.main()
    quick = experiments.quick_protocol()
    assert len(commands) == 2 and all(c[:2] == ("bench", "relight") and "--no-tune" in c for c in commands)
    assert all(" ".join(quick) in " ".join(c) and "--seeds 0 1 2 " in " ".join(c) for c in commands)
    assert ["--leave-one-out" in c for c in commands] == [False, True]
    return json.loads((tmp_path / "run" / f"{name}.json").read_text())["summary"]


def test_gamma_compresses_the_training_crops_as_its_method_compresses_an_image_and_benches_the_quick_protocol(
    experiments: types.ModuleType, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """gamma.py's compression keeps [0, 1] (1 and the order kept), its method is ALCN of the compressed image, the
    training's crops are compressed the same way only within the context, Eq. 3 without the gain map's structure is 0
    where the image is flat (Eq. 3 is not: the DoG of the map), and each group of scenes is benched once, untuned, on
    the quick protocol."""
    from alcn_cv import createALCN
    from alcn_cv.train import real_light

    module = importlib.import_module("gamma")
    levels = np.linspace(0, 1, 256, dtype=np.float32)
    out = module.compressed(levels, 0.3, 0.2)
    assert out.dtype == np.float32 and out[-1] == 1 and out[0] == pytest.approx((0.2 / 1.2) ** 0.3)
    assert np.all(np.diff(out) > 0)
    image = np.random.default_rng(0).random((96, 80), dtype=np.float32)
    method = module.CompressedALCN(gamma=0.5, offset=0.1)
    np.testing.assert_array_equal(method.normalize(image), createALCN().normalize(module.compressed(image, 0.5, 0.1)))
    half_flat = np.full((96, 128), 0.5, np.float32)
    half_flat[:, 64:] = image[:, :64]
    alcn = createALCN()
    flat = np.s_[:, :56]  # beyond the kernels' reach of the textured half
    assert np.abs(alcn.runtime.mixture(half_flat)[flat]).max() > 1e-3
    assert np.abs(module.eq3_without_gain_structure(alcn, half_flat)[flat]).max() < 1e-6
    frame, centres = image, np.array([[20, 30], [40, 50]])
    plain = real_light.crop_windows
    with module.compressed_crops(0.5, 0.1):
        crops = real_light.crop_windows(frame, centres, 16)
    assert real_light.crop_windows is plain
    np.testing.assert_array_equal(crops.numpy(), module.compressed(plain(frame, centres, 16).numpy(), 0.5, 0.1))
    summary = _benched_quick_and_left_out(experiments, module, "gamma", monkeypatch, tmp_path)
    assert {"shipped", "untrained start, compressed", "trained compressed, seed 2", "none"} <= set(summary)
    assert summary["trained compressed, seed 0"]["test identification"] == 50.0
