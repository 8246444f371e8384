"""What to fit: one frozen :class:`FitSpec` (model kind, degree, extra terms, centre prior).

A spec names one member of the two model families :func:`pipeline.fit.fit_distortion`
can fit:

* ``radial`` — :class:`~pipeline.models.radial.RadialModel` with a free centre,
  ``k0 = 1`` and ``k1 .. k_degree`` (degree 1..10, default 4), optionally with the
  decentering (``tangential``: p1, p2) and thin-prism (``prism``: s1..s4) terms, optionally
  with the three-fold (``trefoil``: t1, t2) term,
  optionally with a division (rational) denominator ``1 + d1 rho^2 + .. + dM rho^2M``
  (``division = M``, 1..3: wide-angle lenses), optionally with a prior pulling the
  distortion centre towards the image centre (``center_prior``);
* ``poly`` — :class:`~pipeline.models.polynomial.PolynomialModel`, a free bivariate
  polynomial of total degree 3..11 (default 5). A degree-2 polynomial is not offered:
  once its linear and first-order projective parts are fixed by the gauge (see
  :mod:`pipeline.fit`) it has no odd (cubic) term, so it cannot express even the
  simplest radial distortion.

The spec is the one spelling of "what to fit" everywhere: the configuration
(``pipeline.model``: a label or ``auto``), ``harp calibrate``'s and ``harp reprocess``'s
``--model``, the cross-validated model selection (:mod:`pipeline.select`), the bootstrap,
and every stored profile (the spec that was actually fitted, so QA and reports refit
exactly that); its defaults are the dataclass's. Its :attr:`~FitSpec.label` is a short name
such as ``radial4+tangential+prism`` that :func:`parse` reads back (:func:`parse_choice` also
reads :data:`AUTO`: left to the cross-validation); :meth:`FitSpec.fit_arguments` gives the
keyword arguments of :func:`pipeline.fit.fit_distortion` and :meth:`FitSpec.from_fit_arguments`
reads them back.

References
----------
.. [1] Z. Tang, R. Grompone von Gioi, P. Monasse, J.-M. Morel, "High-precision camera
   distortion measurements with a calibration harp", JOSA A 29(10), 2012.
"""

from __future__ import annotations

import math
import operator
from dataclasses import dataclass
from typing import Any

KINDS: tuple[str, ...] = ("radial", "poly")
"""The model families a spec can name."""

AUTO = "auto"
"""The choice that names no spec: what to fit is chosen by cross-validation (:mod:`pipeline.select`)."""

DEGREE_BOUNDS: dict[str, tuple[int, int]] = {"radial": (1, 10), "poly": (3, 11)}
"""Allowed degrees per kind, inclusive: radial = highest power of rho, poly = total degree."""

DEFAULT_DEGREE: dict[str, int] = {"radial": 4, "poly": 5}
"""Degree of a spec that gives none."""

DIVISION_BOUNDS: tuple[int, int] = (0, 3)
"""Allowed number of division (denominator) coefficients of a radial spec, inclusive."""

FIELD_BOUNDS: tuple[int, int] = (4, 24)
"""Allowed control points per axis of a residual field, inclusive (4: one cubic piece)."""

DEFAULT_FIELD_PENALTY = 1e-3
"""Roughness weight of a field spec that gives none (:class:`~pipeline.models.radial_field.RadialFieldParametrisation`:
a thin-plate energy of ``E`` px² per half-diagonal² costs like a residual of ``penalty * sqrt(E)`` px on every
point); the cross-validation (:func:`pipeline.select.field_candidates`) chooses among several."""

