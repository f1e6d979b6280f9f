"""File-level stage functions: path in, path out.

Workflow scripts and the ``phiscene`` command call these; each loads its
inputs (validating them), calls the computing function of its module and
writes its outputs atomically.
"""

from __future__ import annotations

import functools
import logging
from collections.abc import Callable
from pathlib import Path

from phiscene.atomic import write_json
from phiscene.proxies import ProxyParams, proxy_for_mesh, read_proxies, write_proxies
from phiscene.scene import load_scene, save_scene
from phiscene.sim.settings import SimSettings
from phiscene.solid import use_disk_cache

log = logging.getLogger(__name__)


def run_proxies(scene_path: str | Path, out_path: str | Path, params: dict, cache_dir: str | Path,
                progress: Callable[[str], None] | None = None) -> None:
    """Convex proxies of every object of a scene -> one ``.npz`` keyed by object id.

    ``progress`` gets one line per object as it is done (default: the log): a cold decomposition of a 30k-face
    reconstruction takes seconds to minutes an object.
    """
    use_disk_cache(cache_dir)
    scene = load_scene(scene_path)
    pp = ProxyParams.from_dict(params)
    proxies = {}
    for k, o in enumerate(scene.objects):
        px = proxies[o.id] = proxy_for_mesh(o.mesh_path, pp, cache_dir)
        n = len(px.hulls)
        (progress or log.info)(f"({k + 1}/{len(scene.objects)}) {o.id}: {n} hull{'' if n == 1 else 's'}, volume ratio "
                               f"{px.volume_ratio:.3f}, max outside {px.max_outside:.4f} m, excess {px.excess:.4f} m, "
                               f"{px.seconds:.2f} s")
    write_proxies(out_path, proxies)


def run_reference(scene_path: str | Path, out_path: str | Path) -> None:
    """A reference method row (gt, initial): the scene itself, re-rooted at ``out_path``."""
    save_scene(load_scene(scene_path), out_path)


def run_topology(scene_path: str | Path, out_path: str | Path, backend: str, params: dict,
                 given_path: str | Path | None = None, attached: dict | None = None,
                 cache_dir: str | Path | None = None) -> None:
    """Support graph and placement order of a scene with the named backend (and the attachment decision).

    ``cache_dir``: where the outer shells of its meshes (:func:`phiscene.solid.use_disk_cache`), which the
    geometric backend samples, are kept between jobs (the proxies' job makes the same ones)."""
    from phiscene import topology

    if cache_dir is not None:
        use_disk_cache(cache_dir)
    scene = load_scene(scene_path)
    graph = topology.infer(scene, backend, params, given_path=given_path, attached=attached)
    topology.save(graph, out_path)
    log.info("%s: %d edges, order %s, dropped %d", backend, len(graph.edges), " ".join(graph.order),
             len(graph.dropped_edges))


def run_ground(scene_path: str | Path, topology_path: str | Path, proxies_path: str | Path,
               out_scene: str | Path, out_log: str | Path, assembly: dict, sim: dict, cache_dir: str | Path,
               progress: Callable[[str], None] | None = None, camera_path: str | Path | None = None) -> None:
    """phi-Scene grounding of one scene in its topology's order.

    ``camera_path`` is the photo's ``camera.json`` in the scene's frame, for the faithful variant's ``ray``
    remedy (:func:`~phiscene.assembly.starts.ray_corrected`) and its ``hidden`` remedy (the share of each
    object the camera sees in the input, :func:`~phiscene.render.visible_shares`); without one both are skipped
    (``ray`` logged).
    """
    from phiscene import topology
    from phiscene.assembly.assemble import AssemblyParams, ground_scene
    from phiscene.assembly.outcome import outcome_line
    from phiscene.render import camera_eye, read_camera, visible_shares
    from phiscene.topology.attached import attached_ids

    use_disk_cache(cache_dir)
    scene = load_scene(scene_path)
    graph = topology.load(topology_path, scene_ids=scene.ids)
    proxies = read_proxies(proxies_path)
    fixed = dict(attached_ids(graph, holders=True))
    fixed.update({o.id: o.attached for o in scene.objects if o.attached is not None})
    params = AssemblyParams.from_dict(assembly)
    camera = read_camera(camera_path) if camera_path is not None else None
    eye = camera_eye(camera) if camera is not None else None
    if eye is None and params.faithful.enabled and params.faithful.ray:
        log.warning("%s: faithful.ray needs the photo's camera (none given): closing gaps straight down", scene_path)
    visible = None  # computed only if an object reaches the remedy hidden
    if camera is not None and params.faithful.enabled and params.faithful.hidden_share > 0:
        visible = functools.partial(visible_shares, scene, camera)
    settled, record = ground_scene(scene, graph.order, proxies, params, SimSettings.from_dict(sim), Path(cache_dir),
                                   progress=progress or log.info, graph=graph, attached=fixed, eye=eye,
                                   visible=visible)
    # what it was grounded with, for `phiscene export` (its round trip tests the scene against these contacts)
    record["topology"] = str(topology_path)
    record["proxies"] = str(proxies_path)
    line = outcome_line(settled, scene, record)  # before the outputs: nothing may fail once they are written
    write_json(out_log, record)
    save_scene(settled, out_scene)
    (progress or log.info)(line)


