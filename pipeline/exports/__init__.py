"""Exports of a harp correction to other software's distortion formats.

:mod:`pipeline.exports.registry` is the table of formats (``opencv``,
``opencv-fisheye``, ``ros``, ``ros-equidistant``, ``lensfun``, ``mrcal``,
``maps``, ``stmap``, ``json``, ``harp``), each with ``write``, ``read`` and
``sniff``, and :func:`~pipeline.exports.registry.read_correction` which
detects and reads any of them. The writers are by family
(:mod:`~pipeline.exports.opencv_writers`, :mod:`~pipeline.exports.family_writers`,
:mod:`~pipeline.exports.lensfun_writer`, :mod:`~pipeline.exports.map_writers`,
:mod:`~pipeline.exports.harp_file`) on what they take and give
(:mod:`~pipeline.exports.source`), the fits they hold (:mod:`~pipeline.exports.fitted`,
:mod:`~pipeline.exports.measured_camera`) and the one rule for trying the fisheye
(:mod:`~pipeline.exports.auto_rule`); :mod:`~pipeline.exports.readers` reads and sniffs the
files. :mod:`pipeline.exports.fit` converts any
:class:`~pipeline.models.base.DistortionModel` to OpenCV (pin-hole or
fisheye) / lensfun parameters by least squares over the whole image and
states the conversion error; :mod:`~pipeline.exports.lens` holds what the
configuration says about the lens and camera (and so what the camera matrix
means); :mod:`~pipeline.exports.opencv`, :mod:`~pipeline.exports.ros`,
:mod:`~pipeline.exports.lensfun`, :mod:`~pipeline.exports.mrcal` and
:mod:`~pipeline.exports.maps` render (and read) the files.
"""
