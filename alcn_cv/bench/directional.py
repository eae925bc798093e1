"""Whole-image identification under hard directional light, on the scenes of ``alcn data scenes --lighting
directional`` (:func:`alcn_cv.data.relief_scenes.render_directional_scene`): each scene is an identity, its first
frame the gallery (frontal light), the others the probes (:data:`~alcn_cv.data.relief_settings.AZIMUTHS` per
elevation of :data:`~alcn_cv.data.relief_settings.ELEVATIONS`).

Every image is normalized by its method's ``apply()`` (float output), area-resized to ``size x size``, made
zero-mean and unit-norm, and identified as its most correlated gallery image.

A method's parameters are tuned (:func:`tune`) over a grid of settings on a validation rendering (other scenes than
the test's), each setting scored by :func:`score`: one number, the mean identification over the elevations at every
side of :data:`SIZES`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import cv2
import numpy as np

from alcn_cv.data.relief_settings import AZIMUTHS, ELEVATIONS
from alcn_cv.enhance.registry import format_spec, from_spec

__all__ = ["SIZES", "descriptors", "identification", "identify", "score", "tune"]

#: Sides of the compared images (pixels).
SIZES = (32, 64)


def descriptors(images: np.ndarray, size: int) -> np.ndarray:
    """``(..., H, W)`` float -> ``(..., size * size)``: area-resized, zero-mean, unit-norm."""
    flat = images.reshape(-1, *images.shape[-2:])
    small = np.stack([cv2.resize(im, (size, size), interpolation=cv2.INTER_AREA).ravel() for im in flat])
    small -= small.mean(axis=1, keepdims=True)
    small /= np.linalg.norm(small, axis=1, keepdims=True) + 1e-9
    return small.reshape(*images.shape[:-2], size * size)


def identification(normalized: np.ndarray, size: int) -> dict[str, float]:
    """The identification of normalized scenes compared at ``size x size``.

    Args:
        normalized: ``(scenes, DIRECTIONAL_FRAMES, H, W)`` float, the gallery then the probes of each scene.
        size: side of the compared images (pixels).

    Returns:
        ``{"elevation E": percent}`` per elevation of :data:`~alcn_cv.data.relief_settings.ELEVATIONS`: the
        percentage (0-100) of its probes whose most correlated gallery image is their own scene's.
    """
    features = descriptors(normalized, size)
    gallery, identities = features[:, 0], np.arange(len(features))
    result = {}
    for j, elevation in enumerate(ELEVATIONS):
        probes = features[:, 1 + j * AZIMUTHS : 1 + (j + 1) * AZIMUTHS]
        nearest = np.argmax(probes @ gallery.T, axis=-1)
        result[f"elevation {elevation}"] = float(100 * np.mean(nearest == identities[:, None]))
    return result


def identify(spec: str, scenes: np.ndarray) -> dict[int, dict[str, float]]:
    """:func:`identification` at each side of :data:`SIZES` of ``scenes`` (``(scenes, DIRECTIONAL_FRAMES, H, W)``
    uint8) normalized by the registered method ``spec``'s ``apply()`` (float32 output)."""
    norm = from_spec(spec)
    normalized = np.stack([[norm.apply(im, out_dtype=np.float32) for im in scene] for scene in scenes])
    return {size: identification(normalized, size) for size in SIZES}


def score(result: Mapping[int, Mapping[str, float]]) -> float:
    """The number a setting is tuned by: the mean percentage (0-100) of :func:`identify`'s ``result`` over its sides
    and elevations."""
    return float(np.mean([percent for per_size in result.values() for percent in per_size.values()]))


def tune(method: str, scenes: np.ndarray, grid: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """Choose ``method``'s setting among ``grid`` by identification on ``scenes``.

    Each setting ``{key: value}`` is run as the spec ``method:key=value...`` (:func:`identify`) and scored by
    :func:`score`; the first best setting wins (a grid whose first setting is the method's default keeps it on a tie).

    Args:
        method: the name of a registered method.
        scenes: ``(scenes, DIRECTIONAL_FRAMES, H, W)`` uint8, the rendering tuned on: a validation rendering, never
            the test's.
        grid: the settings searched, e.g. ``TUNING_GRIDS[method]`` (:data:`alcn_cv.bench.relight.TUNING_GRIDS`).

    Returns:
        ``{"chosen": spec, "scores": {spec: percent}}``, the scores in the order of ``grid``.
    """
    scores = {}
    for params in grid:
        spec = format_spec(method, dict(params))
        scores[spec] = score(identify(spec, scenes))
    return {"chosen": max(scores, key=lambda k: scores[k]), "scores": scores}  # max: the first of equal maxima
