"""Terrain spec fields: typed, range-checked reading of a terrain YAML (one-line errors).

Every field error names the file and the dotted field path; unknown fields are errors.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from planner.core.errors import TerrainError

_REQUIRED = object()


def _one_line(text: str) -> str:
    """Collapse whitespace (including newlines) to single spaces."""
    return " ".join(str(text).split())


def _error(source: str, field: str, message: str) -> TerrainError:
    """A one-line error naming the file and the field."""
    return TerrainError(_one_line(f"{source}: field '{field}': {message}"))


class _YamlLoader(yaml.SafeLoader):
    """PyYAML's safe loader (YAML 1.1), reading YAML 1.2's floats too.

    ``1e9`` and ``1.0e9`` are numbers (YAML 1.1 wants a dot and a signed exponent,
    ``1.0e+9``, and reads them as strings).
    """


_YamlLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?[0-9][0-9_]*(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"),
)


def _show(value: Any) -> str:
    """Short repr of a bad value for an error message."""
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


class _Fields:
    """Typed, range-checked access to one mapping of a spec; records which keys were used."""

    def __init__(self, data: Any, source: str, prefix: str, what: str = "a mapping"):
        if not isinstance(data, Mapping):
            raise _error(
                source, prefix.rstrip(".") or "(top level)", f"expected {what}, got {_show(data)}"
            )
        self.data = dict(data)
        self.source = source
        self.prefix = prefix
        self.used: set[str] = set()

    def path(self, key: str) -> str:
        """Dotted field path for messages."""
        return f"{self.prefix}{key}"

    def fail(self, key: str, message: str) -> TerrainError:
        """Error about ``key``."""
        return _error(self.source, self.path(key), message)

    def has(self, key: str) -> bool:
        """Whether ``key`` was given (and not null)."""
        return self.data.get(key) is not None

    def raw(self, key: str, default: Any = _REQUIRED, hint: str = "") -> Any:
        """The value of ``key``, or ``default``; missing required keys raise."""
        self.used.add(key)
        value = self.data.get(key)
        if value is None:
            if default is _REQUIRED:
                raise self.fail(key, f"missing; add it{(' (' + hint + ')') if hint else ''}")
            return default
        return value

    def number(
        self,
        key: str,
        default: Any = _REQUIRED,
        *,
        lo: float | None = None,
        hi: float | None = None,
        lo_open: bool = False,
        nonzero: bool = False,
        hint: str = "a number",
    ) -> float:
        """A finite float in [lo, hi] (or (lo, hi] with ``lo_open``)."""
        value = self.raw(key, default, hint)
        if value is None:
            return value
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            numeric = isinstance(value, str) and any(c.isdigit() for c in value)
            hint = "; write it as a plain number, e.g. 0.25 or 1e3" * numeric
            raise self.fail(key, f"expected a number, got {_show(value)}{hint}")
        value = float(value)
        if not math.isfinite(value):
            raise self.fail(key, f"expected a finite number, got {value}")
        if lo is not None and (value < lo or (lo_open and value == lo)):
            bound = f"> {lo}" if lo_open else f">= {lo}"
            raise self.fail(key, f"must be {bound}, got {value}; change it")
        if hi is not None and value > hi:
            raise self.fail(key, f"must be <= {hi}, got {value}; change it")
        if nonzero and value == 0.0:
            raise self.fail(key, "must not be 0; give a non-zero value")
        return value

    def integer(
        self, key: str, default: Any = _REQUIRED, *, lo: int | None = None, hi: int | None = None
    ) -> int:
        """An integer in [lo, hi]."""
        value = self.raw(key, default, "an integer")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or value != int(value):
            raise self.fail(key, f"expected an integer, got {_show(value)}")
        value = int(value)
        if lo is not None and value < lo:
            raise self.fail(key, f"must be >= {lo}, got {value}; change it")
        if hi is not None and value > hi:
            raise self.fail(key, f"must be <= {hi}, got {value}; change it")
        return value

    def string(self, key: str, default: Any = _REQUIRED) -> str:
        """A string."""
        value = self.raw(key, default, "a string")
        if not isinstance(value, str):
            raise self.fail(key, f"expected a string, got {_show(value)}")
        return value

    def pair(self, key: str, default: Any = _REQUIRED) -> list[float] | None:
        """Two finite numbers ``[a, b]``."""
        value = self.raw(key, default, "[x, y] in metres")
        if value is None:
            return None
        if (
            not isinstance(value, (list, tuple))
            or len(value) != 2
            or not all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                for v in value
            )
        ):
            raise self.fail(key, f"expected [x, y] (two finite numbers), got {_show(value)}")
        return [float(value[0]), float(value[1])]

    def numbers(
        self, key: str, count: int, default: Any = _REQUIRED, hint: str = ""
    ) -> list[float] | None:
        """A list of ``count`` finite numbers."""
        value = self.raw(key, default, hint)
        if value is None:
            return None
        if (
            not isinstance(value, (list, tuple))
            or len(value) != count
            or not all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                for v in value
            )
        ):
            what = hint or f"{count} finite numbers"
            raise self.fail(key, f"expected {what}, got {_show(value)}")
        return [float(v) for v in value]

    def finish(self, known: Sequence[str] | None = None) -> None:
        """Reject any key that was not read."""
        extra = sorted(set(self.data) - self.used)
        if extra:
            names = ", ".join(sorted(known if known is not None else self.used))
            raise self.fail(extra[0], f"unknown field; remove it or use one of: {names}")


@dataclass(frozen=True)
class _Context:
    """Where a kind lives: its x span (local coordinates), the course's y span, smoothing."""

    u0: float
    u1: float
    y0: float
    y1: float
    w: float
    base_dir: Path | None
