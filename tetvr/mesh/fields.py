"""Which field of a file is rendered, and how: the default choice when none is named (the
first field that varies: a constant one draws the mesh's shape in one colour), the warning
when a named field is constant, and a vector field made a scalar (its magnitude, or one
component)."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from tetvr.core.checks import warn

__all__ = ["choose_field", "warn_constant"]


def _scalar_of(values: NDArray[Any], component: int | None) -> str:
    """How the rendered scalar comes from a field (:attr:`tetvr.mesh.tetmesh.MeshReport.scalar_of`)."""
    v = np.asarray(values)
    if v.ndim != 2 or v.shape[1] == 1:
        return ""
    return "magnitude" if component is None else f"component {component}"


def _plain(value: float) -> str:
    """A value as a reader writes it: ``1.0``, ``0.25``, ``1e+20``."""
    text = f"{value:.6g}"
    return text if any(c in text for c in ".ein") else text + ".0"


def _varies(values: NDArray[Any]) -> bool:
    finite = values[np.isfinite(values)]
    return finite.size > 0 and bool(finite.max() > finite.min())


def choose_field(fields: list[tuple[str, Any]], component: int | None, where: str) -> str:
    """The field to render when none is named: the first of ``fields`` (``(name, values)``
    pairs, point fields first, then cell fields) whose values vary. A constant field draws
    the mesh's shape in one colour and its legend says nothing, so fields that are constant
    are passed over, with a warning naming them and the field chosen; when every field is
    constant, the first is chosen, with a warning.

    >>> import warnings
    >>> with warnings.catch_warnings(record=True) as said:
    ...     warnings.simplefilter("always")
    ...     choose_field([("ones", np.ones(4)), ("T", np.arange(4.0))], None, "m.vtu")
    'T'
    >>> str(said[0].message)[:55]
    "m.vtu: field 'ones' (1.0 everywhere) is constant; rende"
    """
    if not fields:
        raise ValueError(f"{where} has no point or cell data to render")
    constant = []
    for name, values in fields:
        try:
            scalar = _field_to_scalar(values, name, component)
        except ValueError:
            continue  # not renderable with this component; the first field's error is the one said
        if _varies(scalar):
            if constant:
                said = " and ".join(f"{n!r} ({_plain(v)} everywhere)" for n, v in constant)
                warn(f"{where}: {'field' if len(constant) == 1 else 'fields'} {said} "
                     f"{'is' if len(constant) == 1 else 'are'} constant; rendering {name!r}, the first field that "
                     "varies (name a field to render another: scalars=..., or --scalars)")
            return name
        finite = scalar[np.isfinite(scalar)]
        constant.append((name, float(finite[0]) if finite.size else float("nan")))
    name = fields[0][0]
    if constant and constant[0][0] == name:
        warn_constant(where, name, constant[0][1], every=len(constant) == len(fields))
    return name


def warn_constant(where: str, name: str, value: float, *, every: bool = False) -> None:
    """Warn that the field rendered is constant: the picture shows only the mesh's shape."""
    lead = f"every field is constant; rendering the first, {name!r}" if every else f"field {name!r} is constant"
    warn(f"{where}: {lead} ({_plain(value)} everywhere): the picture shows the mesh's shape in one colour, "
         "and its legend says only that value")


def _check_named_field(values: NDArray[Any], name: str, where: str) -> None:
    """Warn when a field named on purpose is constant."""
    if not _varies(values):
        finite = values[np.isfinite(values)]
        warn_constant(where, name, float(finite[0]) if finite.size else float("nan"))


def _field_to_scalar(values: NDArray[Any], name: str, component: int | None) -> NDArray[np.float64]:
    v = np.asarray(values)
    if v.ndim == 2 and v.shape[1] == 1:
        v = v[:, 0]
    if v.ndim == 1 and component not in (None, 0):
        raise ValueError(f"field {name!r} is a scalar field; component {component} is out of range")
    if v.ndim == 2:
        if component is None:
            return np.linalg.norm(v.astype(np.float64), axis=1)
        if not 0 <= component < v.shape[1]:
            raise ValueError(f"field {name!r} has {v.shape[1]} components; component {component} is out of range")
        return v[:, component].astype(np.float64)
    if v.ndim != 1:
        raise ValueError(f"field {name!r} has unsupported shape {v.shape}")
    return v
