"""Build one benchmark scene: template -> simulated ground truth -> degraded initial scene -> reference render.

:func:`build_scene` is the entry point of the Snakemake benchmark rule. It is a
deterministic function of its arguments (same params -> byte-identical files on
the same machine) and writes its output folder atomically: everything is built
in a temporary sibling folder that is renamed to ``out_dir`` at the end.

Output layout::

    out_dir/meshes/obj_XX.glb           local-frame meshes (shared by gt and initial)
    out_dir/gt/scene.json               ground truth at rest
    out_dir/gt/topology.json            GT support graph (backend "gt"; walls as ``structure`` nodes)
    out_dir/initial/scene.json          degraded scene
    out_dir/reference/image.png         RGB render of the GT scene
    out_dir/reference/segmentation.png  instance colours (= objects' "color"), black background
    out_dir/reference/camera.json       camera (see phiscene.render)
"""

from __future__ import annotations

import hashlib
import logging
import os
import shutil
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from phiscene import schemas
from phiscene.atomic import write_json
from phiscene.bench import clutter, rooms  # noqa: F401  (register the rooms and clutter suites)
from phiscene.bench.assets import ASSET_VERSION, asset_library
from phiscene.bench.degrade import DegradeParams, degrade_scene
from phiscene.bench.foundation import foundation_scene
from phiscene.bench.groundtruth import GroundTruth, GTParams, ground_truth
from phiscene.bench.templates import (
    GROUND,
    LIBRARIES,
    SUITE_DEFAULTS,
    TEMPLATES,
    Placement,
    TemplateError,
    TemplateParams,
    template_names,
)
from phiscene.meshes import save_mesh
from phiscene.params import Params
from phiscene.proxies import ProxyParams
from phiscene.render import (
    RenderParams,
    camera_elevation,
    camera_for,
    hidden_objects,
    instance_labels,
    labels_to_colors,
    raised_cameras,
    render,
    save_png,
    segmentation_colors,
)
from phiscene.scene import Scene, SceneObject, save_scene
from phiscene.sim.settings import SimSettings

log = logging.getLogger(__name__)

#: Bump when the benchmark generator changes in a way that changes its output.
BENCH_VERSION = 1

#: Start of an attempt's problem when it was at rest but the reference camera did not see every object
#: (:func:`build_scene` retries those from raised views).
HIDDEN = "hidden in the"


@dataclass(frozen=True)
class BenchParams(Params):
    """The ``benchmark`` config section, parsed.

    Attributes
    ----------
    seed
        Benchmark seed (scene seeds derive from it, the suite and the scene index).
    n_assets
        Size of the asset library (>= 16 holds every category).
    n_objects
        Inclusive range of objects per scene.
    templates
        Templates to cycle through (scene ``index`` uses ``templates[index % len]``); empty = all of the suite.
    max_attempts
        Scenes resampled at most this often before giving up.
    template, gt, degrade, render, sim, proxies
        Sections for :class:`TemplateParams`, :class:`GTParams`, :class:`DegradeParams`,
        :class:`RenderParams`, :class:`SimSettings`, :class:`ProxyParams`.
    """

    _label = "benchmark parameters"
    _coerce = {"n_objects": lambda v: tuple(int(x) for x in v), "templates": lambda v: tuple(v or ())}

    seed: int = 0
    n_assets: int = 48
    n_objects: tuple[int, int] = (3, 8)
    templates: tuple[str, ...] = ()
    max_attempts: int = 25
    template: TemplateParams = field(default_factory=TemplateParams)
    gt: GTParams = field(default_factory=GTParams)
    degrade: DegradeParams = field(default_factory=DegradeParams)
    render: RenderParams = field(default_factory=RenderParams)
    sim: SimSettings = field(default_factory=SimSettings)
    proxies: ProxyParams = field(default_factory=ProxyParams)

    def check(self) -> None:
        """Reject an ``n_objects`` that is not ``[min, max]`` with ``1 <= min <= max`` (``ValueError``)."""
        if len(self.n_objects) != 2 or not 1 <= self.n_objects[0] <= self.n_objects[1]:
            raise ValueError("benchmark n_objects must be [min, max] with 1 <= min <= max, got "
                             f"{list(self.n_objects)}")


def default_params() -> dict:
    """The default ``benchmark`` config section as plain data (what config.yaml carries)."""
    from dataclasses import asdict

    p = BenchParams()
    out = asdict(p)
    out["n_objects"] = list(p.n_objects)
    out["templates"] = list(p.templates)
    out["render"]["light_direction"] = list(p.render.light_direction)
    for key in ("axis_scale", "scale"):
        out["degrade"]["foundation"][key] = list(getattr(p.degrade.foundation, key))
    return out


def with_suite_defaults(suite: str, params: dict | None) -> dict:
    """``params`` over the suite's :data:`~phiscene.bench.templates.SUITE_DEFAULTS`, section by section.

    A key missing from ``params`` takes the suite default; a section (``template``, ``degrade``, ...)
    given in ``params`` is completed key by key from the suite default's section. Suites without
    defaults (``contact``) get ``params`` unchanged.
    """
    params = dict(params or {})
    out = dict(SUITE_DEFAULTS.get(suite, {}))
    for key, value in params.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = {**out[key], **value}
        else:
            out[key] = value
    return out


