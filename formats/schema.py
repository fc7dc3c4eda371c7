"""Typed reading of untrusted JSON metadata: every field checked for type and range before use.

A :class:`Fields` wraps one JSON object and names it in errors (file, section, key path), so a
header parser reads like a schema::

    f = Fields(cfg, "x.lfc: config")
    B = f.int("block_size", choices=(4, 8, 16))
    q16 = f.int_list("q16", length=P, lo=16, hi=1 << 20)

Integers must be JSON integers (not floats, not bools); floats must be finite; nothing is
coerced silently. Every failure is a :class:`~formats.errors.FormatError`.
"""
from __future__ import annotations

import math

from .errors import FormatError

_MISSING = object()


class Fields:
    """Checked access to a JSON object's fields.

    Args:
        obj: the parsed JSON value (must be a dict).
        where: a name for messages, e.g. ``"scene.lfc: config"``.
    """

    def __init__(self, obj, where: str):
        if not isinstance(obj, dict):
            raise FormatError(f"{where}: expected a JSON object, got {type(obj).__name__}")
        self.obj, self.where = obj, where

    def _get(self, key, default):
        if key in self.obj:
            return self.obj[key]
        if default is _MISSING:
            raise FormatError(f"{self.where}: missing field {key!r}")
        return default

    def _bad(self, key, what, v):
        r = repr(v)
        raise FormatError(f"{self.where}: field {key!r} must be {what}, got {r[:60]}{'...' if len(r) > 60 else ''}")

    def has(self, key) -> bool:
        return key in self.obj

    def int(self, key, lo=None, hi=None, *, choices=None, default=_MISSING) -> int:
        v = self._get(key, default)
        return check_int(v, lo, hi, choices, lambda what: self._bad(key, what, v))

    def float(self, key, lo=None, hi=None, *, default=_MISSING) -> float:
        v = self._get(key, default)
        if v is None and default is None:
            return None
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            self._bad(key, "a finite number", v)
        if (lo is not None and v < lo) or (hi is not None and v > hi):
            self._bad(key, f"within [{lo}, {hi}]", v)
        return float(v)

    def str(self, key, *, choices=None, max_len=256, default=_MISSING) -> str:
        v = self._get(key, default)
        if not isinstance(v, str) or len(v) > max_len:
            self._bad(key, f"a string of at most {max_len} characters", v)
        if choices is not None and v not in choices:
            self._bad(key, f"one of {', '.join(map(str, choices))}", v)
        return v

    def bool(self, key, *, default=_MISSING) -> bool:
        v = self._get(key, default)
        if not isinstance(v, bool):
            self._bad(key, "true or false", v)
        return v

    def int_list(self, key, *, length=None, min_len=0, max_len=1 << 24, lo=None, hi=None, default=_MISSING) -> list:
        v = self._get(key, default)
        if not isinstance(v, list):
            self._bad(key, "a list of integers", v)
        if length is not None and len(v) != length:
            self._bad(key, f"a list of {length} integers", v)
        if not min_len <= len(v) <= max_len:
            self._bad(key, f"a list of {min_len}..{max_len} integers", v)
        for x in v:
            check_int(x, lo, hi, None, lambda what: self._bad(key, f"a list of integers each {what}", x))
        return list(v)

    def list(self, key, *, max_len=1 << 20, default=_MISSING) -> list:
        v = self._get(key, default)
        if not isinstance(v, list) or len(v) > max_len:
            self._bad(key, f"a list of at most {max_len} items", v)
        return v

    def obj_(self, key, *, default=_MISSING) -> "Fields":
        v = self._get(key, default)
        return Fields(v, f"{self.where}.{key}")

    def sub(self, key, *, default=_MISSING) -> "Fields":
        """The nested object at ``key`` as Fields."""
        return self.obj_(key, default=default)


def check_int(v, lo=None, hi=None, choices=None, fail=None) -> int:
    """``v`` if it is a JSON integer within [lo, hi] (and in ``choices``), else ``fail(what)``."""
    def _fail(what):
        if fail is None:
            raise FormatError(f"expected {what}, got {v!r}")
        fail(what)

    if isinstance(v, bool) or not isinstance(v, int):
        _fail("an integer")
    if choices is not None and v not in choices:
        _fail(f"one of {', '.join(map(str, choices))}")
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        _fail(f"within [{lo}, {hi}]")
    return v


def read_vector(v, n: int, where: str) -> list:
    """``v`` if it is a JSON list of ``n`` finite numbers (as floats), else FormatError."""
    if not isinstance(v, list) or len(v) != n or any(
            isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x) for x in v):
        raise FormatError(f"{where}: must be a list of {n} finite numbers, got {repr(v)[:60]}")
    return [float(x) for x in v]