def run_baseline(kind: str, scene_path: str | Path, out_scene: str | Path, out_log: str | Path, params: dict,
                 sim: dict, cache_dir: str | Path, proxies_path: str | Path | None = None,
                 topology_path: str | Path | None = None) -> None:
    """A registered baseline (:mod:`phiscene.baselines.registry`; the paper's Tab. 6 ones) on one initial scene.

    Parameters
    ----------
    kind
        Registered baseline kind (``joint_sdf``, ``joint_sim``, ``joint_sdf_sim``, ``lift_sim``, ...).
    params
        The baseline's parameter mapping (its class' ``from_dict``).
    proxies_path, topology_path
        The scene's proxies and support graph, for the kinds that need them.
    """
    from phiscene import topology
    from phiscene.baselines.registry import BaselineInputs, get_baseline

    baseline = get_baseline(kind)
    paths = {"proxies": proxies_path, "topology": topology_path}
    missing = [n for n in baseline.needs if paths[n] is None]
    if missing:
        raise ValueError(f"baseline {kind} needs {' and '.join(missing)}")
    scene = load_scene(scene_path)
    inputs = BaselineInputs(
        scene, SimSettings.from_dict(sim), Path(cache_dir),
        proxies=read_proxies(proxies_path) if "proxies" in baseline.needs else None,
        graph=topology.load(topology_path, scene_ids=scene.ids) if "topology" in baseline.needs else None)
    out, record = baseline.run(inputs, baseline.params.from_dict(params))
    write_json(out_log, record)
    save_scene(out, out_scene)


def run_external(pred_dir: str | Path, initial_path: str | Path, out_scene: str | Path, out_log: str | Path,
                 params: dict) -> None:
    """Import another method's prediction of one scene (meshes, poses.json or a GLB scene) as a method row."""
    from phiscene.baselines import ImportParams, import_external

    _, record = import_external(pred_dir, initial_path, out_scene, ImportParams.from_dict(params))
    write_json(out_log, record)


def run_metrics(tasks: list[dict], settings: dict, proxies_path: str | Path | None = None,
                gt_path: str | Path | None = None, initial_path: str | Path | None = None,
                reference_dir: str | Path | None = None, cache_dir: str | Path | None = None,
                name: str = "metrics") -> dict:
    """Metrics files of one scene's methods (:func:`phiscene.metrics.evaluate.methods_metrics`).

    Parameters
    ----------
    tasks
        Per method: ``method``, ``scene`` (its ``scene.json``), ``out`` (the metrics JSON to write),
        ``sections`` and optionally ``proxies`` (its own) and ``align`` (its scenes are in their own frame).
    settings
        Parameter mappings by name (``physical``, ``sim``, ``mujoco``, ``alignment``, ``recon``).
    proxies_path, gt_path, initial_path, reference_dir, cache_dir
        The shared inputs the sections need (:func:`phiscene.metrics.evaluate.required_inputs`).
    name
        Job name for the log and failure records.

    Returns
    -------
    dict
        Method -> whether its metrics (``True``) or a failure record (``False``) was written.
    """
    from phiscene.metrics.evaluate import MetricInputs, MetricTask, methods_metrics

    use_disk_cache(cache_dir)
    inputs = MetricInputs(proxies=proxies_path, gt=gt_path, initial=initial_path, reference_dir=reference_dir,
                          cache_dir=cache_dir)
    todo = [MetricTask(t["method"], t["scene"], t["out"], tuple(t["sections"]), t.get("proxies"), t.get("align", False))
            for t in tasks]
    return methods_metrics(todo, inputs, settings, name)
