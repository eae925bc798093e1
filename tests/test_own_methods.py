"""A normalization of one's own: written on :class:`alcn_cv.Normalization`, registered, given to every command by
``alcn --import``, and held to the contract of the shipped ones (a researcher's walk found each gap below)."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
import warnings

import cv2
import numpy as np
import pytest

import alcn_cv
from alcn_cv.enhance import registry
from alcn_cv.errors import InputError
from alcn_cv.report import machine

GAMMA = textwrap.dedent(
    '''
    import numpy as np

    import alcn_cv


    @alcn_cv.register
    class Gamma(alcn_cv.Normalization):
        """A gamma curve."""

        name = "gamma"

        def __init__(self, gamma: float = 0.5) -> None:
            self.gamma = gamma

        def _normalize(self, gray: np.ndarray) -> np.ndarray:
            return gray**self.gamma
    '''
)


@pytest.fixture
def own_registry(monkeypatch):
    """The registrations of a test are its alone."""
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))


def test_a_response_of_another_shape_is_named_not_reshaped(own_registry):
    """A method returning its image transposed went through apply() as a scrambled image of the right shape (and
    ranked in the bench); one of another size failed in NumPy's reshape, naming no method."""

    class Transposed(alcn_cv.Normalization):
        name = "transposed"

        def _normalize(self, gray):
            return gray.T

    image = np.random.default_rng(0).integers(0, 256, (48, 64), np.uint8)
    for call in (Transposed().apply, lambda i: Transposed().normalize(i.astype(np.float32) / 255)):
        with pytest.raises(InputError, match=r"transposed returned a response of shape \(64, 48\) for an image of"):
            call(image)


def test_a_non_finite_response_is_said_once(caplog):
    """A method of one's own returning NaN or infinities had them written as 0 without a word; the shipped methods
    are not checked (tested instead), so their frame time does not pay for it."""

    class Holes(alcn_cv.Normalization):
        output_range = (0.0, 1.0)

        def _normalize(self, gray):
            out = gray.copy()
            out[0, :3] = [np.nan, np.inf, -np.inf]
            return out

    image = np.full((8, 8), 200, np.uint8)
    with caplog.at_level("WARNING", logger="alcn_cv.enhance.base"):
        first = Holes().apply(image)
        Holes().apply(image)
    said = [r.getMessage() for r in caplog.records if "non-finite" in r.getMessage()]
    assert said == [
        "Holes returned 3 non-finite values (NaN or infinity) of 64: apply() writes them as 0 (warned once)"
    ]
    assert first[0, :4].tolist() == [0, 0, 0, 200]
    caplog.clear()
    with caplog.at_level("WARNING", logger="alcn_cv.enhance.base"):
        alcn_cv.create("dlcn").apply(np.zeros((8, 8), np.uint8))  # flat: the shipped methods' own business
    assert not [r for r in caplog.records if "non-finite" in r.getMessage()]


def test_a_method_cannot_change_the_callers_image(own_registry):
    """normalize() handed the caller's array to the method: one blurring it in place changed the photographs every
    later method of `bench invariance` normalized. The method now sees it read-only."""

    class InPlace(alcn_cv.Normalization):
        name = "inplace"

        def _normalize(self, gray):
            gray *= 0.5
            return gray

    image = np.full((8, 8), 0.5, np.float32)
    with pytest.raises(ValueError, match="read-only"):
        InPlace().normalize(image)
    assert (image == 0.5).all()
    response = alcn_cv.create("none").normalize(image)  # the identity's response is no view of the image
    response[0, 0] = 0.0
    assert image[0, 0] == 0.5


@pytest.mark.parametrize(
    ("attributes", "message"),
    [
        ({"name": "my:method"}, "cannot name a method"),
        ({"name": "homo,v2"}, "cannot name a method"),
        ({"name": "homo+lstd"}, "cannot name a method"),
        ({"name": "mine", "output_range": (1.0, 1.0)}, r"output_range must be two finite numbers \(low, high\)"),
        ({"name": "mine", "output_range": (1.0, 0.0)}, "output_range must be"),
        ({"name": "mine", "output_range": (0.0, float("inf"))}, "output_range must be"),
        ({"name": "dog"}, r"'dog' is already registered by alcn_cv.enhance.lcn.DifferenceOfGaussians: give .* another"),
    ],
)
def test_register_refuses_what_no_command_could_use(attributes, message, own_registry):
    """A name a spec cannot hold registered and then failed in create() or split in a --methods list; an output
    range of zero width failed with ZeroDivisionError at the first apply()."""
    cls = type("Mine", (alcn_cv.Normalization,), {"_normalize": lambda self, gray: gray, **attributes})
    with pytest.raises(TypeError, match=message):
        registry.register(cls)


