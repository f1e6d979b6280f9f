"""JSON schemas shipped with phiscene and a validator that names file and field."""

from __future__ import annotations

import json
from functools import lru_cache
from importlib import resources
from pathlib import Path
from typing import Any

from phiscene.errors import InputError


@lru_cache(maxsize=None)
def load_schema(name: str) -> dict:
    """Return the packaged JSON schema ``<name>.schema.json``."""
    text = resources.files("phiscene.schemas").joinpath(f"{name}.schema.json").read_text()
    return json.loads(text)


def field_path(parts) -> str:
    """Render a jsonschema error path as ``objects[2].pose``."""
    out = ""
    for p in parts:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else str(p))
    return out or "(top level)"


def validate(data: Any, name: str, path: str | Path | None) -> None:
    """Validate ``data`` against schema ``name``; raise :class:`InputError` on the first problem."""
    import jsonschema

    validator = jsonschema.Draft202012Validator(load_schema(name))
    errors = sorted(validator.iter_errors(data), key=lambda e: (len(e.path), list(map(str, e.path))))
    if errors:
        err = errors[0]
        if err.validator == "const" and list(err.path) == ["format"]:
            raise InputError(path, "format", f"unknown format {err.instance!r}, expected {err.validator_value!r}")
        msg = err.message
        if len(msg) > 200:
            msg = msg[:200] + "..."
        raise InputError(path, field_path(err.path), msg)


def read_json(path: str | Path) -> Any:
    """Read a JSON file; missing or malformed files raise :class:`InputError`."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, None, "file not found")
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise InputError(path, None, f"not valid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})") from None
    except UnicodeDecodeError:
        raise InputError(path, None, "not a UTF-8 text file") from None
