"""A levelled copy of one REST3D page scene (its sam3d/ meshes) as a phiscene scene.json, for development.

usage: python benchmarks/faithful/level_rest3d.py SCENE [tl]
Reads /work/data/REST3D/assets/SCENE/{sam3d,ours}/meshes/*.glb (CC BY-NC: never commit them or the output), levels
with REST3D's rotation (Kabsch between the object centres of sam3d/ and ours/), Y-up -> Z-up, lowest point at z = 0;
with `tl`, also rotates the scene so the largest object's nearest resting facet faces down. Writes
/tmp/faithful_viga/SCENE[_tl]/scene.json. Stands in for the real-scenes importer until it lands."""
import glob
import os
import sys

import numpy as np
import trimesh

from phiscene.metrics.pose import rigid_alignment
from phiscene.scene import Scene, SceneObject, save_scene
from phiscene.transforms import make_pose

name = sys.argv[1] if len(sys.argv) > 1 else "custom_viga"
root = f"/work/data/REST3D/assets/{name}"
table_level = len(sys.argv) > 2
out = f"/tmp/faithful_viga/{name}" + ("_tl" if table_level else "")
os.makedirs(out, exist_ok=True)
def load(p):
    s = trimesh.load(p)
    return s.to_geometry() if isinstance(s, trimesh.Scene) else s
ids = sorted(os.path.basename(p)[:-4] for p in glob.glob(f"{root}/sam3d/meshes/*.glb"))
sam = {i: load(f"{root}/sam3d/meshes/{i}.glb") for i in ids}
ours = {i: load(f"{root}/ours/meshes/{i}.glb") for i in ids}
cs = np.array([sam[i].bounds.mean(0) for i in ids]); co = np.array([ours[i].bounds.mean(0) for i in ids])
R, t = rigid_alignment(cs, co)
ang = np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1)))
yup = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], float)  # Y-up -> Z-up
M = yup @ R
verts = {i: sam[i].vertices @ M.T for i in ids}
if table_level:  # level by the resting facet of the largest object (the table), nearest to the current down
    from phiscene.assembly.resting import resting_normals, rotation_between
    big = max(ids, key=lambda i: np.ptp(verts[i], axis=0).prod())
    n = resting_normals(verts[big]); k = int(np.argmax(n @ [0, 0, -1.0]))
    Q = rotation_between(n[k] / np.linalg.norm(n[k]), np.array([0, 0, -1.0]))
    print("table-level extra rotation", np.degrees(np.arccos(np.clip(n[k] @ [0, 0, -1.0] / np.linalg.norm(n[k]), -1, 1))))
    verts = {i: v @ Q.T for i, v in verts.items()}
zmin = min(v[:, 2].min() for v in verts.values())
objs = []
for i in ids:
    v = verts[i] - [0, 0, zmin]
    c = (v.min(0) + v.max(0)) / 2
    m = trimesh.Trimesh(v - c, sam[i].faces, process=False)
    p = f"{out}/{i}.ply"; m.export(p)
    objs.append(SceneObject(i, p, make_pose(translation=c)))
save_scene(Scene(objs), f"{out}/scene.json")
print(f"levelling rotation {ang:.2f} deg, {len(ids)} objects, faces {[len(sam[i].faces) for i in ids][:3]}...")