def test_register_takes_an_output_range_of_each_instance_and_keeps_the_benches_names(own_registry):
    """A property (each instance's range) or a list was refused by the range check, which holds for a class's own
    tuple; `unet` registered and could never be built by the benchmarks, which build the U-Net themselves."""

    class PerInstance(alcn_cv.Normalization):
        name = "per_instance"

        @property
        def output_range(self):
            return (-1.0, 1.0)

        def _normalize(self, gray):
            return gray * 2 - 1

    registry.register(PerInstance)
    registry.register(type("Listed", (alcn_cv.Normalization,), {"name": "listed", "output_range": [-1.0, 1.0]}))
    assert PerInstance().apply(np.full((2, 2), 128, np.uint8))[0, 0] == 128
    with pytest.raises(TypeError, match="'unet' names a method the benchmarks build themselves"):
        registry.register(type("U", (alcn_cv.Normalization,), {"name": "unet"}))


def test_a_method_given_a_read_only_image_raises_no_torch_warning():
    """The read-only image made torch warn ("The given NumPy array is not writable") on the torch backend."""
    image = np.random.default_rng(0).integers(0, 256, (32, 48), np.uint8)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        alcn_cv.create("alcn", backend="torch").apply(image)


def test_register_takes_only_normalizations_and_the_same_class_again(own_registry):
    with pytest.raises(TypeError, match="is not a subclass of alcn_cv.Normalization"):
        registry.register(type("Plain", (), {"name": "plain"}))
    namespace: dict[str, object] = {"__name__": "my_notebook"}
    exec(GAMMA, namespace)
    exec(GAMMA, namespace)  # a notebook's cell run again: the class of that module and name replaced
    assert alcn_cv.create("gamma:gamma=0.4").gamma == 0.4


def test_alcn_import_gives_a_method_to_every_command_and_the_report_records_it(tmp_path):
    """The command line had no way to load a method of one's own (only a script wrapping alcn_cv.cli.main)."""
    (tmp_path / "my_methods.py").write_text(GAMMA)
    alcn = [sys.executable, "-m", "alcn_cv.cli"]
    run = {"capture_output": True, "text": True, "timeout": 300, "cwd": tmp_path}
    listed = subprocess.run([*alcn, "--import", "my_methods.py", "normalize", "--list"], **run)
    assert listed.returncode == 0 and "gamma      A gamma curve." in listed.stdout, listed.stderr
    (tmp_path / "mine").mkdir()  # the standard library's name: imported already, the file would never run
    (tmp_path / "mine" / "platform.py").write_text(GAMMA)
    clash = subprocess.run([*alcn, "--import", "mine/platform.py", "normalize", "--list"], **run)
    assert clash.returncode == 2 and "a module named 'platform' is imported already" in clash.stderr, clash.stderr
    missing = subprocess.run([*alcn, "--import", "nope", "normalize", "--list"], **run)
    assert missing.returncode == 2
    assert missing.stderr.strip().endswith(
        "--import nope: no module named 'nope' (give a .py file's path, or set PYTHONPATH)"
    )
    image = tmp_path / "in.png"
    cv2.imwrite(str(image), np.full((16, 16), 64, np.uint8))
    done = subprocess.run(
        [*alcn, "--import", str(tmp_path / "my_methods.py"), "normalize", "in.png", "out.png", "-m", "gamma"], **run
    )
    assert done.returncode == 0, done.stderr
    assert cv2.imread(str(tmp_path / "out.png"), cv2.IMREAD_UNCHANGED)[0, 0] == 128


def test_a_report_records_the_version_of_alcn_cv():
    assert json.loads(json.dumps(machine()))["alcn_cv"] == alcn_cv.__version__


def test_the_tuning_text_counts_each_grid_and_names_the_methods_left_untuned():
    """A grid of 3 settings of one's own beside dog's 8 was reported as "Each method's 3 settings", and a method
    without a grid was left untuned without a word."""
    from alcn_cv.bench.relight_report import _tuning_text

    tuned = {"chosen": "dog", "scores": {"dog": 80.0, "dog:sigma1=0.5": 81.0}}
    result = {
        "tuning": {"dog": {"all": tuned}},
        "split": {"mode": "train/test"},
        "settings": {"tuning_grids": {"dog": ["dog"] * 8, "mine": ["mine"] * 3}, "tune_frames": 8, "tune_seed": 0},
        "methods": {"none": {}, "dog": {}, "dog (tuned)": {}, "mine": {}, "mine (tuned)": {}, "gamma": {}},
    }
    text = _tuning_text(result)
    assert "Each method's settings (dog 8, mine 3)" in text and "Not tuned (no grid): `none`, `gamma`." in text
