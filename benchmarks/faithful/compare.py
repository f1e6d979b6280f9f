"""Ground a scene.json with phi_scene (faithful) and phi_scene_paper (the paper's loop); pose + physical metrics.

usage: python benchmarks/faithful/compare.py SCENE_JSON [proxy_backend|convex] [GT_SCENE_JSON|-] [TOPOLOGY_JSON]
Environment: FAITHFUL='{"max_flush_angle": 10}' overrides assembly.faithful keys. Logs go to /tmp/faithful_viga/.
Not a timed benchmark: seconds are warm, on whatever load the machine has."""
import json
import sys
import time
from pathlib import Path

import torch
import yaml

torch.set_num_threads(1)
from phiscene import topology
from phiscene.assembly import AssemblyParams, ground_scene
from phiscene.config import method_assembly
from phiscene.metrics.drift import drift_mujoco
from phiscene.metrics.physical import PhysicalParams, physical_metrics
from phiscene.metrics.pose import pose_metrics
from phiscene.proxies import ProxyParams, scene_proxies
from phiscene.scene import load_scene
from phiscene.sim.mujoco import MujocoParams
from phiscene.sim.settings import SimSettings

ROOT = Path(__file__).resolve().parents[2]
cfg = yaml.safe_load(open(ROOT / "config/config.yaml"))
import os

cfg["methods"]["phi_scene"]["assembly"]["faithful"].update(json.loads(os.environ.get("FAITHFUL", "{}")))
path = Path(sys.argv[1]); backend = sys.argv[2] if len(sys.argv) > 2 else "convex"
gt = load_scene(sys.argv[3]) if len(sys.argv) > 3 and sys.argv[3] != "-" else None
scene = load_scene(path)
cache = Path("/tmp/faithful_viga/cache")
cache.mkdir(parents=True, exist_ok=True)
sim = SimSettings.from_dict(cfg["sim"])
graph = (topology.load(sys.argv[4], scene_ids=scene.ids) if len(sys.argv) > 4
         else topology.infer(scene, "geometric", cfg["topology"]["geometric"]))
t = time.perf_counter()
proxies = scene_proxies(scene, ProxyParams.from_dict({**cfg["proxies"], "backend": backend}), cache)
print(f"proxies ({backend}) {time.perf_counter()-t:.1f} s; edges", [(e.source, e.target, e.relation) for e in graph.edges][:40])
pp = PhysicalParams.from_dict(cfg["metrics"]["physical"])
rows = {}
def show(name, s, secs, rec=None):
    pm = pose_metrics(s, scene, gt=gt)
    ph = physical_metrics(s, proxies, pp, sim, cache)
    mj = drift_mujoco(s, proxies, pp, sim, MujocoParams.from_dict(cfg["metrics"]["mujoco"]))
    r = {"disp_mean_cm": pm["displacement_mean"]*100, "disp_max_cm": pm["displacement_max"]*100,
         "rot_mean_deg": pm["rotation_mean"], "rot_max_deg": pm["rotation_max"],
         "pen_mm": ph["pen_depth"]*1000, "float_mm": (ph["float_dist"] or 0)*1000,
         "pb_drift_mm": ph["drift_trans"]*1000, "pb_drift_deg": ph["drift_rot"],
         "mj_drift_mm": mj["drift_trans"]*1000, "mj_drift_deg": mj["drift_rot"], "seconds": secs}
    if gt is not None:
        r.update({k: pm[k] for k in pm if k.startswith("gt_") and k.endswith("mean")})
    if rec is not None:
        r["unsettled"] = rec["summary"]["unsettled"]
        r["lost"] = rec["summary"].get("supporters_lost"); r["remedies"] = rec["summary"].get("remedies")
    rows[name] = r
    if rec is not None:
        worst = sorted(ph["objects"].items(), key=lambda kv: -float(kv[1]["drift_trans"]))[:4]
        print("  worst pybullet drift:", [(k[:18], round(v["drift_trans"] * 1000, 1), round(v["drift_rot"], 1),
              rec["objects"][k].get("certificate", {}).get("remedy")) for k, v in worst], flush=True)
    print(name, json.dumps({k: (round(v, 3) if isinstance(v, float) else v) for k, v in r.items()}), flush=True)
show("initial", scene, 0.0)
for name in ("phi_scene", "phi_scene_paper"):
    params = AssemblyParams.from_dict(method_assembly(cfg, name))
    ground_scene(scene, graph.order, proxies, params, sim, cache, graph=graph)  # warm
    t = time.perf_counter()
    s, rec = ground_scene(scene, graph.order, proxies, params, sim, cache, graph=graph)
    secs = time.perf_counter() - t
    json.dump(rec, open(f"/tmp/faithful_viga/{path.parent.name}_{name}_log.json", "w"), indent=1, default=str)
    show(name, s, secs, rec)
