"""Benchmarks of ALCN against the classical normalizations (Rad, Roth & Lepetit, BMVC 2017, Sec. 4.3).

* :mod:`~alcn_cv.bench.detect` -- the few-shot detection benchmark (``alcn bench detect``): its
  protocol and run; :mod:`~alcn_cv.bench.detect_settings` (settings, presets),
  :mod:`~alcn_cv.bench.detect_data` (data sets and training windows),
  :mod:`~alcn_cv.bench.policies` (the detector's input policies),
  :mod:`~alcn_cv.bench.detect_report` (``detect.md``);
* :mod:`~alcn_cv.bench.fewshot` -- the few-shot validation of any registered method
  (``alcn bench fewshot``);
* :mod:`~alcn_cv.bench.invariance` -- agreement of normalized real photographs under 12 lights
  (``alcn bench invariance``);
* :mod:`~alcn_cv.bench.directional` -- whole-image identification under hard directional light on the scenes
  of ``alcn data scenes --lighting directional``;
* :mod:`~alcn_cv.bench.objective` -- the real-light training objective of trained weight files on the training
  and test scenes;
* :mod:`~alcn_cv.bench.relight` -- patch identification, keypoint matching and homography pose
  between frames of fixed cameras under real light changes (``alcn bench relight``) on the scenes of
  :mod:`~alcn_cv.data.scenes`;
  :mod:`~alcn_cv.bench.relight_settings` (settings, presets),
  :mod:`~alcn_cv.bench.relight_report` (``relight.md``, ``.json``, ``.png``);
* :mod:`~alcn_cv.bench.speed` -- time and memory of every method and ALCN variant (``alcn bench speed``);
* :mod:`~alcn_cv.bench.metrics` -- non-maximum suppression, PASCAL matching, precision-recall, AUC;
* :mod:`~alcn_cv.bench.plots` -- the figures (precision-recall curves, time against frame size);
* :mod:`~alcn_cv.bench.cli` -- the ``alcn bench`` command;
* :mod:`~alcn_cv.report` -- Markdown tables, machine description, command line, figures.

Importing this package does not import torch.
"""