STRINGS_SEPARATE = "separate"
STRINGS_IGNORE = "ignore"
STRINGS_KINKS = "separate-kinks"
STRINGS_CHOICES: tuple[str, ...] = (STRINGS_SEPARATE, STRINGS_IGNORE, STRINGS_KINKS)
"""What a session fits beside the lens when its turntable angles tell a string's own bend from the lens
(:func:`pipeline.harp_shape.fit_harp_shape`): ``separate-kinks`` (the default) fits every string's bend with
the lens, finds each string's kinks and models them (:mod:`pipeline.harp_kinks`: on the realistic
simulator's 60 lenses at or below 0.005 px for 47 against 43 with the bends only, higher by more than 5 % for
one, +0.0002 px; ``benchmarks/RESULTS-strings.md``) and keeps the lens; ``separate`` fits the bends only;
``ignore`` fits the lens alone as for loose photographs."""

CHOICE_FOLDS_PLAIN = "plain"
CHOICE_FOLDS_STRINGS = "strings-separated"
CHOICE_FOLDS: tuple[str, ...] = (CHOICE_FOLDS_PLAIN, CHOICE_FOLDS_STRINGS)
"""How a session's automatic choice (``pipeline.model: auto``) cross-validates the candidates when it knows the
turntable angles: ``plain`` (the default) judges each held-out shot as it is (:func:`pipeline.select.select_model`'s
two tiers); ``strings-separated`` fits every fold with the strings' own bends separated and judges the held-out
shot with its strings' fitted bends removed (:mod:`pipeline.separated_cv`; with ``pipeline.strings: separate``
and folds of 3 turntable angles or more). Not the default: on the realistic simulator it brought the chosen
model's field error closer to the best candidate's on some lenses and farther on others
(``benchmarks/RESULTS-strings.md``: 15 better and 12 worse of 51; on the point populations of
``benchmarks/RESULTS-model-choice.md`` not better), at about 7 times the choice's time."""

FIELD_NONE = "none"
FIELD_AUTO = "auto"
FIELD_CHOICES: tuple[str, ...] = (FIELD_NONE, FIELD_AUTO)
"""Whether a session adds a residual field (:class:`~pipeline.models.radial_field.RadialFieldParametrisation`) to
the radial model it fits: ``auto`` (the default) when a field holds on unseen orientations
(:func:`pipeline.select.select_field`: the model, chosen or given, against it with each field of
:func:`pipeline.select.field_candidates`, each fold fitted with the strings' bends, and kinks as the session's,
separated when the turntable angles are known; :data:`pipeline.select.FIELD_MARGIN_SE`), ``none`` never. A field needs
:data:`pipeline.orientations.REQUIRED_ORIENTATIONS_POLY` distinct orientations; with fewer the model is kept and the
reason says so."""

FREE_CENTER_WEIGHT = 1e-5
"""``w_center`` of a radial fit without a centre prior: the centre is practically free."""

CENTER_PRIOR_WEIGHT = 1e-2
"""``w_center`` of a spec with ``center_prior``.

A shift of the distortion centre is, to first order, a tangential term, so with
tangential terms the centre is nearly undetermined by few orientations; the prior
pulls it towards the image centre and lets the tangential terms carry the
decentering. Whether that generalises better is for the cross-validation to say (it
does on the real photos, not on a strongly decentred synthetic lens)."""


def spec_problem(
    kind: Any,
    degree: Any = None,
    tangential: Any = False,
    prism: Any = False,
    division: Any = 0,
    field: Any = None,
    field_penalty: Any = None,
    trefoil: Any = False,
) -> str | None:
    """Why ``(kind, degree, tangential, prism, division, field, field_penalty, trefoil)`` is not a valid
    spec, or ``None``.

    The one check of the allowed kinds and degrees (:data:`DEGREE_BOUNDS`,
    :data:`DIVISION_BOUNDS`, :data:`FIELD_BOUNDS`), used by :class:`FitSpec` and by
    :func:`pipeline.fit.fit_distortion`.
    """
    if kind not in KINDS:
        return f"unknown model {kind!r}; use {' or '.join(repr(k) for k in KINDS)}"
    if degree is not None:
        lo, hi = DEGREE_BOUNDS[kind]
        try:
            whole = not isinstance(degree, bool) and operator.index(degree) == degree
        except TypeError:
            whole = False
        if not whole or not lo <= degree <= hi:
            name = "polynomial" if kind == "poly" else "radial"
            return f"{name} degree must be within {lo}..{hi}, got {degree}"
    if kind == "poly" and (tangential or prism or trefoil):
        return "tangential/prism/trefoil terms apply to the radial model only (poly contains them)"
    try:
        whole_div = not isinstance(division, bool) and operator.index(division) == division
    except TypeError:
        whole_div = False
    lo, hi = DIVISION_BOUNDS
    if not whole_div or not lo <= division <= hi:
        return f"division terms must be within {lo}..{hi}, got {division}"
    if kind == "poly" and division:
        return "division terms apply to the radial model only"
    return _field_problem(kind, field, field_penalty)


