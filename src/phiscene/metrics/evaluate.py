"""Every metric of one method's scene in one pass: the per-scene metrics file.

A metrics file (``results/metrics/{method}/{suite}/{scene}.json``) holds the
sections the tables need of that scene, each computed by its own module::

    {"format": "phiscene.metrics/1", "sections": ["alignment", "physical"],
     "physical": {...}, "alignment": {...}}

The sections are the entries of the registry :mod:`phiscene.metrics.sections` (``physical``: penetration,
floating, pybullet drift; ``alignment``: mask IoU against the reference; ``recon``: MIDI-3D reconstruction
against ground truth; ``pose`` / ``pose_gt``: displacement and rotation change from the input, and pose error
against ground truth) and of the drift simulators of :mod:`phiscene.metrics.drift` (``mujoco``). Each names the
settings and input files it reads; :func:`required_inputs` and :func:`section_settings` answer for a set of them.

A method whose scenes live in another frame (config ``frame: own``, e.g. an imported peer's result in its own
levelled frame) is compared after the best rigid alignment of its object centres (``MetricTask.align``).

The workflow computes the files of every method of a scene in one job
(:func:`methods_metrics`): importing the simulators and mesh libraries costs a
process more than most sections' compute, so one process per scene, not per
method and section, halves the benchmark's metric time. If any section of a
method fails on that method's data, its whole file is a failure record
(:mod:`phiscene.failures`), which the tables count in ``n_failed``; the other
methods' files are unaffected.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from pathlib import Path

from phiscene.errors import InputError
from phiscene.failures import is_failure_record

log = logging.getLogger(__name__)

FORMAT = "phiscene.metrics/1"


def section_names() -> list[str]:
    """The registered metric sections, in computing order (:data:`phiscene.metrics.sections.SECTIONS`)."""
    import phiscene.metrics.drift  # noqa: F401  (registers the simulators' sections)
    from phiscene.metrics.sections import SECTIONS

    return list(SECTIONS)


@dataclass(frozen=True)
class MetricTask:
    """One method's metrics file of a scene.

    Attributes
    ----------
    method
        Method name (for the log and a failure record).
    scene
        The method's ``scene.json``.
    out
        The metrics file to write.
    sections
        Its sections (:func:`section_names`).
    proxies
        The method's own proxies (methods that bring their own meshes); ``None`` = the scene's shared ones.
    align
        The method's scenes are in their own frame: pose metrics align its object centres first.
    """

    method: str
    scene: str | Path
    out: str | Path
    sections: tuple[str, ...]
    proxies: str | Path | None = None
    align: bool = False


@dataclass(frozen=True)
class MetricInputs:
    """The files a scene's metrics read besides the scene itself (``None`` where no section needs one).

    Attributes
    ----------
    proxies
        Convex proxies ``.npz`` of the scene's objects (``physical``, ``mujoco``).
    gt
        Ground-truth ``scene.json`` (``recon``).
    initial
        Initial ``scene.json`` (``alignment``: pose change, and the objects' colours).
    reference_dir
        Folder with ``image.png``, ``segmentation.png`` and ``camera.json`` (``alignment``).
    cache_dir
        Content-addressed cache folder (hull files of the simulated sections).
    """

    proxies: str | Path | None = None
    gt: str | Path | None = None
    initial: str | Path | None = None
    reference_dir: str | Path | None = None
    cache_dir: str | Path | None = None


def check_sections(sections: list[str] | tuple[str, ...] | set[str]) -> list[str]:
    """The requested sections in computing order; ``ValueError`` naming an unknown or missing one."""
    known = section_names()
    unknown = sorted(set(sections) - set(known))
    if unknown:
        raise ValueError(f"unknown metric sections {unknown}; known: {known}")
    if not sections:
        raise ValueError("no metric sections requested")
    return [s for s in known if s in sections]


def required_inputs(sections: list[str] | tuple[str, ...]) -> list[str]:
    """Names of the :class:`MetricInputs` fields that ``sections`` need."""
    from phiscene.metrics.sections import SECTIONS

    return sorted({name for s in check_sections(sections) for name in SECTIONS[s].inputs})


def section_settings(sections: list[str] | tuple[str, ...]) -> list[str]:
    """Names of the settings (``sim``, keys of the ``metrics`` config section) that ``sections`` read."""
    from phiscene.metrics.sections import SECTIONS

    return sorted({name for s in check_sections(sections) for name in SECTIONS[s].settings})


def scene_metrics(scene_path: str | Path, sections: list[str] | tuple[str, ...], inputs: MetricInputs,
                  settings: dict, align: bool = False) -> dict:
    """Compute the requested metric sections of one scene.

    Parameters
    ----------
    scene_path
        The method's ``scene.json``.
    sections
        Any of :func:`section_names`.
    inputs
        The other files the sections read (see :func:`required_inputs`).
    settings
        Per settings name (:func:`section_settings`: ``physical``, ``sim``, ``mujoco``, ``alignment``, ...) the
        mapping for that parameter dataclass' ``from_dict``; a missing one takes the defaults.
    align
        Pose sections compare after the best rigid alignment of the object centres (a method in its own frame).

    Returns
    -------
    dict
        The metrics file's content (``format``, ``sections`` and one dict per section).

    Raises
    ------
    ValueError
        An unknown section, or an input a section needs is missing.
    phiscene.errors.PhisceneError
        Bad scene data (the workflow records it as a failed scene).
    """
    from phiscene.metrics.sections import SECTIONS, SectionContext
    from phiscene.scene import load_scene

    order = check_sections(sections)
    missing = [name for name in required_inputs(order) if getattr(inputs, name) is None]
    if missing:
        raise ValueError(f"metric sections {order} need {missing}")
    ctx = SectionContext(load_scene(scene_path), inputs, settings, align)
    out: dict = {"format": FORMAT, "sections": order}
    for name in order:
        section = SECTIONS[name]
        r = out[name] = section.compute(ctx)
        if section.summary is not None:
            log.info("%s: %s", name, section.summary(r))
    return out


def read_section(data: dict, section: str, path: str | Path | None = None) -> dict:
    """One section of a parsed metrics file; a failure record is returned as it is.

    Parameters
    ----------
    data
        The parsed JSON of a metrics file.
    section
        One of :func:`section_names`.
    path
        The file, for the error message.

    Raises
    ------
    InputError
        Not a metrics file, or it lacks ``section`` (made for other tables: rerun its metrics job).
    """
    if is_failure_record(data):
        return data
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        found = data.get("format") if isinstance(data, dict) else type(data).__name__
        raise InputError(path, "format", f"not a metrics file (format {found!r}, expected {FORMAT!r})")
    if not isinstance(data.get(section), dict):
        raise InputError(path, section, f"no {section!r} section (this file has {data.get('sections')}); "
                                        "its metrics job was made for other tables")
    return data[section]


def methods_metrics(tasks: list[MetricTask], inputs: MetricInputs, settings: dict, name: str = "metrics") -> dict:
    """Compute and write the metrics file of every task (the methods of one scene), in one process.

    A task whose scene data is bad (a :class:`~phiscene.errors.PhisceneError` that is ``per_scene``,
    e.g. a failed upstream job's record or a corrupt mesh) gets a failure record in its file and the
    others go on, as if each were its own job.

    Parameters
    ----------
    tasks
        The methods' files to make.
    inputs
        Files shared by the methods (a task's own ``proxies`` replaces the shared ones).
    settings
        As for :func:`scene_metrics`.
    name
        Job name, prefixed to each method's log lines and failure record.

    Returns
    -------
    dict
        Method -> ``True`` if its metrics were written, ``False`` if a failure record was.
    """
    import time

    from phiscene.atomic import write_json
    from phiscene.errors import PhisceneError
    from phiscene.failures import record_failure

    done = {}
    for task in tasks:
        t0 = time.perf_counter()
        job = f"{name} {task.method}"
        own = replace(inputs, proxies=task.proxies) if task.proxies is not None else inputs
        try:
            result = scene_metrics(task.scene, task.sections, own, settings, task.align)
        except PhisceneError as exc:
            if not exc.per_scene:
                raise
            record_failure(job, exc, [task.out], log)
            done[task.method] = False
            continue
        write_json(task.out, result)
        log.info("%s: %s in %.2f s", job, "+".join(result["sections"]), time.perf_counter() - t0)
        done[task.method] = True
    return done
