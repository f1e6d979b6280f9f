"""Shared base of the frozen parameter dataclasses filled from ``config.yaml``.

Every stage reads its settings into a ``@dataclass(frozen=True)`` that derives from
:class:`Params`: :meth:`Params.from_dict` rejects unknown keys with a one-line
``ValueError`` naming them and the known ones, builds nested parameter dataclasses from
nested mappings, constructs the dataclass and runs its :meth:`Params.check` range
validation; :meth:`Params.to_dict` turns it back into plain data.

Examples
--------
>>> from dataclasses import dataclass
>>> @dataclass(frozen=True)
... class StepParams(Params):
...     _label = "step parameters"
...     n: int = 1
...     def check(self) -> None:
...         if self.n < 1:
...             raise ValueError(f"step n must be >= 1, got {self.n}")
>>> StepParams.from_dict({"n": 3}).to_dict()
{'n': 3}
>>> StepParams.from_dict({"m": 3})
Traceback (most recent call last):
...
ValueError: unknown step parameters ['m']; known: ['n']
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Mapping
from dataclasses import asdict, fields
from typing import Any, ClassVar, TypeVar

P = TypeVar("P", bound="Params")


class Params:
    """Mixin for frozen parameter dataclasses built from config mappings.

    Subclasses are ``@dataclass(frozen=True)`` classes; they customise parsing through two
    class attributes (plain assignments without annotations, so they are not dataclass fields)
    and one hook.

    Attributes
    ----------
    _label : str or None
        What the unknown-key error calls the mapping (``"unknown <label> [...]"``), for
        example ``"settle parameters"``; ``None`` (default) gives ``"<ClassName> keys"``.
    _coerce : Mapping[str, Callable[[Any], Any]]
        Per-field conversions applied to the raw config value, when the key is given,
        before construction (for example ``{"solimp": lambda v: tuple(float(x) for x in v)}``).
    """

    _label: ClassVar[str | None] = None
    _coerce: ClassVar[Mapping[str, Callable[[Any], Any]]] = {}

    @classmethod
    def from_dict(cls: type[P], d: Mapping[str, Any] | None) -> P:
        """Build from a config mapping.

        Parameters
        ----------
        d
            Field values by name; ``None`` or an empty mapping gives the defaults. A field whose
            type is itself a :class:`Params` subclass accepts a nested mapping (or ``None``, the
            defaults) as well as an instance; any other value is an error.

        Returns
        -------
        Params
            The instance, after :meth:`check`.

        Raises
        ------
        ValueError
            For unknown keys (naming them and the known ones), a nested field given something
            other than a mapping, or a value that fails a conversion, the dataclass's own
            ``__post_init__`` or :meth:`check`.
        """
        d = dict(d or {})
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            label = cls._label or f"{cls.__name__} keys"
            raise ValueError(f"unknown {label} {unknown}; known: {sorted(known)}")
        for name, convert in cls._coerce.items():
            if name in d:
                d[name] = convert(d[name])
        for name, sub in nested_params(cls).items():
            value = d.get(name)
            if name in d and not isinstance(value, sub):
                if value is not None and not isinstance(value, Mapping):
                    raise ValueError(f"{cls.__name__}.{name} must be a mapping of {sub.__name__} fields, "
                                     f"got {value!r}")
                d[name] = sub.from_dict(value)
        p = cls(**d)
        p.check()
        return p

    def check(self) -> None:
        """Validate value ranges after construction (no-op here; subclasses override).

        Raises
        ------
        ValueError
            Naming the offending field(s) and value(s).
        """

    def to_dict(self) -> dict:
        """Plain-data form (nested parameter dataclasses become nested dicts)."""
        return asdict(self)


def nested_params(cls: type) -> dict[str, type[Params]]:
    """Fields of dataclass ``cls`` whose declared type is a :class:`Params` subclass.

    Annotations are strings under ``from __future__ import annotations``; a bare class name is
    looked up in the defining module (other annotations are never parameter dataclasses here).
    """
    module = vars(sys.modules[cls.__module__])
    nested = {}
    for f in fields(cls):
        typ = module.get(f.type) if isinstance(f.type, str) else f.type
        if isinstance(typ, type) and issubclass(typ, Params):
            nested[f.name] = typ
    return nested