def _field_problem(kind: Any, field: Any, field_penalty: Any) -> str | None:
    """Why a residual field ``(field, field_penalty)`` is not valid for ``kind``, or ``None``."""
    if field is None:
        return None if field_penalty is None else "a field penalty needs a field (field=(nx, ny))"
    if kind != "radial":
        return "a residual field applies to the radial model only"
    lo, hi = FIELD_BOUNDS
    try:
        nx, ny = (operator.index(v) for v in field)
        ok = not any(isinstance(v, bool) for v in field) and lo <= nx <= hi and lo <= ny <= hi
    except (TypeError, ValueError):
        ok = False
    if not ok:
        return f"a field needs (nx, ny) control points within {lo}..{hi} each, got {field!r}"
    if field_penalty is not None:
        try:
            pen = float(field_penalty)
        except (TypeError, ValueError):
            pen = float("nan")
        if isinstance(field_penalty, bool) or not math.isfinite(pen) or pen <= 0:
            return f"the field penalty must be a number > 0, got {field_penalty!r}"
    return None


@dataclass(frozen=True)
class FitSpec:
    """One model configuration to fit (see the module docstring).

    Parameters
    ----------
    kind : {'radial', 'poly'}
    degree : int, optional
        Radial: highest power of rho in ``f``; poly: total degree. ``None``: the
        default of the kind (:data:`DEFAULT_DEGREE`); the spec always holds a number.
    tangential, prism : bool
        Radial only: decentering (p1, p2) / thin-prism (s1..s4) terms.
    division : int
        Radial only: number of division (denominator) coefficients ``d1 .. dM``, 0..3.
    center_prior : bool
        Radial only: pull the distortion centre towards the image centre
        (:data:`CENTER_PRIOR_WEIGHT`).
    field : (int, int), optional
        Radial only: a residual field of ``nx x ny`` B-spline control points over the image
        (:class:`~pipeline.models.radial_field.RadialFieldModel`), or ``None``.
    field_penalty : float, optional
        The field's roughness weight; ``None``: :data:`DEFAULT_FIELD_PENALTY` (the spec then
        holds the number).
    trefoil : bool
        Radial only: the three-fold term (t1, t2) of :class:`~pipeline.models.radial.RadialModel`,
        the quadratic distortion that thin-prism terms and homographies cannot express; it needs
        four string orientations (:func:`pipeline.orientations.required_orientations`).

    Raises
    ------
    ValueError
        One line saying what is wrong (unknown kind, degree out of bounds, terms that
        do not apply to the kind).
    """

    kind: str = "radial"
    degree: int | None = None
    tangential: bool = False
    prism: bool = False
    center_prior: bool = False
    division: int = 0
    field: tuple[int, int] | None = None
    field_penalty: float | None = None
    trefoil: bool = False

    def __post_init__(self) -> None:
        problem = spec_problem(
            self.kind,
            self.degree,
            self.tangential,
            self.prism,
            self.division,
            self.field,
            self.field_penalty,
            self.trefoil,
        )
        if problem is None and self.kind == "poly" and self.center_prior:
            problem = "a centre prior applies to the radial model only"
        if problem is not None:
            raise ValueError(problem)
        object.__setattr__(self, "degree", DEFAULT_DEGREE[self.kind] if self.degree is None else int(self.degree))
        object.__setattr__(self, "tangential", bool(self.tangential))
        object.__setattr__(self, "prism", bool(self.prism))
        object.__setattr__(self, "trefoil", bool(self.trefoil))
        object.__setattr__(self, "center_prior", bool(self.center_prior))
        object.__setattr__(self, "division", int(self.division))
        if self.field is not None:
            object.__setattr__(self, "field", (int(self.field[0]), int(self.field[1])))
            pen = DEFAULT_FIELD_PENALTY if self.field_penalty is None else float(self.field_penalty)
            object.__setattr__(self, "field_penalty", pen)

    @property
    def label(self) -> str:
        """Short name, e.g. ``radial4+tangential+prism+centre-prior``, ``radial2+division1``,
        ``radial4+tangential+prism+trefoil``,
        ``radial4+tangential+field8x6@0.001`` or ``poly5`` (:func:`parse` reads it)."""
        if self.kind == "poly":
            return f"poly{self.degree}"
        return (
            f"radial{self.degree}"
            + ("+tangential" if self.tangential else "")
            + ("+prism" if self.prism else "")
            + ("+trefoil" if self.trefoil else "")
            + (f"+division{self.division}" if self.division else "")
            + ("+centre-prior" if self.center_prior else "")
            + (f"+field{self.field[0]}x{self.field[1]}@{self.field_penalty:g}" if self.field else "")
        )

    @property
    def w_center(self) -> float:
        """Weight of the centre penalty of a radial fit (:mod:`pipeline.fit`)."""
        return CENTER_PRIOR_WEIGHT if self.center_prior else FREE_CENTER_WEIGHT

    def fit_arguments(self) -> dict[str, Any]:
        """Keyword arguments of :func:`pipeline.fit.fit_distortion` that fit this spec."""
        kw: dict[str, Any] = {"model": self.kind, "degree": self.degree}
        if self.kind == "radial":
            kw.update(tangential=self.tangential, prism=self.prism)
            if self.trefoil:
                kw["trefoil"] = True
            if self.division:
                kw["division"] = self.division
            if self.center_prior:
                kw["w_center"] = CENTER_PRIOR_WEIGHT
            if self.field is not None:
                kw.update(field=self.field, field_penalty=self.field_penalty)
        return kw

    @classmethod
    def from_fit_arguments(cls, kw: Any) -> FitSpec:
        """Inverse of :meth:`fit_arguments` (a centre prior: a ``w_center`` ten times the free
        centre's or more). ValueError (one line) for arguments no spec gives."""
        if not isinstance(kw, dict):
            raise ValueError(f"fit arguments must be a mapping, got {type(kw).__name__}")
        w = kw.get("w_center")
        field = kw.get("field")
        return cls(
            str(kw.get("model")),
            kw.get("degree"),
            bool(kw.get("tangential", False)),
            bool(kw.get("prism", False)),
            w is not None and w > 10 * FREE_CENTER_WEIGHT,
            kw.get("division", 0),
            None if field is None else tuple(field),
            kw.get("field_penalty"),
            bool(kw.get("trefoil", False)),
        )

    def to_dict(self) -> dict[str, Any]:
        """Plain data (model files, JSON, the store): ``model`` (the kind), ``degree``,
        ``tangential``, ``prism``, ``center_prior``, ``label`` and, when not 0, ``division``; with a
        field, ``field`` ``[nx, ny]`` and ``field_penalty``; with the three-fold term, ``trefoil``."""
        d: dict[str, Any] = {
            "model": self.kind,
            "degree": self.degree,
            "tangential": self.tangential,
            "prism": self.prism,
            "center_prior": self.center_prior,
            "label": self.label,
        }
        if self.trefoil:
            d["trefoil"] = True
        if self.division:
            d["division"] = self.division
        if self.field is not None:
            d["field"] = list(self.field)
            d["field_penalty"] = self.field_penalty
        return d

    @classmethod
    def from_dict(cls, d: Any) -> FitSpec:
        """Inverse of :meth:`to_dict` (``label`` is ignored; missing flags are false).
        ValueError (one line) for anything else."""
        if not isinstance(d, dict):
            raise ValueError(f"a fit spec must be a mapping, got {type(d).__name__}")
        return cls(
            str(d.get("model", d.get("kind"))),
            d.get("degree"),
            bool(d.get("tangential", False)),
            bool(d.get("prism", False)),
            bool(d.get("center_prior", False)),
            d.get("division", 0),
            None if d.get("field") is None else tuple(d["field"]),
            d.get("field_penalty"),
            bool(d.get("trefoil", False)),
        )


