"""Atomic file writes: a failed job never leaves a half-written output.

Every writer in phiscene goes through :func:`atomic_path`, which yields a
temporary path in the destination folder and renames it over the target only
when the block finishes without an exception.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any


@contextlib.contextmanager
def atomic_path(path: str | Path, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path that is renamed to ``path`` on success.

    Parameters
    ----------
    path
        Final destination. Parent folders are created.
    suffix
        Suffix of the temporary file (defaults to the destination's, so
        libraries that pick a format by extension still work).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(
        prefix=f".{path.name}.", suffix=suffix if suffix is not None else "".join(path.suffixes),
        dir=path.parent,
    )
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        os.replace(tmp_path, path)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def write_text(path: str | Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def write_json(path: str | Path, data: Any) -> None:
    """Write ``data`` as indented JSON atomically (NaN is refused)."""
    text = json.dumps(data, indent=1, allow_nan=False, sort_keys=False) + "\n"
    write_text(path, text)


#: What an importer writes under its output folder (:func:`staged_folder`).
IMPORT_ENTRIES = ("initial", "reference", "import.json")


@contextlib.contextmanager
def staged_folder(out_dir: str | Path, entries: tuple[str, ...] = IMPORT_ENTRIES) -> Iterator[Path]:
    """Yield a staging folder beside ``out_dir``; on success its ``entries`` replace those of ``out_dir``.

    A writer of several files (an importer: meshes, ``scene.json``, the camera, ``import.json``) writes them all
    into the staging folder; only when the block finishes without an exception is each entry of ``out_dir`` named
    in ``entries`` removed and the staged one moved in its place. A failure leaves ``out_dir`` as it was, with
    nothing half-written (an earlier import into it stays whole, not mixed with the new one's meshes).
    """
    import shutil

    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        from phiscene.errors import InputError

        raise InputError(out_dir, None, "output folder is an existing file")
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.staged-", dir=out_dir.parent))
    try:
        yield stage
        out_dir.mkdir(parents=True, exist_ok=True)
        for name in entries:
            target, staged = out_dir / name, stage / name
            if target.is_dir() and not target.is_symlink():
                shutil.rmtree(target)
            elif target.exists() or target.is_symlink():
                target.unlink()
            if staged.exists():
                os.replace(staged, target)
    finally:
        shutil.rmtree(stage, ignore_errors=True)
