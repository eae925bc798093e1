"""The JSON schemas of the file formats: an unknown name, a violation, and jsonschema not installed."""

from __future__ import annotations

import pytest

from alcn_cv.errors import DatasetError, InputError
from alcn_cv.formats import schema, validate_json


def test_an_unknown_schema_is_an_input_error_listing_the_known_ones():
    with pytest.raises(InputError, match=r"unknown schema 'cocoo'; known: bop_scene_camera, bop_scene_gt, coco$"):
        schema("cocoo")
    with pytest.raises(InputError, match="unknown schema 'cocoo'"):
        validate_json({}, "cocoo", "a.json")


def test_a_violation_names_the_file_and_the_field():
    with pytest.raises(DatasetError, match=r"^a.json: field images: "):
        validate_json({"images": 1, "annotations": [], "categories": []}, "coco", "a.json")


def test_without_jsonschema_the_error_names_the_extra(run_python):
    code = """
    from alcn_cv.errors import MissingDependencyError
    from alcn_cv.formats import validate_json
    try:
        validate_json({}, "coco", "a.json")
    except MissingDependencyError as exc:
        print(exc)
    """
    proc = run_python(code, blocked=("jsonschema",))
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == (
        'validating a.json: needs the [data] extra (jsonschema is not installed): pip install "alcn-cv[data]"'
    )
