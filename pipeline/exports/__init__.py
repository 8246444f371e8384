"""Exports of a harp correction to other software's distortion formats.

:mod:`pipeline.exports.registry` is the table of formats (``opencv``,
``opencv-fisheye``, ``ros``, ``ros-equidistant``, ``lensfun``, ``mrcal``,
``maps``, ``stmap``, ``json``, ``harp``), each with ``write``, ``read`` and
``sniff``, and :func:`~pipeline.exports.registry.read_correction` which
detects and reads any of them. :mod:`pipeline.exports.fit` converts any
:class:`~pipeline.models.base.DistortionModel` to OpenCV (pin-hole or
fisheye) / lensfun parameters by least squares over the whole image and
states the conversion error; :mod:`~pipeline.exports.lens` holds what the
configuration says about the lens and camera (and so what the camera matrix
means); :mod:`~pipeline.exports.opencv`, :mod:`~pipeline.exports.ros`,
:mod:`~pipeline.exports.lensfun`, :mod:`~pipeline.exports.mrcal` and
:mod:`~pipeline.exports.maps` render (and read) the files.
"""
