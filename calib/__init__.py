"""Camera calibration and registration of training sequences for :mod:`pose`.

- :mod:`calib.board`: chessboard and ChArUco targets, detection, printable board images.
- :mod:`calib.camera`: ``cv2.calibrateCamera`` from images or a video (frame selection by
  coverage and pose spread); OpenCV FileStorage YAML, COLMAP camera, per-view errors, figure.
- :mod:`calib.register`: per-frame camera poses in mm, from a ChArUco board (``solvePnP``) or
  from pycolmap SfM scaled by a known length; BOP and COLMAP output for ``alcn pose build``.
- :mod:`calib.undistort`: undistortion of images and videos.
- :mod:`calib.conventions`: OpenCV / COLMAP / BOP camera conventions.
- :mod:`calib.quality`: the rules that judge a calibration: outlier views, coverage of the image.
- :mod:`calib.report`: figures.
- :mod:`calib.colmap_log`: pycolmap's own log (glog) sent to a Python logger.
- :mod:`calib.cli`: ``alcn calib camera|board|register|undistort``.
"""
