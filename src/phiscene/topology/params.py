"""Base class of backend parameter dataclasses (``from_dict`` that rejects unknown keys)."""

from __future__ import annotations

from dataclasses import asdict, fields


class BackendParams:
    """Mixin for frozen parameter dataclasses filled from ``config.yaml`` (``topology.<backend>``)."""

    @classmethod
    def from_dict(cls, d: dict | None):
        """Build from a config mapping; unknown keys raise ``ValueError`` naming them."""
        d = dict(d or {})
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ValueError(f"unknown {cls.__name__} keys {unknown}; known: {sorted(known)}")
        return cls(**d)

    def to_dict(self) -> dict:
        return asdict(self)
