"""Benchmarks of ALCN against the classical normalizations (Rad, Roth & Lepetit, BMVC 2017, Sec. 4.3).

* :mod:`~alcn_cv.bench.detect` -- the few-shot detection benchmark (``alcn bench detect``);
* :mod:`~alcn_cv.bench.invariance` -- agreement of normalized real photographs under 12 lights
  (``alcn bench invariance``);
* :mod:`~alcn_cv.bench.tuning` -- parameter search for DoG, SLCN and DLCN on training windows;
* :mod:`~alcn_cv.bench.metrics` -- non-maximum suppression, PASCAL matching, precision-recall, AUC;
* :mod:`~alcn_cv.report` -- Markdown tables, machine description, figures.

Importing this package does not import torch.
"""
