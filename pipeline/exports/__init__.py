"""Exports of a harp correction to other software's distortion formats.

:mod:`pipeline.exports.fit` converts any :class:`~pipeline.models.base.DistortionModel`
to OpenCV / lensfun parameters by least squares over the image and states
the conversion error; :mod:`~pipeline.exports.opencv`, :mod:`~pipeline.exports.ros`
and :mod:`~pipeline.exports.lensfun` render (and read) the file texts.
"""
