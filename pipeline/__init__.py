"""Pure image-processing core of harp station.

Everything in this package is a function (or a frozen dataclass) over numpy
arrays: no cameras, no configuration, no printing, no writing of files (reading a
model file, :func:`pipeline.model_file.read_model_file`, is the one file access).

Where things are
----------------
* measuring strings: :mod:`pipeline.edges` (sub-pixel Canny/Devernay; its gradient
  :mod:`pipeline.edge_gradient`, thresholds :mod:`pipeline.edge_thresholds` and chaining
  :mod:`pipeline.edge_chains`),
  :mod:`pipeline.grouping` (edges into strings), :mod:`pipeline.resample`
  (along-edge smoothing), :mod:`pipeline.straightness` (d, d_max),
  :mod:`pipeline.measure` (all of it on one image), :mod:`pipeline.render`
  (synthetic harps with exact truth);
* models: :mod:`pipeline.models` (one file per model, each with its equation and,
  for the fitted ones, its parametrisation), :mod:`pipeline.model_file` (the YAML
  format);
* fitting: :mod:`pipeline.fitspec` (what to fit), :mod:`pipeline.edgeset` (the edges
  of a fit, TLS lines, figures, result types), :mod:`pipeline.fit` (the
  fit; its least-squares problem :mod:`pipeline.fit_problem`, its Levenberg–Marquardt
  :mod:`pipeline.fit_solver`), :mod:`pipeline.alvarez` (closed-form start),
  :mod:`pipeline.cross_validation` (the candidates' CV table), :mod:`pipeline.orientations` (whether
  the shots' string orientations support a model), :mod:`pipeline.select` (the model choice of them),
  :mod:`pipeline.uncertainty` (bootstrap field uncertainty);
* using corrections: :mod:`pipeline.compare` and :mod:`pipeline.normalise` (modulo
  homography), :mod:`pipeline.evaluate`, :mod:`pipeline.interpolate` (over focus),
  :mod:`pipeline.undistort_maps`, :mod:`pipeline.exports` (OpenCV, ROS, lensfun).

Coordinate convention (used everywhere in harp station)
-------------------------------------------------------
A point is ``(x, y)`` with ``x`` the column and ``y`` the row of the image
array ``image[y, x]``. Pixel *centres* lie at integer coordinates: the pixel
``image[0, 0]`` covers ``[-0.5, 0.5] x [-0.5, 0.5]``. Point sets are float64
arrays of shape ``(N, 2)``. Angles are in degrees, counter-clockwise from the
+x axis *as seen in the array* (i.e. towards +y), in ``[0, 180)`` for lines.

References
----------
.. [1] Z. Tang, R. Grompone von Gioi, P. Monasse, J.-M. Morel,
   "High-precision camera distortion measurements with a calibration harp",
   JOSA A 29(10), 2012.
.. [2] R. Grompone von Gioi, G. Randall, "A Sub-Pixel Edge Detector: an
   Implementation of the Canny/Devernay Algorithm", IPOL 7 (2017).
"""

from typing import Any


def __getattr__(name: str) -> Any:
    """``pipeline.load_model(path)``, the entry point named in every model file's header
    (:func:`pipeline.model_file.load_model`), imported when first used."""
    if name == "load_model":
        from pipeline.model_file import load_model  # defers cv2, numpy, yaml

        return load_model
    raise AttributeError(f"module 'pipeline' has no attribute {name!r}")
