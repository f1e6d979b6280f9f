"""The ``phiscene`` command: run single stages outside Snakemake.

    phiscene ground SCENE_DIR OUT_DIR [--topology geometric|height|given] [--config config/config.yaml]
    phiscene metrics SCENE_JSON [--config ...]
    phiscene bench OUT_DIR [--suite contact] [--index 0] [--config ...]

Settings come from a workflow config file (``--config``; default
``config/config.yaml`` if present in the working directory, else built-in defaults).
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

from phiscene.errors import PhisceneError

log = logging.getLogger("phiscene")


def _config(path: str | None) -> dict:
    import yaml

    p = Path(path) if path else Path("config/config.yaml")
    if not p.is_file():
        if path:
            raise PhisceneError(f"{p}: config file not found")
        return {}
    try:
        return yaml.safe_load(p.read_text()) or {}
    except yaml.YAMLError as exc:
        raise PhisceneError(f"{p}: not valid YAML ({str(exc).splitlines()[0]})") from None


def _scene_file(path: Path) -> Path:
    return path / "scene.json" if path.is_dir() else path


def cmd_ground(args: argparse.Namespace) -> None:
    from phiscene import pipeline

    cfg = _config(args.config)
    scene = _scene_file(Path(args.scene_dir))
    out = Path(args.out_dir)
    cache = Path(args.cache_dir or cfg.get("cache_dir", out / "cache"))
    backend = args.topology
    given = Path(args.given) if args.given else scene.parent.parent / "gt" / "topology.json"
    if backend == "given" and not given.is_file():
        raise PhisceneError(f"{given}: topology file not found (pass --given FILE)")
    print(f"[1/3] proxies for {scene}", flush=True)
    pipeline.run_proxies(scene, out / "proxies.npz", cfg.get("proxies", {}), cache)
    print(f"[2/3] topology ({backend})", flush=True)
    pipeline.run_topology(scene, out / "topology.json", backend, cfg.get("topology", {}).get(backend, {}),
                          given_path=given if backend == "given" else None)
    print("[3/3] grounding", flush=True)
    pipeline.run_ground(scene, out / "topology.json", out / "proxies.npz", out / "scene.json", out / "assembly.json",
                        cfg.get("assembly", {}), cfg.get("sim", {}), cache,
                        progress=lambda msg: print(f"      {msg}", flush=True))
    print(f"wrote {out / 'scene.json'} and {out / 'assembly.json'}")


def cmd_metrics(args: argparse.Namespace) -> None:
    import tempfile

    from phiscene import pipeline

    cfg = _config(args.config)
    scene = _scene_file(Path(args.scene))
    cache = Path(args.cache_dir or cfg.get("cache_dir", Path(tempfile.gettempdir()) / "phiscene-cache"))
    with tempfile.TemporaryDirectory() as tmp:
        pipeline.run_proxies(scene, Path(tmp) / "p.npz", cfg.get("proxies", {}), cache)
        pipeline.run_physical_metrics(scene, Path(tmp) / "p.npz", Path(tmp) / "m.json",
                                      cfg.get("metrics", {}).get("physical", {}), cfg.get("sim", {}), cache)
        result = json.loads((Path(tmp) / "m.json").read_text())
    summary = {k: result[k] for k in ("pen_depth", "float_dist", "drift_trans", "drift_rot")}
    print(json.dumps(result if args.full else summary, indent=1))


def cmd_bench(args: argparse.Namespace) -> None:
    from phiscene.bench.build import build_scene

    cfg = _config(args.config)
    params = {**cfg.get("benchmark", {}), **cfg.get("suites", {}).get(args.suite, {}).get("benchmark", {}),
              "sim": cfg.get("sim", {}), "proxies": cfg.get("proxies", {})}
    cache = Path(args.cache_dir or cfg.get("cache_dir", Path(args.out_dir) / "cache"))
    build_scene(Path(args.out_dir), args.suite, args.index, params, cache)
    print(f"wrote {args.out_dir}")


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="phiscene", description=__doc__.split("\n\n")[0])
    ap.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = ap.add_subparsers(dest="command", required=True)

    g = sub.add_parser("ground", help="physically ground one scene (proxies, topology, SDF + settling)")
    g.add_argument("scene_dir", help="folder with scene.json (or the scene.json itself)")
    g.add_argument("out_dir", help="output folder (scene.json, assembly.json, topology.json, proxies.npz)")
    g.add_argument("--topology", default="geometric", help="topology backend (default: geometric)")
    g.add_argument("--given", help="topology JSON for --topology given (default: ../gt/topology.json)")
    g.set_defaults(func=cmd_ground)

    m = sub.add_parser("metrics", help="physical metrics of one scene")
    m.add_argument("scene", help="scene.json or its folder")
    m.add_argument("--full", action="store_true", help="print per-object values too")
    m.set_defaults(func=cmd_metrics)

    b = sub.add_parser("bench", help="build one embedded benchmark scene")
    b.add_argument("out_dir")
    b.add_argument("--suite", default="contact")
    b.add_argument("--index", type=int, default=0)
    b.set_defaults(func=cmd_bench)

    for p in (g, m, b):
        p.add_argument("--config", help="workflow config YAML (default: config/config.yaml if present)")
        p.add_argument("--cache-dir", help="cache folder (default: the config's cache_dir)")
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from phiscene.runner import set_threads, setup_logging

    setup_logging(level=logging.DEBUG if args.verbose else logging.WARNING)
    set_threads(1)
    try:
        args.func(args)
    except PhisceneError as exc:
        print(f"phiscene: error: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
