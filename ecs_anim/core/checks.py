"""Checking values at the API's boundary before anything is written: numbers, arrays of a
given shape, and the fields of the package's plain-data classes against their type hints;
each refusal a :class:`~ecs_anim.core.errors.UsageError` of one line saying what was expected
and what was found."""

from __future__ import annotations

import dataclasses
import functools
import numbers
import types
import typing
from typing import Any, Union, cast

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.errors import UsageError, quoted
from ecs_anim.core.ground import Ground

F64 = NDArray[np.float64]


def is_integer(value: object) -> bool:
    """Whether ``value`` is an integer (a Python or numpy one; a bool is not)."""
    return isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_))


def is_real(value: object) -> bool:
    """Whether ``value`` is a real number (int, float or a numpy number; not a bool, a text or
    an array)."""
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def real_number(value: object, what: str) -> float:
    """``value`` as a float if :func:`is_real`; else a :class:`UsageError` naming ``what``.
    Finite or not: callers say."""
    if is_real(value):
        return float(cast(float, value))
    raise UsageError(f"{what} must be a number, got {found(value)}")


def real_array(value: object, shape: tuple[int | None, ...], what: str) -> F64:
    """``value`` (a tuple, list or numpy array of real numbers) as a float64 array of ``shape``
    (None: any length on that axis); else a :class:`UsageError` naming ``what`` and saying
    what was found. Texts, booleans and objects are refused, not converted."""
    if isinstance(value, (str, bytes)) or value is None:
        raise UsageError(f"{what} must be numbers of shape {shape_text(shape)}, got {found(value)}")
    try:
        array = np.asarray(value)
    except ValueError:  # a ragged list
        raise UsageError(f"{what} must be numbers of shape {shape_text(shape)}, got a ragged list") \
            from None
    if array.dtype.kind not in "iuf":
        raise UsageError(f"{what} must be numbers of shape {shape_text(shape)}, got {found(value)}")
    if array.ndim != len(shape) or any(n is not None and n != k for n, k in zip(shape, array.shape,
                                                                                strict=True)):
        raise UsageError(f"{what} must have shape {shape_text(shape)}, got shape {array.shape}")
    return array.astype(np.float64)


def shape_text(shape: tuple[int | None, ...]) -> str:
    return "(" + ", ".join("k" if n is None else str(n) for n in shape) + ("," if len(shape) == 1 else "") + ")"


def found(value: object) -> str:
    """A refused value in an error message: its type and its repr, cut to one short line."""
    return f"{type(value).__name__} {quoted(repr(value), 40)[1:-1]}"


def hint_name(hint: Any) -> str:
    return " | ".join(hint_name(a) for a in typing.get_args(hint)) \
        if typing.get_origin(hint) in (Union, types.UnionType) else getattr(hint, "__name__", str(hint))


@functools.cache
def _field_hints(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def conforms(value: object, hint: Any) -> bool:
    """Whether ``value`` fits the type hint ``hint`` of a field of the package's plain-data
    classes (numbers, texts, flags, tuples, unions, grounds, classes; a dataclass value has its
    own fields checked too). Numbers may be numpy numbers and tuples lists or arrays; a bool
    is not a number and a text is not a tuple. Hints not listed here (arrays) are the class's
    own to check."""
    if hint is type(None):
        return value is None
    if hint is float:
        return is_real(value)
    if hint is int:
        return is_integer(value)
    if hint is bool:
        return isinstance(value, (bool, np.bool_))
    if hint is str:
        return isinstance(value, str)
    if hint is Ground:
        return callable(getattr(value, "height", None))
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (Union, types.UnionType):
        return any(conforms(value, a) for a in args)
    if origin is tuple:
        if not isinstance(value, (tuple, list, np.ndarray)):
            return False
        items = list(value)
        if len(args) == 2 and args[1] is Ellipsis:
            return all(conforms(v, args[0]) for v in items)
        return len(items) == len(args) and all(map(conforms, items, args))
    if isinstance(hint, type):
        return isinstance(value, hint) and fields_problem(value) is None
    return True


def fields_problem(value: object) -> str | None:
    """The first field of a dataclass ``value`` that does not fit its type hint, said in a few
    words (``"Play.clip: expected str, got int 3"``), or None when every field fits (and for a
    value that is not a dataclass)."""
    if not dataclasses.is_dataclass(value) or isinstance(value, type):
        return None
    hints = _field_hints(type(value))
    for f in dataclasses.fields(value):
        item = getattr(value, f.name)
        if not conforms(item, hints[f.name]):
            inner = fields_problem(item) if isinstance(hints[f.name], type) else None
            return inner or (f"{type(value).__name__}.{f.name}: expected "
                             f"{hint_name(hints[f.name])}, got {found(item)}")
    return None


def as_triple(values: NDArray[np.float64]) -> tuple[float, float, float]:
    """A checked (3,) array as the 3-tuple of floats the plain-data classes hold."""
    return float(values[0]), float(values[1]), float(values[2])


def check_value(value: object, hint: Any, what: str) -> None:
    """Raise :class:`UsageError` naming ``what`` unless ``value`` fits ``hint``."""
    if not conforms(value, hint):
        problem = fields_problem(value) if isinstance(hint, type) and isinstance(value, hint) else None
        raise UsageError(f"{what}: {problem}" if problem else
                         f"{what}: expected {hint_name(hint)}, got {found(value)}")
