"""Validation of frozen settings dataclasses from their field metadata.

Every settings field carries ``metadata={'description': str, 'range': (lo, hi)}`` for
numbers (inclusive bounds), or ``'choices': (...)`` for strings. ``check_fields`` is
called from ``__post_init__`` and raises ``ValueError`` naming the field and its range,
so a bad YAML or a bad ``ros2 param set`` fails loudly instead of running wrongly.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any


def param(default: Any, description: str, range: tuple | None = None,
          choices: tuple | None = None, read_only: bool = False):
    """A dataclass field with the metadata that nodes turn into parameter descriptors."""
    md: dict[str, Any] = {'description': description, 'read_only': read_only}
    if range is not None:
        md['range'] = range
    if choices is not None:
        md['choices'] = tuple(choices)
    if isinstance(default, (list, dict)):
        raise TypeError('use a tuple for sequence defaults (settings are frozen)')
    return dataclasses.field(default=default, metadata=md)


def check_fields(obj: Any) -> None:
    """Check every field of a settings dataclass against its metadata.

    Raises:
        ValueError: '<Class>.<field> = <value> is out of range [lo, hi] (<description>)'.
        TypeError: a number field holding a non-number, or a bool field a non-bool.
    """
    cls = type(obj).__name__
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        md = f.metadata
        desc = md.get('description', '')
        if 'range' in md:
            lo, hi = md['range']
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise TypeError(f'{cls}.{f.name} must be a number in [{lo}, {hi}], '
                                f'got {value!r} ({desc})')
            if (isinstance(f.default, int) and not isinstance(f.default, bool)
                    and not isinstance(value, int)):
                raise TypeError(f'{cls}.{f.name} must be a whole number in [{lo}, {hi}], '
                                f'got {value!r} ({desc})')
            if isinstance(value, float) and not math.isfinite(value):
                raise ValueError(f'{cls}.{f.name} = {value} is not finite; '
                                 f'must be in [{lo}, {hi}] ({desc})')
            if not (lo <= value <= hi):
                raise ValueError(f'{cls}.{f.name} = {value} is out of range '
                                 f'[{lo}, {hi}] ({desc})')
        if 'choices' in md and value not in md['choices']:
            raise ValueError(f'{cls}.{f.name} = {value!r} is not one of '
                             f'{list(md["choices"])} ({desc})')
        if isinstance(f.default, bool) and not isinstance(value, bool):
            raise TypeError(f'{cls}.{f.name} must be true or false, got {value!r} ({desc})')


def to_dict(obj: Any) -> dict[str, Any]:
    """Settings dataclass to a plain dict (tuples kept as lists for YAML)."""
    out = {}
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        out[f.name] = list(v) if isinstance(v, tuple) else v
    return out
