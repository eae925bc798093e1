"""Part-based 3D pose of a box under light changes, after contrast normalization.

The pipeline of Sec. 4.4 of Rad, Roth & Lepetit, "ALCN: Meta-Learning for Contrast
Normalization Applied to Robust 3D Pose Estimation", BMVC 2017, one module per stage:

* :mod:`pose.model`: the part-model file format;
* :mod:`pose.sequence`: training sequences (registered, or the frames of a video);
* :mod:`pose.triangulate`: features, matches and 3D points (pycolmap);
* :mod:`pose.box_fit`: the object's box from its 3D points (open3d);
* :mod:`pose.plots`: figures (the model and its cameras, the Table-1 bars);
* :mod:`pose.build`: ``alcn pose build``, part model from a training sequence (the stages above);
* :mod:`pose.parts`: part detectors run after a normalization (:func:`alcn_cv.enhance.registry.from_spec`);
* :mod:`pose.corners`: the learned detector of the box's corners, edge middles and face centres,
  run by ``cv2.dnn`` (ONNX);
  :mod:`pose.corner_data` its labelled training frames, :mod:`pose.corner_net` its network and
  :mod:`pose.corner_train` ``alcn pose train-corners`` (torch, export to ONNX),
  :mod:`pose.corner_bench` ``alcn pose bench-corners`` (its speed, torch-free);
* :mod:`pose.solver`: PnP + RANSAC + LM refinement, tracking with a prior, lost/recovered;
* :mod:`pose.track`: ``alcn pose track``, poses per frame and overlays; :func:`pose.track.open_tracker`, its
  tracker in Python, one frame at a time;
* :mod:`pose.evaluate`: ``alcn pose eval``, Table-1-style report and Middlebury errors;
* :mod:`pose.planar`: ``alcn pose planar``, a planar target's pose on fixed webcams under real light;
* :mod:`pose.overlay`: ``alcn pose overlay-error``, the drawn box's distance to the image's edges;
* :mod:`pose.cli`: the ``alcn pose`` command.
"""