def scene_seed(seed: int, suite: str, index: int) -> int:
    """Stable 63-bit seed of scene ``index`` of ``suite`` (SHA-256, independent of Python's ``hash``)."""
    digest = hashlib.sha256(f"phiscene.bench/{BENCH_VERSION}/{seed}/{suite}/{index}".encode()).digest()
    return int.from_bytes(digest[:8], "little") >> 1


def object_ids(n: int) -> list[str]:
    """``obj_01`` ... ``obj_NN``."""
    return [f"obj_{k + 1:02d}" for k in range(n)]


def _write_meshes(placements: list[Placement], order: np.ndarray, mesh_dir: Path) -> Scene:
    """Save the placements' meshes as ``obj_XX.glb`` (ids in shuffled ``order``) and return the scene.

    The scene's ``structure`` is the placements' (a :class:`~phiscene.bench.templates.Layout`), or empty.
    """
    ids = object_ids(len(placements))
    colors = segmentation_colors(len(placements))
    id_of = {int(k): ids[j] for j, k in enumerate(order)}
    objects = []
    for j, k in enumerate(order):
        pl = placements[int(k)]
        path = save_mesh(pl.asset.mesh, mesh_dir / f"{ids[j]}.glb")
        intended = sorted("ground" if s == GROUND else s if isinstance(s, str) else id_of[s] for s in pl.supporters)
        objects.append(SceneObject(id=ids[j], mesh_path=path.resolve(), pose=np.array(pl.pose, dtype=float),
                                   description=pl.asset.description, color=colors[j],
                                   meta={"asset": pl.asset.name, "category": pl.asset.category,
                                         "rgb": [int(c) for c in pl.asset.rgb], "role": pl.role,
                                         "intended_supporters": intended}, attached=pl.attached))
    return Scene(objects=objects, ground_height=0.0, structure=list(getattr(placements, "structure", [])))


def _attempt(suite: str, template: str, n_objects: int, library: tuple, rng: np.random.Generator,
             p: BenchParams, mesh_dir: Path, cache_dir: Path, raised: bool = False
             ) -> tuple[GroundTruth | None, str | None, dict | None, tuple | None]:
    """One sampled, simulated and photographed scene, and what is wrong with it (``None``: accepted).

    The reference camera is the configured one; with ``raised``, the cameras of
    :func:`~phiscene.render.raised_cameras` instead, the first from which no object is hidden.
    """
    try:
        placements = TEMPLATES[suite][template](library, n_objects, rng, p.template)
    except TemplateError as exc:
        return None, f"template: {exc}", None, None
    order = rng.permutation(len(placements))
    if mesh_dir.exists():
        shutil.rmtree(mesh_dir)
    scene = _write_meshes(placements, order, mesh_dir)
    intended = {o.id: set(o.meta["intended_supporters"]) for o in scene.objects}
    gt = ground_truth(scene, p.sim, p.proxies, cache_dir, p.gt, intended)
    if gt.problem:
        return gt, gt.problem, None, None
    cameras = raised_cameras(gt.scene, p.render) if raised else [camera_for(gt.scene, p.render)]
    if not cameras:
        return gt, f"no raised view (the configured elevation is already {p.render.elevation_deg:g} deg)", None, None
    for camera in cameras:
        labels = instance_labels(gt.scene, camera)
        hidden = hidden_objects(gt.scene, labels, p.render.min_visible_pixels)
        if not hidden:
            break
    if hidden:
        view = "raised reference views" if raised else "reference view"
        return gt, f"{HIDDEN} {view}: {', '.join(hidden)} (< {p.render.min_visible_pixels} px)", None, None
    rgb = render(gt.scene, camera, shadow=p.render.shadow, light_direction=p.render.light_direction)
    return gt, None, camera, (rgb, labels)


