"""JSON schemas shipped with phiscene and a validator that names file and field."""

from __future__ import annotations

import json
from functools import cache
from importlib import resources
from pathlib import Path
from typing import Any

from phiscene.errors import InputError


@cache
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
        where, msg = field_path(err.path), err.message
        if err.validator == "required" and isinstance(err.instance, dict):
            missing = [k for k in err.validator_value if k not in err.instance]
            where, msg = _join(where, missing[0]), "required field is missing"
        elif err.validator == "additionalProperties" and isinstance(err.instance, dict):
            allowed = sorted(err.schema.get("properties", {}))
            extra = sorted(k for k in err.instance if k not in allowed)
            where, msg = _join(where, extra[0]), f"unknown field (allowed: {', '.join(allowed)})"
        elif err.validator in ("minItems", "maxItems") and isinstance(err.instance, list):
            bound = "at least" if err.validator == "minItems" else "at most"
            msg = f"has {len(err.instance)} items, expected {bound} {err.validator_value}"
        elif err.validator == "not":
            msg = f"{err.instance!r} is not allowed here (reserved)"
        if len(msg) > 200:
            msg = msg[:200] + "..."
        raise InputError(path, where, msg)


def _join(where: str, key: str) -> str:
    """``objects[0]`` + ``pose`` -> ``objects[0].pose`` (the top level has no prefix)."""
    return key if where == "(top level)" else f"{where}.{key}"


def read_json(path: str | Path) -> Any:
    """Read a JSON file.

    Raises
    ------
    InputError
        Missing, empty or malformed file.
    phiscene.failures.FailedInput
        The file is a failure record (an upstream job failed on this scene).
    """
    from phiscene.failures import FailedInput, is_failure_record

    path = Path(path)
    if not path.is_file():
        raise InputError(path, None, "file not found")
    try:
        text = path.read_text()
        if not text.strip():
            raise InputError(path, None, "file is empty")
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(path, None, f"not valid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})") from None
    except UnicodeDecodeError:
        raise InputError(path, None, "not a UTF-8 text file") from None
    if is_failure_record(data):
        raise FailedInput(path, data)
    return data
