"""Pure image-processing core of harp station.

Everything in this package is a function (or a frozen dataclass) over numpy
arrays: no files, no cameras, no configuration, no printing.

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

from pipeline.models import load_model  # noqa: F401  (public entry point)