def build_scene(out_dir: Path, suite: str, index: int, params: dict, cache_dir: Path) -> None:
    """Build scene ``index`` of benchmark ``suite`` into ``out_dir`` (replaced atomically).

    Parameters
    ----------
    out_dir
        Scene folder to create (e.g. ``results/scenes/contact/scene_000``).
    suite
        Benchmark suite (a key of :data:`phiscene.bench.templates.TEMPLATES`, e.g. ``contact``).
    index
        Scene number within the suite (>= 0); picks the template and, with the seed, all random choices.
    params
        The ``benchmark`` config section (see :class:`BenchParams`; missing keys take the suite's
        defaults (:func:`with_suite_defaults`), then the global ones).
    cache_dir
        Shared cache folder (collision proxies, hull OBJ files).

    Raises
    ------
    ValueError
        Unknown parameters or suite.
    RuntimeError
        No accepted scene within ``max_attempts`` (the message lists each attempt's reason).
    """
    t_start = time.perf_counter()
    p = BenchParams.from_dict(with_suite_defaults(suite, params))
    out_dir, cache_dir = Path(out_dir), Path(cache_dir)
    names = list(p.templates) or template_names(suite)
    unknown = sorted(set(names) - set(template_names(suite)))
    if unknown:
        raise ValueError(f"unknown templates {unknown} for suite {suite!r}; known: {template_names(suite)}")
    if index < 0:
        raise ValueError(f"scene index must be >= 0, got {index}")
    template = names[index % len(names)]
    sseed = scene_seed(p.seed, suite, index)
    n_objects = int(np.random.default_rng([sseed, 0]).integers(p.n_objects[0], p.n_objects[1] + 1))
    library = LIBRARIES.get(suite, asset_library)(p.seed, p.n_assets, cache_dir)

    out_dir.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.", dir=out_dir.parent))
    try:
        reasons, hidden_only = [], []
        for attempt in range(p.max_attempts):
            rng = np.random.default_rng([sseed, 1, attempt])
            gt, problem, camera, images = _attempt(suite, template, n_objects, library, rng, p, tmp / "meshes",
                                                   cache_dir)
            if problem is None:
                break
            reasons.append(f"attempt {attempt}: {problem}")
            log.info("%s/%d: %s", suite, index, reasons[-1])
            if problem.startswith(HIDDEN):
                hidden_only.append(attempt)
        else:
            # last resort, so that every scene a seed builds from the configured view stays as it is: the attempts
            # that were stable but hid an object from the configured camera, again, seen from higher up
            for attempt in hidden_only:
                rng = np.random.default_rng([sseed, 1, attempt])
                gt, problem, camera, images = _attempt(suite, template, n_objects, library, rng, p,
                                                       tmp / "meshes", cache_dir, raised=True)
                if problem is None:
                    log.info("%s/%d: attempt %d taken from a raised view (elevation %.0f deg)", suite, index,
                             attempt, camera_elevation(camera))
                    break
                reasons.append(f"attempt {attempt} again: {problem}")
            else:
                raise RuntimeError(f"benchmark scene {suite}/{index} ({template}): no stable scene in "
                                   f"{p.max_attempts} attempts:\n  " + "\n  ".join(reasons))
        _write_outputs(tmp, gt, camera, images, p, suite, index, template, sseed, attempt)
        _replace_dir(tmp, out_dir)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp)
    log.info("%s/%d (%s, %d objects, attempt %d) built in %.2f s", suite, index, template, n_objects, attempt,
             time.perf_counter() - t_start)


def _write_outputs(root: Path, gt: GroundTruth, camera: dict, images: tuple, p: BenchParams, suite: str,
                   index: int, template: str, sseed: int, attempt: int) -> None:
    rgb, labels = images
    camera_path = root / "reference" / "camera.json"
    meta = {"suite": suite, "index": index, "template": template, "seed": sseed, "benchmark_seed": p.seed,
            "attempt": attempt, "generator": f"phiscene.bench/{BENCH_VERSION} assets/{ASSET_VERSION}"}
    gt_scene = gt.scene
    gt_scene.camera = camera_path
    gt_scene.meta = {**meta, "state": "gt", "settle_frames": gt.settle_frames,
                     "max_drift_m": max(gt.drift_m.values()), "max_drift_deg": max(gt.drift_deg.values())}
    if p.degrade.kind == "foundation":  # reconstructed meshes, camera-ray errors, levelled from a tilted frame
        made = foundation_scene(gt_scene, camera, labels, p.degrade.foundation, [sseed, 2], root / "initial" / "meshes")
        initial = made.initial
        made.camera_frame.meta = {**meta, **made.camera_frame.meta}
        save_scene(made.camera_frame, root / "initial" / "camera_frame.json")
    else:
        initial = degrade_scene(gt_scene, p.degrade, [sseed, 2])
    initial.meta = {**meta, **initial.meta}
    for o in initial.objects:  # the initial scene must not reveal the template's support intent
        o.meta = {k: v for k, v in o.meta.items() if k not in ("role", "intended_supporters")}
    colors = [o.color for o in gt_scene.objects]
    write_json(camera_path, camera)
    save_png(rgb, root / "reference" / "image.png")
    save_png(labels_to_colors(labels, colors), root / "reference" / "segmentation.png")
    topology = {"format": "phiscene.topology/1", "backend": "gt", "objects": ["ground", *gt_scene.ids],
                "edges": gt.edges, "order": [], "dropped_edges": []}
    if gt_scene.structure:  # walls as supporter nodes (phiscene.topology.graph)
        topology["structure"] = [p.id for p in gt_scene.structure]
    topo_path = root / "gt" / "topology.json"
    schemas.validate(topology, "topology", topo_path)
    write_json(topo_path, topology)
    save_scene(initial, root / "initial" / "scene.json")
    save_scene(gt_scene, root / "gt" / "scene.json")


def _replace_dir(src: Path, dst: Path) -> None:
    """Rename folder ``src`` to ``dst``, replacing an existing ``dst``."""
    if dst.exists():
        trash = Path(tempfile.mkdtemp(prefix=f".{dst.name}.old.", dir=dst.parent))
        os.replace(dst, trash / dst.name)
        os.replace(src, dst)
        shutil.rmtree(trash)
    else:
        os.replace(src, dst)
