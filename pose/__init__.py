"""Part-based 3D pose of a box under light changes, after contrast normalization.

The pipeline of Sec. 4.4 of Rad, Roth & Lepetit, "ALCN: Meta-Learning for Contrast
Normalization Applied to Robust 3D Pose Estimation", BMVC 2017, one module per stage:

* :mod:`pose.model`: the part-model file format;
* :mod:`pose.build`: ``alcn pose build``, part model from a training sequence (pycolmap, open3d);
* :mod:`pose.parts`: part detectors run after a normalizer (``alcn_cv.create(name)``);
* :mod:`pose.corners`: ``alcn pose train-corners``, the learned box-corner detector (CNN,
  exported to ONNX and run by ``cv2.dnn``);
* :mod:`pose.solver`: PnP + RANSAC + LM refinement, tracking with a prior, lost/recovered;
* :mod:`pose.track`: ``alcn pose track``, poses per frame and overlays;
* :mod:`pose.evaluate`: ``alcn pose eval``, Table-1-style report and Middlebury errors;
* :mod:`pose.cli`: the ``alcn pose`` command.
"""
