"""The ``phiscene`` command: run single stages outside Snakemake.

    phiscene ground SCENE_DIR OUT_DIR [--topology geometric|height|given] [--suite real] [--config config/config.yaml]
    phiscene metrics SCENE_JSON [--proxies P.npz | --suite real] [--config ...]
    phiscene bench OUT_DIR [--suite contact] [--index 0] [--config ...]
    phiscene failures [RESULTS_DIR] [--why]
    phiscene import-sam3d IN_DIR OUT_DIR [--floor NX NY NZ D] [--unit-scale 1] [--no-walls]
    phiscene import-placed MESH_DIR|SCENE.glb OUT_DIR [--objects files|nodes] [--up y|z|-y|...] [--placements P.json]
                           [--camera C.json] [--unit-scale 1] [--no-level] [--no-walls]
    phiscene import-rest3d ROOT SCENE OUT_DIR [--variant sam3d|ours|dc|gen3dsr|sg] [--no-level] [--no-walls]
    phiscene import-front3d ROOT OUT_DIR [--room SCENE_ID ...] [--test-rooms 1000] [--initial PATTERN]
    phiscene export SCENE_JSON OUT_DIR [--proxies P.npz] [--topology T.json] [--suite real] [--no-check] [--demo]

Settings come from a workflow config file (``--config``; default ``config/config.yaml`` if present in the
working directory, else the workflow's default config as shipped with the package, :func:`phiscene.config.
packaged_config_path`, so that ``phiscene ground`` run anywhere grounds as the workflow's ``phi_scene`` does).
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

from phiscene.errors import PhisceneError

log = logging.getLogger("phiscene")


def _config(paths: list[str] | None, bench_suite: str | None = None) -> dict:
    """The config of ``--config`` (given more than once: each file deep-merged over the ones before, as Snakemake's
    ``--configfile`` over the workflow's config), its plugins loaded and the sections the stages read checked
    (with ``bench_suite``, also that suite's benchmark settings, :func:`_bench_settings`).

    Raises
    ------
    PhisceneError
        A file is missing or not YAML, a plugin does not import, or a setting is bad: one line naming the file(s)
        and the setting's config path.
    """
    import yaml

    from phiscene.config import ConfigError, check_stage_config, deep_merge
    from phiscene.plugins import load_plugins

    files = [Path(p) for p in paths] if paths else [Path("config/config.yaml")]
    shipped = False
    if not paths and not files[0].is_file():
        from phiscene.config import packaged_config_path

        files, shipped = [packaged_config_path()], True
        if not files[0].is_file():
            raise PhisceneError(f"no config/config.yaml in {Path.cwd()} and none shipped with phiscene ({files[0]}): "
                                "pass --config FILE")
        print(f"phiscene: no config/config.yaml in {Path.cwd()}; using the default config shipped with phiscene "
              f"({files[0]}; --config FILE for another)", file=sys.stderr)
    cfg: dict = {}
    for p in files:
        if not p.is_file():
            raise PhisceneError(f"{p}: config file not found")
        try:
            data = yaml.safe_load(p.read_text()) or {}
        except yaml.YAMLError as exc:
            raise PhisceneError(f"{p}: not valid YAML ({str(exc).splitlines()[0]})") from None
        if not isinstance(data, dict):
            raise PhisceneError(f"{p}: not a config (a YAML mapping of sections), got {type(data).__name__}")
        cfg = deep_merge(cfg, data)
    if shipped:
        cfg.pop("cache_dir", None)  # the workflow's results/cache, relative to a repository: beside the outputs here
    label = " + ".join(map(str, files))
    load_plugins(cfg.get("plugins") or [])  # a PluginError names the module
    try:
        check_stage_config(cfg)
        if bench_suite is not None:
            _check_bench(cfg, bench_suite)
    except ConfigError as exc:
        hint = ("; an override file goes after the config it overrides: --config config/config.yaml --config FILE"
                if len(files) == 1 and "no proxy profile" in str(exc) else "")
        raise PhisceneError(f"{label}: {exc}{hint}") from None
    return cfg


def _check_bench(cfg: dict, suite: str) -> None:
    """The benchmark settings ``phiscene bench --suite`` builds with: ``benchmark``, then the suite's merged over it
    and completed by its generator's defaults (``ConfigError`` naming the setting; an unknown suite or one that no
    generator builds is left to :func:`cmd_bench`)."""
    from phiscene.bench.build import TEMPLATES, BenchParams
    from phiscene.config import check_params, check_suite_benchmark

    check_params(BenchParams, cfg.get("benchmark"), "benchmark")
    spec = (cfg.get("suites") or {}).get(suite)
    if isinstance(spec, dict) and "source" not in spec and spec.get("generator", suite) in TEMPLATES:
        check_suite_benchmark(cfg, suite)


def _known_suite(cfg: dict, suite: str) -> None:
    """Raise a one-line error when ``suite`` is not a suite of the config."""
    suites = cfg.get("suites") or {}
    if suite not in suites:
        raise PhisceneError(f"--suite {suite!r}: not a suite of the config ({', '.join(sorted(suites)) or 'none'})")


def _bench_settings(cfg: dict, suite: str) -> dict:
    """The benchmark settings of ``suite``, deep-merged as the workflow's ``benchmark`` rule merges them."""
    from phiscene.config import bench_settings

    _known_suite(cfg, suite)
    return bench_settings(cfg, suite)


def _proxy_settings(cfg: dict, suite: str | None, profile: str | None = None) -> dict:
    """The config's proxy settings: with ``suite``, that suite's (its profile and override, as the workflow uses
    them); with ``profile``, the named ``proxy_profiles`` entry over the global section."""
    from phiscene.config import ConfigError, proxy_profile, suite_proxies

    if profile is not None:
        try:
            return proxy_profile(cfg, profile, "--proxy-profile")
        except ConfigError as exc:
            raise PhisceneError(str(exc).removeprefix("config: ")) from None
    if suite is not None:
        _known_suite(cfg, suite)
    return suite_proxies(cfg, suite)


#: A scene whose median mesh has more faces than this is a reconstruction (SAM 3D Objects writes about 30,000 per
#: object; the embedded benchmark's clean meshes a few hundred): :func:`cmd_ground` names the suites whose lighter
#: proxy settings are made for such meshes when none is given.
RECONSTRUCTION_FACES = 10_000


def _reconstruction_hint(cfg: dict, scene_path: Path) -> str | None:
    """A note for ``phiscene ground`` without ``--suite`` on a scene of reconstructed meshes: the config's suites
    of real data with proxy settings of their own (a ``proxy_profile`` or a ``proxies`` override: the ``real``
    suite's lighter CoACD search), or ``None``."""
    import numpy as np

    from phiscene.scene import load_scene

    suites = {name: s.get("proxy_profile") for name, s in (cfg.get("suites") or {}).items()
              if "source" in s and ("proxies" in s or "proxy_profile" in s)}
    if not suites:
        return None
    faces = float(np.median([len(o.mesh().faces) for o in load_scene(scene_path).objects]))
    if faces <= RECONSTRUCTION_FACES:
        return None
    suite, profile = next(iter(suites.items()))
    option = f"--proxy-profile {profile} (or --suite {suite})" if profile else f"--suite {suite}"
    return (f"note: {scene_path}: its meshes are reconstructions (median {faces:,.0f} faces), decomposed with the "
            f"config's global proxy settings; {option} takes the lighter CoACD search made for them "
            f"(README 'The phiscene command')")


def _scene_file(path: Path) -> Path:
    return path / "scene.json" if path.is_dir() else path


def cmd_ground(args: argparse.Namespace) -> None:
    import time

    from phiscene import pipeline

    cfg = _config(args.config)
    scene = _scene_file(Path(args.scene_dir))
    out = Path(args.out_dir)
    if out.resolve() == scene.parent.resolve():
        raise PhisceneError(f"{out}: the output folder is the input scene's folder (grounding would write its "
                            "scene.json over the input); pass another folder")
    cache = Path(args.cache_dir or cfg.get("cache_dir", out / "cache"))
    methods = cfg.get("methods") or {}
    notes: list[str] = []
    if args.method == "phi_scene" and "phi_scene" not in methods:  # a config without it: its assembly section
        assembly, backend = cfg.get("assembly", {}), args.topology or "geometric"
        if not (assembly.get("faithful") or {}).get("enabled", False):
            notes.append("note: the config has no methods.phi_scene: grounding with its assembly section, which "
                         "leaves faithful grounding off (the paper's loop); pass the workflow's config/config.yaml "
                         "first and yours second (--config config/config.yaml --config FILE) to change only what "
                         "yours sets")
    elif args.method not in methods or methods[args.method].get("kind") != "phi_scene":
        names = sorted(k for k, v in methods.items() if v.get("kind") == "phi_scene")
        raise PhisceneError(f"--method {args.method!r}: not a phi_scene-kind method of the config ({', '.join(names)})")
    else:
        from phiscene.config import method_assembly

        assembly = method_assembly(cfg, args.method)
        backend = args.topology or methods[args.method].get("topology", "geometric")
    proxy_settings = _proxy_settings(cfg, args.suite, args.proxy_profile)
    hint = None if args.suite is not None or args.proxy_profile else _reconstruction_hint(cfg, scene)
    for note in notes:  # with the progress lines: stderr holds only the one line of an error
        print(note, flush=True)
    if hint:
        print(hint, file=sys.stderr, flush=True)
    given = Path(args.given) if args.given else scene.parent.parent / "gt" / "topology.json"
    if backend == "given" and not given.is_file():
        raise PhisceneError(f"{given}: topology file not found (pass --given FILE)")
    camera = Path(args.camera) if args.camera else scene.parent.parent / "reference" / "camera.json"
    if args.camera and not camera.is_file():
        raise PhisceneError(f"{camera}: camera file not found")
    topo = cfg.get("topology", {})
    stages = [
        ("proxies", lambda: pipeline.run_proxies(scene, out / "proxies.npz", proxy_settings, cache,
                                                 progress=lambda msg: print(f"      {msg}", flush=True))),
        (f"topology ({backend})", lambda: pipeline.run_topology(
            scene, out / "topology.json", backend, topo.get(backend, {}), given_path=given if backend == "given"
            else None, attached=topo.get("attached", {}), cache_dir=cache)),
        ("grounding", lambda: pipeline.run_ground(
            scene, out / "topology.json", out / "proxies.npz", out / "scene.json", out / "assembly.json",
            assembly, cfg.get("sim", {}), cache,
            progress=lambda msg: print(f"      {msg}", flush=True), camera_path=camera if camera.is_file() else None)),
    ]
    total = time.perf_counter()
    for k, (name, run) in enumerate(stages):
        print(f"[{k + 1}/{len(stages)}] {name} of {scene}", flush=True)
        t0 = time.perf_counter()
        run()
        print(f"      {name}: {time.perf_counter() - t0:.2f} s", flush=True)
    print(f"wrote {out / 'scene.json'} and {out / 'assembly.json'} ({time.perf_counter() - total:.2f} s in all)")


def cmd_metrics(args: argparse.Namespace) -> None:
    import tempfile

    from phiscene import pipeline
    from phiscene.metrics.evaluate import MetricInputs, scene_metrics

    cfg = _config(args.config)
    scene = _scene_file(Path(args.scene))
    cache = Path(args.cache_dir or cfg.get("cache_dir", Path(tempfile.gettempdir()) / "phiscene-cache"))
    # the proxies the scene was grounded with, as `phiscene export` finds them (the workflow's metrics use those)
    given = Path(args.proxies) if args.proxies else None
    if given is None and args.suite is None and args.proxy_profile is None:
        given = _grounded_with(scene, "proxies.npz")
    with tempfile.TemporaryDirectory() as tmp:
        proxies = given or Path(tmp) / "p.npz"
        if given is None:
            pipeline.run_proxies(scene, proxies, _proxy_settings(cfg, args.suite, args.proxy_profile), cache)
        settings = {"physical": cfg.get("metrics", {}).get("physical", {}), "sim": cfg.get("sim", {})}
        result = scene_metrics(scene, ["physical"], MetricInputs(proxies=proxies, cache_dir=cache),
                               settings)["physical"]
    summary = {k: result[k] for k in ("pen_depth", "float_dist", "drift_trans", "drift_rot")}
    if given is not None and not args.proxies:  # after the work: an error stays the only line on stderr
        print(f"proxies the scene was grounded with: {given}", file=sys.stderr, flush=True)
    print(json.dumps(result if args.full else summary, indent=1))


def cmd_bench(args: argparse.Namespace) -> None:
    from phiscene.bench.build import TEMPLATES, build_scene
    from phiscene.config import ConfigError, suite_generator

    cfg = _config(args.config, bench_suite=args.suite)
    params = _bench_settings(cfg, args.suite)
    cache = Path(args.cache_dir or cfg.get("cache_dir", Path(args.out_dir) / "cache"))
    try:
        generator = suite_generator(cfg, args.suite)
    except ConfigError:
        raise PhisceneError(f"--suite {args.suite!r}: not built by an embedded benchmark generator (known: "
                            f"{', '.join(sorted(TEMPLATES))}; a suite of another name gives `generator:`)") from None
    build_scene(Path(args.out_dir), generator, args.index, params, cache)
    print(f"wrote {args.out_dir}")


def _grounded_with(scene: Path, name: str) -> Path | None:
    """The file ``name`` (``proxies.npz``, ``topology.json``) a settled scene was grounded with, or ``None``.

    Beside the scene (``phiscene ground`` writes them there), else the one its ``assembly.json`` names (key ``proxies``
    or ``topology``, written by :func:`phiscene.pipeline.run_ground`; a workflow result), if it still exists. A
    relative path there is taken as it stands (the workflow's folder), else under each folder above the scene (a
    command run from elsewhere).
    """
    beside = scene.parent / name
    if beside.is_file():
        return beside
    try:
        record = json.loads((scene.parent / "assembly.json").read_text())
    except (OSError, ValueError):
        return None
    value = record.get(name.split(".")[0]) if isinstance(record, dict) else None
    if not isinstance(value, str) or not value:
        return None
    path = Path(value)
    tries = [path] if path.is_absolute() else [path, *(d / path for d in scene.resolve().parents)]
    return next((t for t in tries if t.is_file()), None)


def cmd_export(args: argparse.Namespace) -> None:
    from phiscene import pipeline
    from phiscene.io.export import FILES, run_export

    cfg = _config(args.config)
    scene = _scene_file(Path(args.scene))
    out = Path(args.out_dir)
    cache = Path(args.cache_dir or cfg.get("cache_dir", out / ".cache"))
    # the proxies and support graph the scene was grounded with, unless others are given: beside it (as `phiscene
    # ground` writes them), else those its assembly log names (a workflow result); other proxies than the
    # grounding's can overlap where the grounding's touched, and the round trip then fails
    proxies = Path(args.proxies) if args.proxies else _grounded_with(scene, "proxies.npz")
    if proxies is not None:
        plain = args.proxies or proxies.parent == scene.parent  # given, or beside the scene
        print(f"[1/3] proxies{'' if plain else ' the scene was grounded with'}: {proxies}", flush=True)
    else:
        proxies = out / "proxies.npz"
        settings = _proxy_settings(cfg, args.suite, args.proxy_profile)
        hint = None if args.suite is not None or args.proxy_profile else _reconstruction_hint(cfg, scene)
        if hint:
            print(hint, file=sys.stderr, flush=True)
        print(f"[1/3] proxies for {scene} (not those it was grounded with: none found; --proxies names them)",
              flush=True)
        pipeline.run_proxies(scene, proxies, settings, cache, progress=lambda msg: print(f"      {msg}", flush=True))
    topology = Path(args.topology) if args.topology else _grounded_with(scene, "topology.json")
    if topology is not None:
        plain = args.topology or topology.parent == scene.parent
        print(f"[2/3] support graph{'' if plain else ' the scene was grounded with'}: {topology}", flush=True)
    else:
        topology = out / "topology.json"
        print("[2/3] support graph (geometric)", flush=True)
        pipeline.run_topology(scene, topology, "geometric", cfg.get("topology", {}).get("geometric", {}))
    print("[3/3] export (GLB, URDF, MJCF, USD, support graph)" + ("" if args.no_check else " + round-trip check"),
          flush=True)
    metrics = cfg.get("metrics", {})
    manifest = run_export(scene, proxies, out, cfg.get("sim", {}), metrics.get("mujoco", {}), topology,
                          None if args.no_check else metrics.get("physical", {}), cache)
    for name in ("glb", "urdf_index", "mjcf", "usd", "support_graph"):
        print(f"wrote {out / manifest['files'][name]}")
    if not args.no_check:
        check = json.loads((out / "roundtrip.json").read_text())
        for engine in [e for e in ("pybullet", "mujoco", "usd") if e in check]:
            c = check[engine]
            print(f"round trip {engine}: max drift difference {c['max_diff_trans'] * 1000:.3f} mm / "
                  f"{c['max_diff_rot']:.3f} deg ({'ok' if c['ok'] else 'OUTSIDE 2 mm / 1 deg'})")
    if args.demo:
        from phiscene.demo import run_demo

        summary = run_demo(out / FILES["urdf_index"], out / "demo.gif", out / "demo.json",
                           cfg.get("export", {}).get("demo", {}), cfg.get("benchmark", {}).get("render", {}))
        print(f"wrote {out / 'demo.gif'} ({summary['frames']} frames)")


def cmd_failures(args: argparse.Namespace) -> None:
    from phiscene.failures import find_failures, read_failure

    for path in find_failures(args.results):
        if args.why:
            rec = read_failure(path) or {}
            print(f"{path}: {rec.get('failed_in', '?')}: {rec.get('error', '?')}")
        else:
            print(path)


def cmd_import_sam3d(args: argparse.Namespace) -> None:
    from phiscene.io.sam3d import Sam3dParams, import_sam3d, make_floor

    floor = make_floor(args.floor[:3], args.floor[3], "--floor") if args.floor else None
    try:
        params = Sam3dParams.from_dict({"unit_scale": args.unit_scale, "walls": {"enabled": not args.no_walls}})
    except ValueError as exc:
        raise PhisceneError(f"--unit-scale: {exc}") from None
    scene = import_sam3d(args.in_dir, args.out_dir, floor, params)
    print(f"wrote {Path(args.out_dir) / 'initial' / 'scene.json'} ({len(scene)} objects, floor "
          f"{scene.meta['floor']['from']}, {scene.meta['levelling']['rotation_deg']:.2f} deg from the camera's up, "
          f"{len(scene.structure)} walls estimated; {Path(args.out_dir) / 'import.json'} has the floor, the up "
          f"estimate and the walls' evidence)")


def _report_import(scene, out_dir: str) -> None:
    lev = scene.meta.get("levelling", {})
    print(f"wrote {Path(out_dir) / 'initial' / 'scene.json'} ({len(scene)} objects, levelled by "
          f"{lev.get('rotation_deg', 0.0):.2f} deg, {len(scene.structure)} walls estimated; "
          f"{Path(out_dir) / 'import.json'} has the transform and the walls' evidence)")


def cmd_import_placed(args: argparse.Namespace) -> None:
    from phiscene.io.placed import PlacedParams, import_placed, read_placed_dir, read_scene_file
    from phiscene.io.placed_suite import read_camera

    try:
        params = PlacedParams.from_dict({"up": args.up, "unit_scale": args.unit_scale, "level": not args.no_level,
                                         "walls": {"enabled": not args.no_walls}})
    except ValueError as exc:
        raise PhisceneError(f"--unit-scale: {exc}") from None
    if Path(args.mesh_dir).is_file():
        if args.objects == "files":
            raise PhisceneError(f"{args.mesh_dir}: --objects files takes a folder of mesh files; a file given alone "
                                "is a scene file whose nodes are the objects")
        objects = read_scene_file(args.mesh_dir, args.placements)
    else:
        objects = read_placed_dir(args.mesh_dir, args.placements, args.objects or "files")
    camera = read_camera(args.camera) if args.camera else None
    scene = import_placed(objects, args.out_dir, params, camera,
                          source={"kind": "placed", "path": str(args.mesh_dir)})
    _report_import(scene, args.out_dir)


def cmd_import_rest3d(args: argparse.Namespace) -> None:
    from phiscene.io.placed import PlacedParams
    from phiscene.io.rest3d import import_rest3d

    params = PlacedParams.from_dict({"level": not args.no_level, "walls": {"enabled": not args.no_walls}})
    scene = import_rest3d(args.root, args.scene, args.out_dir, args.variant, params)
    _report_import(scene, args.out_dir)


def cmd_import_front3d(args: argparse.Namespace) -> None:
    from phiscene.io.front3d import Front3dParams, import_front3d_room, scene_id, select_rooms

    source = {"root": args.root, "test_rooms": args.test_rooms, "max_rooms": args.max_rooms, "gt": args.gt,
              "up": args.up, "initial": args.initial}
    try:
        params = Front3dParams.from_dict(source)
    except ValueError as exc:
        raise PhisceneError(str(exc)) from None
    rooms = args.room or [scene_id(r) for _, r in select_rooms(params)]
    for k, sid in enumerate(rooms):
        rec = import_front3d_room(params, sid, Path(args.out_dir) / sid)
        kept = sum(o["kept"] for o in rec["objects"])
        print(f"[{k + 1}/{len(rooms)}] {rec['room']} -> {Path(args.out_dir) / sid} ({kept} of "
              f"{len(rec['objects'])} objects)", flush=True)


def _positive_int(text: str) -> int:
    """argparse type: an integer >= 1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def build_parser() -> argparse.ArgumentParser:
    from phiscene.io import OBJECT_MODES, UP_AXES

    ap = argparse.ArgumentParser(prog="phiscene", description=__doc__.split("\n\n")[0])
    ap.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    ap.add_argument("--threads", type=_positive_int, default=1,
                    help="threads for the libraries that use them (CoACD's decomposition of cold proxies, BLAS, "
                         "torch, open3d; default 1, as every workflow job runs); the result does not depend on it")
    sub = ap.add_subparsers(dest="command", required=True)

    g = sub.add_parser("ground", help="physically ground one scene (proxies, topology, SDF + settling)")
    g.add_argument("scene_dir", help="folder with scene.json (or the scene.json itself)")
    g.add_argument("out_dir", help="output folder (scene.json, assembly.json, topology.json, proxies.npz)")
    g.add_argument("--method", default="phi_scene",
                   help="a phi_scene-kind method of the config whose assembly settings and topology backend to use "
                        "(default: phi_scene, faithful grounding; phi_scene_paper: the paper's loop)")
    g.add_argument("--topology", default=None, help="topology backend (default: the method's, else geometric)")
    g.add_argument("--given", help="topology JSON for --topology given (default: ../gt/topology.json)")
    g.add_argument("--camera", help="the photo's camera.json in the scene's frame, for the method's faithful.ray "
                                    "(default: ../reference/camera.json when it exists)")
    which = g.add_mutually_exclusive_group()
    which.add_argument("--suite", help="take the proxy settings of this suite of the config (e.g. real: the lighter "
                                       "CoACD search for 30k-face reconstructions; default: the global proxies "
                                       "section)")
    which.add_argument("--proxy-profile", metavar="NAME", help="take this proxy profile of the config over the "
                                                               "global proxies section (e.g. reconstruction)")
    g.set_defaults(func=cmd_ground)

    m = sub.add_parser("metrics", help="physical metrics of one scene")
    m.add_argument("scene", help="scene.json or its folder")
    m.add_argument("--full", action="store_true", help="print per-object values too")
    which = m.add_mutually_exclusive_group()
    which.add_argument("--proxies", help="convex proxies .npz of the scene (default: those it was grounded with, as "
                                         "export finds them, else computed with the config's settings)")
    which.add_argument("--suite", help="compute the proxies with this suite's settings (as ground --suite)")
    which.add_argument("--proxy-profile", metavar="NAME", help="compute the proxies with this proxy profile (as "
                                                               "ground --proxy-profile)")
    m.set_defaults(func=cmd_metrics)

    b = sub.add_parser("bench", help="build one embedded benchmark scene")
    b.add_argument("out_dir")
    b.add_argument("--suite", default="contact")
    b.add_argument("--index", type=int, default=0)
    b.set_defaults(func=cmd_bench)

    f = sub.add_parser("failures", help="list the failure records of scenes that failed in a workflow run")
    f.add_argument("results", nargs="?", default="results", help="results folder (default: results)")
    f.add_argument("--why", action="store_true", help="also print where each failure started and its error")
    f.set_defaults(func=cmd_failures)

    s3 = sub.add_parser("import-sam3d", help="import SAM 3D Objects outputs as OUT_DIR/initial/scene.json + "
                                             "reference/ (README: Real inputs)")
    s3.add_argument("in_dir", help="folder of per-object folders (<id>/pose.json + mesh.ply|mesh.obj|mesh.glb)")
    s3.add_argument("out_dir")
    s3.add_argument("--floor", nargs=4, type=float, metavar=("NX", "NY", "NZ", "D"),
                    help="floor plane n.p + d = 0 in the PyTorch3D camera frame (default: IN_DIR/floor.json, "
                         "else estimated: the levelling's up, the ground where the objects stand)")
    s3.add_argument("--unit-scale", type=float, default=1.0, help="multiply translations and scales (default 1)")
    s3.add_argument("--no-walls", action="store_true", help="estimate no walls from the panels hanging on them")
    s3.set_defaults(func=cmd_import_sam3d)

    pl = sub.add_parser("import-placed", help="import per-object meshes placed in one frame, levelled "
                                               "(README: Real scenes)")
    pl.add_argument("mesh_dir", help="folder with one mesh file per object (GLB/PLY/OBJ), vertices in one frame; "
                    "or one glTF/GLB scene file whose top-level nodes are the objects")
    pl.add_argument("--objects", choices=OBJECT_MODES,
                    help="in a folder: one object per file (default), or each glTF/GLB file's top-level nodes")
    pl.add_argument("out_dir")
    pl.add_argument("--up", choices=UP_AXES, default="y",
                    help="the files' axis that points up (default y, glTF's; --up=-y: OpenCV's camera frame, y down)")
    pl.add_argument("--placements", help="JSON {id: {pos, quat (w,x,y,z)} | 4x4} applied to each mesh")
    pl.add_argument("--camera", help="JSON {eye, target, fov_y_deg}: the photo's camera in the files' frame and units "
                                     "(written as reference/camera.json)")
    pl.add_argument("--unit-scale", type=float, default=1.0,
                    help="metres per source unit (default 1; 0.001 for millimetres, 0.01 for centimetres)")
    pl.add_argument("--no-level", action="store_true", help="trust the up convention (no gravity estimate)")
    pl.add_argument("--no-walls", action="store_true", help="estimate no walls from the panels hanging on them")
    pl.set_defaults(func=cmd_import_placed)

    r3 = sub.add_parser("import-rest3d", help="import one scene of the REST3D page assets (README: Real scenes)")
    r3.add_argument("root", help="a clone of the REST3D gh-pages branch (holds assets/)")
    r3.add_argument("scene", help="scene folder name, e.g. custom_viga")
    r3.add_argument("out_dir")
    r3.add_argument("--variant", choices=("sam3d", "ours", "dc", "gen3dsr", "sg"), default="sam3d",
                    help="sam3d: raw SAM 3D Objects; ours: REST3D's result; dc, gen3dsr, sg: Digital Cousins', "
                         "Gen3DSR's, SceneGen's reconstruction of the same photo (where the scene has it)")
    r3.add_argument("--no-level", action="store_true", help="trust the up convention (no gravity estimate)")
    r3.add_argument("--no-walls", action="store_true", help="estimate no walls from the panels hanging on them")
    r3.set_defaults(func=cmd_import_rest3d)

    f3 = sub.add_parser("import-front3d", help="import 3D-FRONT test rooms (MIDI-3D layout) as benchmark scenes")
    f3.add_argument("root", help="MIDI-3D's 3D-FRONT folder (midi_room_ids.json, 3D-FRONT-RENDER, ...)")
    f3.add_argument("out_dir", help="one sub-folder per room: gt/, initial/, reference/")
    f3.add_argument("--room", action="append", help="scene id of a room to import (repeatable; default: all)")
    f3.add_argument("--test-rooms", type=int, default=1000, help="the test set: the last N rooms (default 1000)")
    f3.add_argument("--max-rooms", type=int, default=0, help="only the first N test rooms (default: all)")
    f3.add_argument("--gt", default="auto", choices=["auto", "mesh", "points"])
    f3.add_argument("--up", default="y", choices=["y", "z"], help="up axis of the normalised scene frame")
    f3.add_argument("--initial", help="SAM 3D Objects output folder per room: a pattern with {scene}, {house}, "
                                      "{room} (default: the initial scene is a copy of the GT)")
    f3.set_defaults(func=cmd_import_front3d)

    e = sub.add_parser("export", help="simulation-ready export of one scene (GLB, URDF, MJCF, USD, support graph)")
    e.add_argument("scene", help="scene.json or its folder (a settled scene)")
    e.add_argument("out_dir", help="output folder")
    e.add_argument("--proxies", help="convex proxies .npz of the scene (default: proxies.npz beside the scene, as "
                                     "phiscene ground writes it, else the file its assembly.json names (a workflow "
                                     "result), else computed with the config's settings)")
    e.add_argument("--topology", help="support graph JSON (default: topology.json beside the scene, else the file "
                                      "its assembly.json names, else inferred with the geometric backend)")
    which = e.add_mutually_exclusive_group()
    which.add_argument("--suite", help="proxies computed here take this suite's settings (as ground --suite)")
    which.add_argument("--proxy-profile", metavar="NAME", help="proxies computed here take this proxy profile (as "
                                                               "ground --proxy-profile)")
    e.add_argument("--no-check", action="store_true", help="skip the round-trip release in pybullet and MuJoCo")
    e.add_argument("--demo", action="store_true", help="also throw a ball into the export: OUT_DIR/demo.gif")
    e.set_defaults(func=cmd_export)

    for p in (g, m, b, e):
        p.add_argument("--config", action="append", metavar="FILE",
                       help="workflow config YAML (default: config/config.yaml if present); again: a file merged "
                            "over it, as snakemake --configfile")
        p.add_argument("--cache-dir", help="cache folder (default: the config's cache_dir)")
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from phiscene.runner import set_threads, setup_logging

    setup_logging(level=logging.DEBUG if args.verbose else logging.WARNING)
    set_threads(args.threads)
    try:
        args.func(args)
    except PhisceneError as exc:
        print(f"phiscene: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:  # Ctrl-C: the writers are atomic, so nothing half-written is left behind
        print(f"phiscene: interrupted ({args.command})", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