FULL_RADIAL = FitSpec("radial", tangential=True, prism=True)
"""The radial model with its decentering and thin-prism terms, degree 4 (12 parameters): what
``harp calibrate --model radial`` fits unless told ``--no-tangential`` / ``--no-prism``, and the
model selection's fallback (:data:`pipeline.cross_validation.FALLBACK`)."""


_TERMS = {
    "tangential": "tangential",
    "prism": "prism",
    "trefoil": "trefoil",
    "centre-prior": "center_prior",
    "center-prior": "center_prior",
}


def parse(label: str) -> FitSpec:
    """The spec of a label: ``radial``, ``radial4``, ``radial4+tangential+prism``,
    ``radial4+tangential+prism+trefoil``,
    ``radial6+tangential+centre-prior``, ``radial2+division1``, ``radial4+field8x6``,
    ``radial4+tangential+field8x6@0.03`` (a field of 8 x 6 control points, its penalty), ``poly``,
    ``poly7`` (no degree: the default).

    Raises
    ------
    ValueError
        One line naming the label and what is wrong.
    """
    text = str(label).strip().lower()
    head, *terms = text.split("+")
    kind = next((k for k in KINDS if head.startswith(k)), None)
    if kind is None:
        raise ValueError(
            f"{label!r}: unknown model; expected radial<degree>[+tangential][+prism][+trefoil][+division<M>][+centre-prior] "
            "[+field<nx>x<ny>[@<penalty>]] or poly<degree>"
        )
    digits = head[len(kind) :]
    if digits and not digits.isdigit():
        raise ValueError(f"{label!r}: the degree must be a whole number, got {digits!r}")
    flags: dict[str, bool] = {}
    division = 0
    field: tuple[int, int] | None = None
    penalty: float | None = None
    for term in terms:
        if term.startswith("division") and term[len("division") :].isdigit():
            division = int(term[len("division") :])
            continue
        if term.startswith("field"):
            field, penalty = _parse_field(label, term)
            continue
        if term not in _TERMS:
            raise ValueError(
                f"{label!r}: unknown term {term!r}; known: tangential, prism, trefoil, division<M>, centre-prior, "
                "field<nx>x<ny>[@<penalty>]"
            )
        flags[_TERMS[term]] = True
    try:
        return FitSpec(
            kind, int(digits) if digits else None, division=division, field=field, field_penalty=penalty, **flags
        )
    except ValueError as exc:
        raise ValueError(f"{label!r}: {exc}") from None


def parse_choice(label: str) -> FitSpec | None:
    """What a ``model`` option or setting names: the spec of a label (:func:`parse`), or None for
    :data:`AUTO` (chosen by cross-validation). ValueError (one line) as :func:`parse`."""
    return None if str(label).strip().lower() == AUTO else parse(label)


def _parse_field(label: str, term: str) -> tuple[tuple[int, int], float | None]:
    """``(nx, ny), penalty`` of a label's ``field<nx>x<ny>[@<penalty>]`` term (ValueError, one line)."""
    body, _, pen = term[len("field") :].partition("@")
    nx, _, ny = body.partition("x")
    if not (nx.isdigit() and ny.isdigit()):
        raise ValueError(f"{label!r}: a field term is field<nx>x<ny>[@<penalty>], e.g. field8x6@0.01; got {term!r}")
    if not pen:
        return (int(nx), int(ny)), None
    try:
        return (int(nx), int(ny)), float(pen)
    except ValueError:
        raise ValueError(f"{label!r}: the field penalty must be a number, got {pen!r}") from None
