"""The networks of ALCN: the Normalizer (predicts mixture weights) and the Detector."""

from alcn_cv.nets.detector import Detector
from alcn_cv.nets.normalizer import Normalizer, reflect101_pad

__all__ = ["Detector", "Normalizer", "reflect101_pad"]
