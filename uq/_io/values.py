"""Checks of option values shared by the command line and the batch catalogue: each takes the text and
returns the value, or raises ValueError with a message fit to follow "option --x:" or "row 3, column x:";
and :func:`resolve`, an object named by its text ``"module:attribute"`` (a registry entry's fitter,
a worker process's function)."""

from __future__ import annotations

import importlib
import math


def resolve(target):
    """An object named ``"module:attribute"`` (imported now), or the object itself."""
    if not isinstance(target, str):
        return target
    module, _, attr = target.partition(":")
    return getattr(importlib.import_module(module), attr)


def _number(text: str, kind=float):
    try:
        value = kind(text)
    except ValueError:
        raise ValueError(
            f"expected {'an integer' if kind is int else 'a number'}, got '{text}'"
        ) from None
    if kind is float and not math.isfinite(value):
        raise ValueError(f"expected a finite number, got '{text}'")
    return value


def positive_float(text: str) -> float:
    value = _number(text)
    if not value > 0:
        raise ValueError(f"expected a positive number, got '{text}'")
    return value


def nonnegative_float(text: str) -> float:
    value = _number(text)
    if value < 0:
        raise ValueError(f"expected a number >= 0, got '{text}'")
    return value


def finite_float(text: str) -> float:
    return _number(text)


def positive_int(text: str) -> int:
    value = _number(text, int)
    if value < 1:
        raise ValueError(f"expected a positive integer, got '{text}'")
    return value


def walkers(text: str) -> int:
    value = _number(text, int)
    if value < 4 or value % 4:  # emcee's snooker move splits each ensemble in four sub-ensembles
        raise ValueError(f"expected a multiple of 4 walkers, at least 4, got '{text}'")
    return value


def seed(text: str) -> int:
    value = _number(text, int)
    if not 0 <= value < 2**63:  # numpy's seed sequences take non-negative integers
        raise ValueError(f"expected an integer seed >= 0, got '{text}'")
    return value


def compression(text: str) -> str:
    """The file's force sign convention: 'positive' (compression positive) or 'negative'."""
    value = text.strip()
    if value not in ("positive", "negative"):
        raise ValueError(f"expected positive or negative, got '{text}'")
    return value


def boolean(text: str) -> bool:
    value = text.strip().lower()
    if value in ("true", "yes", "1"):
        return True
    if value in ("false", "no", "0"):
        return False
    raise ValueError(f"expected true or false, got '{text}'")
