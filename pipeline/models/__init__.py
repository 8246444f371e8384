"""Distortion models: named objects mapping distorted -> ideal pixels.

Every model has ``undistort_points``, ``distort_points``, ``undistortion_maps``,
``to_dict``/``from_dict`` and its equation in its docstring; :func:`model_from_dict`
rebuilds any of them by its ``name`` (:data:`MODEL_TYPES`). The models a fit can
produce carry their parametrisation beside them (:mod:`pipeline.models.radial`,
:mod:`pipeline.models.polynomial`). Model files: :mod:`pipeline.model_file`.
"""

from pipeline.models.base import DistortionModel, IdentityModel, model_from_dict, model_types
from pipeline.models.grid_field import GridFieldModel
from pipeline.models.homography import HomographyModel
from pipeline.models.lensfun_model import LensfunModel
from pipeline.models.opencv_fisheye_model import OpenCVFisheyeModel
from pipeline.models.opencv_model import OpenCVModel
from pipeline.models.polynomial import PolynomialModel
from pipeline.models.radial import RadialModel
from pipeline.models.radial_field import RadialFieldModel
from pipeline.models.remap_model import RemapModel
from pipeline.models.thin_prism_fisheye_model import ThinPrismFisheyeModel

MODEL_TYPES: dict[str, type[DistortionModel]] = model_types()
"""Every model class by the ``name`` its files carry: identity, radial, poly, homography,
opencv, opencv_fisheye, thin_prism_fisheye, lensfun, grid_field, remap, radial_field."""

__all__ = [
    "MODEL_TYPES",
    "DistortionModel",
    "GridFieldModel",
    "HomographyModel",
    "IdentityModel",
    "LensfunModel",
    "OpenCVFisheyeModel",
    "OpenCVModel",
    "PolynomialModel",
    "RadialFieldModel",
    "RadialModel",
    "RemapModel",
    "ThinPrismFisheyeModel",
    "model_from_dict",
    "model_types",
]
