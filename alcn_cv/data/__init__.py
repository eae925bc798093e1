"""The illumination data engine: rendered data under the lightings of the paper's Fig. 1 and 4.

Modules:

- :mod:`~alcn_cv.data.lighting`: lights (directional, point, spot; coloured), lighting families
  and their sampling, hard shadow shapes.
- :mod:`~alcn_cv.data.render`: materials (matte, plastic, velvet-like, metal), vectorised
  shading, height-field shadows and the camera (exposure, noise, saturation, gamma, motion blur).
- :mod:`~alcn_cv.data.frames`: a reproducible textured frame under uneven light (benchmarks, tests).
- :mod:`~alcn_cv.data.textures`: procedural textures and the photographs of :mod:`skimage.data`
  that permit any use.
- :mod:`~alcn_cv.data.objects`: textured relief objects and their placement on 2.5D surfaces.
- :mod:`~alcn_cv.data.phos`: the Normalizer's Phos-like 64x64 training windows.
- :mod:`~alcn_cv.data.synthetic`: the paper's simple synthetic images from a few real images.
- :mod:`~alcn_cv.data.detect`: an ALCN-2D-like detection benchmark in COCO format.
- :mod:`~alcn_cv.data.raster`, :mod:`~alcn_cv.data.pose`: box and duck pose sequences in the BOP
  layout, with a COLMAP model of the training sequence.
- :mod:`~alcn_cv.data.relief_scenes`: rendered registered scenes, one view under many lights.
- :mod:`~alcn_cv.data.scenes`: the loader of registered multi-light scenes (real and rendered),
  their split and terms.
- :mod:`~alcn_cv.data.preview`, :mod:`~alcn_cv.data.stats`: contact sheets; statistics beside the
  real PSM photographs.
- :mod:`~alcn_cv.data.light_changes`, :mod:`~alcn_cv.data.permissive_images`: real photographs
  that permit any use, relit (the default gain Normalizer's training data).
- :mod:`~alcn_cv.data.manifest`: manifests, atomic folders, deterministic files.
- :mod:`~alcn_cv.data.detect_settings`, :mod:`~alcn_cv.data.pose_settings`, :mod:`~alcn_cv.data.relief_settings`:
  the generators' presets and constants, which the command line reads without importing the renderers.

Every generator is deterministic for its seed (byte-identical output) and writes a
``manifest.json``. The command line is ``alcn data phos|detect|pose|scenes|preview|compare-psm``.
"""
