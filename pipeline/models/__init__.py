"""Distortion models: named objects mapping distorted -> ideal pixels.

Every model has ``undistort_points``, ``distort_points``, ``undistortion_maps``,
``to_dict``/``from_dict``; :func:`model_from_dict` rebuilds any of them.
"""

from pipeline.models.base import DistortionModel, IdentityModel
from pipeline.models.grid_field import GridFieldModel
from pipeline.models.homography import HomographyModel
from pipeline.models.lensfun_model import LensfunModel
from pipeline.models.opencv_model import OpenCVModel
from pipeline.models.polynomial import PolynomialModel
from pipeline.models.radial import RadialModel

MODEL_TYPES: dict[str, type[DistortionModel]] = {
    IdentityModel.name: IdentityModel,
    "radial": RadialModel,
    "poly": PolynomialModel,
    "homography": HomographyModel,
    "opencv": OpenCVModel,
    "lensfun": LensfunModel,
    "grid_field": GridFieldModel,
}


def model_from_dict(d: dict) -> DistortionModel:
    """Rebuild a model from :meth:`DistortionModel.to_dict` output."""
    name = d.get("model") if isinstance(d, dict) else None
    if name not in MODEL_TYPES:
        raise ValueError(f"unknown distortion model {name!r}; known: {sorted(MODEL_TYPES)}")
    return MODEL_TYPES[name].from_dict(d)


def load_model(path):
    """Load the model of a saved model file (see :mod:`pipeline.model_file`); ValueError if bad."""
    from pipeline.model_file import read_model_file  # file I/O lives outside the pure core

    return read_model_file(path).model
