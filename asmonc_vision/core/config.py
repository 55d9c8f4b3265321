"""Validation of frozen settings dataclasses from their field metadata.

Every settings field carries ``metadata={'description': str, 'range': (lo, hi)}`` for
numbers (inclusive bounds), or ``'choices': (...)`` for strings. ``check_fields`` is
called from ``__post_init__`` and raises ``ValueError`` naming the field and its range,
so a bad YAML or a bad ``ros2 param set`` fails loudly instead of running wrongly.

A field made with ``group`` holds a settings dataclass of its own (a stage's settings
inside a detector's): its parameters are named ``<group>.<field>`` (``flat_fields``),
and ``override`` sets them by those dotted names.
"""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any, TypeVar

T = TypeVar('T')


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


def group(cls: type, description: str):
    """A dataclass field holding the settings dataclass `cls` (default: its defaults)."""
    return dataclasses.field(default_factory=cls,
                             metadata={'description': description, 'group': cls})


def is_group(f: dataclasses.Field) -> bool:
    """True for a field made with `group`."""
    return 'group' in f.metadata


def flat_fields(cls: type, prefix: str = '') -> list[tuple[str, dataclasses.Field]]:
    """Every leaf field of settings class `cls` with its dotted name, groups expanded in
    declaration order: [('threshold.k', Field), ...] (`prefix` put before each)."""
    out: list[tuple[str, dataclasses.Field]] = []
    for f in dataclasses.fields(cls):
        if is_group(f):
            out += flat_fields(f.metadata['group'], f'{prefix}{f.name}.')
        else:
            out.append((prefix + f.name, f))
    return out


def flat_values(obj: Any, prefix: str = '') -> dict[str, Any]:
    """{dotted name: value} of every leaf field of settings `obj` (see `flat_fields`)."""
    out: dict[str, Any] = {}
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if is_group(f):
            out.update(flat_values(value, f'{prefix}{f.name}.'))
        else:
            out[prefix + f.name] = value
    return out


def override(obj: T, values: Mapping[str, Any]) -> T:
    """A copy of settings `obj` with the fields named in `values` (dotted names for the
    fields of a group, e.g. {'threshold.k': 3.0, 'plane.update': 'none'}) replaced and
    validated again.

    Raises:
        ValueError: a name that is no field ('<Class> has no setting <name>'), or a value
            the settings' own checks refuse.
    """
    own: dict[str, Any] = {}
    nested: dict[str, dict[str, Any]] = {}
    known = {name for name, _ in flat_fields(type(obj))}
    for name, value in values.items():
        if name not in known:
            raise ValueError(f'{type(obj).__name__} has no setting {name!r}')
        head, dot, rest = name.partition('.')
        if dot:
            nested.setdefault(head, {})[rest] = value
        else:
            own[head] = value
    for head, sub in nested.items():
        try:
            own[head] = override(getattr(obj, head), sub)
        except (ValueError, TypeError) as exc:
            # 'ThresholdSettings.k = ...' -> 'GpodConfig.threshold.k = ...'
            inner = type(getattr(obj, head)).__name__ + '.'
            text = str(exc)
            text = (text.replace(inner, f'{type(obj).__name__}.{head}.', 1)
                    if text.startswith(inner) else f'{type(obj).__name__}.{head}: {text}')
            raise type(exc)(text) from exc
    return dataclasses.replace(obj, **own)  # type: ignore[type-var]


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
        if is_group(f):
            if not isinstance(value, md['group']):
                raise TypeError(f'{cls}.{f.name} must be a {md["group"].__name__}, '
                                f'got {type(value).__name__} ({desc})')
            continue
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
    """Settings dataclass to a plain dict (tuples kept as lists for YAML; a group as a
    dict of its own)."""
    out: dict[str, Any] = {}
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        out[f.name] = to_dict(v) if is_group(f) else list(v) if isinstance(v, tuple) else v
    return out
