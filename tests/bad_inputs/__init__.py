"""The bad-input corpus: every case is generated into a temporary folder (no committed binaries).

Each :class:`Case` starts from the same small, valid scene (a 0.4 x 0.4 x 0.1 m
slab on the ground and a 0.1 m cube resting on it, plus a ground-truth
topology file) and breaks one thing. A case either expects a one-line error
that names a file and a field (``file``, ``field``, ``words``) or is handled
gracefully (``handling`` says how; ``check`` verifies the grounded result
against an analytic answer).

``stage`` is the first workflow job that reads the broken file: ``proxies``
(every scene problem) or ``topology`` (topology files given to the
``given`` backend, MLLM answers to the ``mllm`` backend).
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from phiscene.meshes import save_mesh
from phiscene.scene import Scene, SceneObject, save_scene
from phiscene.transforms import make_pose

#: Slab and cube sizes (m) of the base scene.
SLAB = (0.4, 0.4, 0.1)
CUBE = 0.1


@dataclass(frozen=True)
class Case:
    """One bad input.

    Attributes
    ----------
    name
        Test id.
    break_it
        ``break_it(root)`` damages the base scene built in ``root``.
    file
        File name the error must mention (``None`` for a graceful case).
    field
        Field the error must name (``None`` when the file as a whole is bad).
    words
        Words the error must contain.
    stage
        First workflow stage that reads the damaged file: ``proxies`` or ``topology``.
    topology
        Topology backend for the CLI run (``given`` reads ``root/gt/topology.json``).
    handling
        For graceful cases: what happens instead of an error.
    check
        For graceful cases: ``check(root, out_dir)`` asserts the result.
    config
        Extra CLI config keys (merged into the test config).
    """

    name: str
    break_it: Callable[[Path], None]
    file: str | None = None
    field: str | None = None
    words: str = ""
    stage: str = "proxies"
    topology: str = "geometric"
    handling: str = ""
    check: Callable[[Path, Path], None] | None = None
    config: dict = dataclasses.field(default_factory=dict)

    @property
    def graceful(self) -> bool:
        return self.file is None


# -- the base scene --------------------------------------------------------------------------------------------------
def scene_path(root: Path) -> Path:
    return root / "initial" / "scene.json"


def topology_path(root: Path) -> Path:
    return root / "gt" / "topology.json"


def build_base(root: Path) -> Path:
    """Write the valid base scene under ``root``; return its ``scene.json``."""
    slab = save_mesh(trimesh.creation.box(SLAB), root / "meshes" / "slab.glb")
    cube = save_mesh(trimesh.creation.box([CUBE] * 3), root / "meshes" / "cube.glb")
    scene = Scene([SceneObject("slab", slab, make_pose(translation=[0, 0, SLAB[2] / 2]), "a wooden slab"),
                   SceneObject("cube", cube, make_pose(translation=[0.05, 0, SLAB[2] + CUBE / 2]), "a cube")])
    save_scene(scene, scene_path(root))
    write(topology_path(root), {"format": "phiscene.topology/1", "backend": "gt", "objects": ["ground", "slab", "cube"],
                                "edges": [{"from": "ground", "to": "slab"}, {"from": "slab", "to": "cube"}]})
    return scene_path(root)


def write(path: Path, data) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data))  # NaN and inf become bare tokens, as a careless writer produces


def edit_scene(fn: Callable[[dict], None]) -> Callable[[Path], None]:
    """A ``break_it`` that edits the parsed scene.json in place."""
    def run(root: Path) -> None:
        data = json.loads(scene_path(root).read_text())
        fn(data)
        write(scene_path(root), data)
    return run


def edit_topology(fn: Callable[[dict], None]) -> Callable[[Path], None]:
    def run(root: Path) -> None:
        data = json.loads(topology_path(root).read_text())
        fn(data)
        write(topology_path(root), data)
    return run


def set_pose(i: int, pose: np.ndarray) -> Callable[[dict], None]:
    return lambda d: d["objects"][i].update(pose=np.asarray(pose, dtype=float).tolist())


def replace_mesh(name: str, make: Callable[[Path], None]) -> Callable[[Path], None]:
    """Point the cube at a new mesh file ``meshes/<name>`` written by ``make(path)``."""
    def run(root: Path) -> None:
        path = root / "meshes" / name
        make(path)
        edit_scene(lambda d: d["objects"][1].update(mesh=f"../meshes/{name}"))(root)
    return run


def only_objects(objects: list[SceneObject]) -> Callable[[Path], None]:
    def run(root: Path) -> None:
        save_scene(Scene(objects), scene_path(root))
    return run


# -- graceful-case checks (analytic answers) -------------------------------------------------------------------------
def rests_on_ground(object_id: str, bottom_offset: float) -> Callable[[Path, Path], None]:
    """The object's pose z equals its local bottom offset above the ground (z = 0), within 2 mm."""
    def check(root: Path, out: Path) -> None:
        from phiscene.scene import load_scene

        z = load_scene(out / "scene.json").get(object_id).pose[2, 3]
        assert abs(z - bottom_offset) < 2e-3, (object_id, z, bottom_offset)
    return check


def every_object_rests(root: Path, out: Path) -> None:
    """Every grounded object's lowest world vertex is on the ground (all lie side by side on it)."""
    from phiscene.scene import load_scene

    for o in load_scene(out / "scene.json").objects:
        zmin = o.world_mesh().bounds[0, 2]
        assert abs(zmin) < 2e-3, (o.id, zmin)


def cycle_broken_at_weakest(root: Path, out: Path) -> None:
    """The cube <-> slab cycle loses its least confident edge (cube -> slab, 0.2); the slab is placed first."""
    topo = json.loads((out / "topology.json").read_text())
    assert [(e["from"], e["to"]) for e in topo["dropped_edges"]] == [("cube", "slab")], topo["dropped_edges"]
    assert topo["order"] == ["slab", "cube"]
    rests_on_ground("cube", SLAB[2] + CUBE / 2)(root, out)


# -- meshes ----------------------------------------------------------------------------------------------------------
def open_box(path: Path) -> None:
    """A 0.1 m box without its top face (not watertight)."""
    box = trimesh.creation.box([CUBE] * 3)
    up = box.face_normals[:, 2] > 0.9
    save_mesh(trimesh.Trimesh(box.vertices, box.faces[~up], process=False), path)


def two_shells(path: Path) -> None:
    """Two disjoint 0.1 m cubes 0.1 m apart in one mesh (multi-shell)."""
    a = trimesh.creation.box([CUBE] * 3)
    b = a.copy()
    b.apply_translation([0.2, 0, 0])
    save_mesh(trimesh.util.concatenate([a, b]), path)


def flat_square(path: Path) -> None:
    save_mesh(trimesh.Trimesh([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [0.1, 0.1, 0]], [[0, 1, 2], [1, 3, 2]]), path)


def millimetre_box(path: Path) -> None:
    save_mesh(trimesh.creation.box([CUBE * 1000] * 3), path)


def text_file(text: str) -> Callable[[Path], None]:
    def make(path: Path) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return make


def bytes_file(data: bytes) -> Callable[[Path], None]:
    def make(path: Path) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)
    return make


def directory(path: Path) -> None:
    path.mkdir(parents=True)


def fifty_cubes(root: Path) -> None:
    """50 cubes on a 10 x 5 grid, each floating 5 mm above the ground."""
    cube = root / "meshes" / "cube.glb"
    objs = [SceneObject(f"c{k:02d}", cube, make_pose(translation=[0.2 * (k % 10), 0.2 * (k // 10), CUBE / 2 + 0.005]))
            for k in range(50)]
    only_objects(objs)(root)


# -- MLLM answers ----------------------------------------------------------------------------------------------------
def mllm_params(root: Path) -> dict:
    """``topology.mllm`` settings that read the answer from a cache seeded by :func:`mllm_answer`."""
    return {"provider": "openai", "model": "fake-model", "base_url": "http://127.0.0.1:9/v1",
            "cache_dir": str(root / "mllm_cache"), "max_retries": 0, "timeout": 1.0,
            "image": str(root / "reference" / "image.png"),
            "segmentation": str(root / "reference" / "segmentation.png")}


def mllm_answer(text: str) -> Callable[[Path], None]:
    """Seed the MLLM backend's response cache with ``text`` as the model's answer for the base scene.

    The cache key comes from the backend's own public :func:`phiscene.topology.mllm.build_request`,
    so the backend reads exactly this answer instead of calling an endpoint.
    """
    def run(root: Path) -> None:
        from PIL import Image

        from phiscene.scene import load_scene
        from phiscene.topology import mllm

        (root / "reference").mkdir(parents=True, exist_ok=True)
        Image.new("RGB", (8, 8), (200, 200, 200)).save(root / "reference" / "image.png")
        Image.new("RGB", (8, 8), (255, 0, 0)).save(root / "reference" / "segmentation.png")
        params = mllm.MllmParams.from_dict(mllm_params(root))
        digest = mllm.build_request(load_scene(scene_path(root)), params).digest(params)
        cache = root / "mllm_cache" / f"{digest}.json"
        cache.parent.mkdir(parents=True, exist_ok=True)
        cache.write_text(json.dumps({"provider": "openai", "model": "fake-model", "request": digest, "response": text}))
    return run


def _mllm_case(name: str, text: str, field_: str | None, words: str) -> Case:
    return Case(name, lambda root: mllm_answer(text)(root), file="mllm_cache", field=field_, words=words,
                stage="topology", topology="mllm")


# -- the corpus ------------------------------------------------------------------------------------------------------
def _shear() -> np.ndarray:
    p = make_pose(translation=[0.05, 0, 0.15])
    p[0, 1] = 0.5
    return p


def _projective() -> np.ndarray:
    p = make_pose(translation=[0.05, 0, 0.15])
    p[3] = [0, 0, 0.1, 1]
    return p


CASES: list[Case] = [
    # scene.json as a file
    Case("scene_missing", lambda r: scene_path(r).unlink(), "scene.json", None, "file not found"),
    Case("scene_empty_file", lambda r: scene_path(r).write_text(""), "scene.json", None, "file is empty"),
    Case("scene_truncated_json", lambda r: scene_path(r).write_text(scene_path(r).read_text()[:200]),
         "scene.json", None, "not valid JSON"),
    Case("scene_not_an_object", lambda r: scene_path(r).write_text("[1, 2]"), "scene.json", "(top level)",
         "is not of type 'object'"),
    # malformed or missing fields
    Case("objects_missing", edit_scene(lambda d: d.pop("objects")), "scene.json", "objects",
         "required field is missing"),
    Case("object_unknown_field", edit_scene(lambda d: d["objects"][0].update(posee=1)), "scene.json",
         "objects[0].posee", "unknown field"),
    Case("mesh_field_missing", edit_scene(lambda d: d["objects"][1].pop("mesh")), "scene.json", "objects[1].mesh",
         "required field is missing"),
    Case("id_not_a_string", edit_scene(lambda d: d["objects"][0].update(id=7)), "scene.json", "objects[0].id",
         "not of type 'string'"),
    Case("id_reserved_ground", edit_scene(lambda d: d["objects"][1].update(id="ground")), "scene.json",
         "objects[1].id", "reserved"),
    Case("duplicate_ids", edit_scene(lambda d: d["objects"][1].update(id="slab")), "scene.json", "objects[1].id",
         "duplicate object id"),
    Case("units_declared_mm", edit_scene(lambda d: d.update(units="mm")), "scene.json", "units", "'m' was expected"),
    Case("ground_height_nan", edit_scene(lambda d: d.update(ground={"height": float("nan")})), "scene.json",
         "ground.height", "must be finite"),
    Case("zero_objects", edit_scene(lambda d: d.update(objects=[])), "scene.json", "objects",
         "has 0 items, expected at least 1"),
    # poses
    Case("pose_3x4", edit_scene(lambda d: d["objects"][0].update(pose=d["objects"][0]["pose"][:3])), "scene.json",
         "objects[0].pose", "has 3 items, expected at least 4"),
    Case("pose_entry_not_a_number", edit_scene(lambda d: d["objects"][0]["pose"][1].__setitem__(2, "x")),
         "scene.json", "objects[0].pose[1][2]", "not of type 'number'"),
    Case("pose_inf", edit_scene(lambda d: d["objects"][1]["pose"][2].__setitem__(3, float("inf"))), "scene.json",
         "objects[1].pose", "NaN or inf"),
    Case("pose_shear", edit_scene(set_pose(1, _shear())), "scene.json", "objects[1].pose", "shear"),
    Case("pose_projective", edit_scene(set_pose(1, _projective())), "scene.json", "objects[1].pose", "last row"),
    Case("pose_scale_tiny", edit_scene(set_pose(1, make_pose(translation=[0, 0, 0.2], scale=1e-5))), "scene.json",
         "objects[1].pose", "uniform scale"),
    # declared centres of mass
    Case("com_two_numbers", edit_scene(lambda d: d["objects"][1].update(com=[0.0, 0.0])), "scene.json",
         "objects[1].com", "expected at least 3"),
    Case("com_inf", edit_scene(lambda d: d["objects"][1].update(com=[0.0, 0.0, float("inf")])), "scene.json",
         "objects[1].com", "must be finite"),
    Case("com_outside_the_object", edit_scene(lambda d: d["objects"][1].update(com=[0.0, 0.0, 0.3])), "scene.json",
         "objects[1].com", "outside the mesh's bounds"),
    # placement and units
    Case("object_kilometres_away", edit_scene(set_pose(1, make_pose(translation=[2500.0, 0, 0.05]))), "scene.json",
         "objects[1].pose", "units must be metres"),
    Case("object_far_below_ground", edit_scene(set_pose(1, make_pose(translation=[0, 0, -20.0]))), "scene.json",
         "objects[1].pose", "below the ground"),
    Case("scene_in_millimetres", lambda r: _millimetre_scene(r), "scene.json",
         "objects[1].pose", "units must be metres"),
    Case("mesh_in_millimetres", replace_mesh("cube_mm.glb", millimetre_box), "scene.json", "objects[1]",
         "millimetres"),
    # meshes
    Case("mesh_missing", edit_scene(lambda d: d["objects"][1].update(mesh="../meshes/nope.glb")), "scene.json",
         "objects[1].mesh", "mesh file not found"),
    Case("mesh_is_a_directory", replace_mesh("dir.glb", directory), "scene.json", "objects[1].mesh",
         "mesh file not found"),
    Case("mesh_empty_file", replace_mesh("empty.glb", bytes_file(b"")), "scene.json", "objects[1].mesh",
         "empty (0 bytes)"),
    Case("mesh_corrupt_glb", replace_mesh("bad.glb", bytes_file(b"glTF\x02\x00\x00\x00garbage!")), "scene.json",
         "objects[1].mesh", "cannot read mesh"),
    Case("mesh_zero_volume", replace_mesh("flat.ply", flat_square), "scene.json", "objects[1].mesh", "no volume"),
    Case("mesh_nan_vertices", replace_mesh("nan.obj", text_file("v 0 0 0\nv 1 0 0\nv 0 1 0\nv nan 0 1\n"
                                                                "f 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n")),
         "scene.json", "objects[1].mesh", "NaN or inf"),
    Case("mesh_without_faces", replace_mesh("points.obj", text_file("v 0 0 0\nv 1 0 0\nv 0 1 0\n")), "scene.json",
         "objects[1].mesh", "no triangles"),
    # topology files (given backend)
    Case("topology_missing", lambda r: topology_path(r).unlink(), "topology.json", None, "not found",
         stage="topology", topology="given"),
    Case("topology_not_json", lambda r: topology_path(r).write_text("{'edges': oops"), "topology.json", None,
         "not valid JSON", stage="topology", topology="given"),
    Case("topology_dangling_edge", edit_topology(lambda d: d["edges"].append({"from": "slab", "to": "ghost"})),
         "topology.json", "edges[2].to", "unknown node 'ghost'", stage="topology", topology="given"),
    Case("topology_missing_object", edit_topology(lambda d: (d.update(objects=["ground", "slab"]),
                                                             d["edges"].pop())),
         "topology.json", "objects", "missing scene objects ['cube']", stage="topology", topology="given"),
    Case("topology_extra_object", edit_topology(lambda d: d["objects"].append("ghost")), "topology.json", "objects",
         "objects not in the scene ['ghost']", stage="topology", topology="given"),
    Case("topology_ground_supported", edit_topology(lambda d: d["edges"].append({"from": "cube", "to": "ground"})),
         "topology.json", "edges[2].to", "ground cannot be supported", stage="topology", topology="given"),
    Case("topology_confidence_above_one", edit_topology(lambda d: d["edges"][1].update(confidence=7)),
         "topology.json", "edges[1].confidence", "7", stage="topology", topology="given"),
    # garbage from the MLLM endpoint (answers read through the backend's response cache)
    _mllm_case("mllm_not_json", "Sure! Here is the support graph you asked for.", None, "response is not JSON"),
    _mllm_case("mllm_json_array", '[{"from": "Plane", "to": "slab"}]', None, "must be an object, got list"),
    _mllm_case("mllm_no_edges", '{"graph": "slab on the floor"}', None, "no 'edges' list"),
    _mllm_case("mllm_bad_confidence", '{"edges": [{"from": "Plane", "to": "slab", "confidence": "high"}]}',
               "edges[0].confidence", "expected a number in [0, 1]"),
    _mllm_case("mllm_edge_not_an_object", '{"edges": ["slab supports cube"]}', "edges[0]", "expected an object"),
    # graceful handling
    Case("topology_cyclic", edit_topology(lambda d: d.update(edges=[
        {"from": "ground", "to": "slab", "confidence": 1.0}, {"from": "slab", "to": "cube", "confidence": 0.9},
        {"from": "cube", "to": "slab", "confidence": 0.2}])), stage="topology", topology="given",
         handling="the cycle is broken at its least confident edge (listed in dropped_edges); grounding proceeds",
         check=cycle_broken_at_weakest),
    Case("one_object", lambda r: only_objects(
        [SceneObject("cube", r / "meshes" / "cube.glb", make_pose(translation=[0, 0, 0.3]))])(r),
         handling="a single floating object is dropped onto the ground",
         check=rests_on_ground("cube", CUBE / 2)),
    Case("buried_object", edit_scene(set_pose(1, make_pose(translation=[0.5, 0, -0.3]))),
         handling="an object up to 1 m below the ground is lifted onto it by the ground term of the SDF solve",
         check=rests_on_ground("cube", CUBE / 2)),
    Case("non_watertight_mesh", replace_mesh("open.glb", open_box),
         handling="an open mesh is used as is (winding-number SDF, convex proxies); it rests on the slab",
         check=rests_on_ground("cube", SLAB[2] + CUBE / 2)),
    Case("multi_shell_mesh", lambda r: (replace_mesh("two.glb", two_shells)(r),
                                        edit_scene(set_pose(1, make_pose(translation=[0.3, 0, 0.2])))(r)),
         handling="several shells form one rigid body; both shells come to rest on the ground",
         check=every_object_rests),
    Case("fifty_objects", fifty_cubes, handling="50 floating cubes are each dropped onto the ground",
         check=every_object_rests),
]


def _millimetre_scene(root: Path) -> None:
    """The base scene written in millimetres: meshes and translations 1000 times too large."""
    slab = save_mesh(trimesh.creation.box([1000 * s for s in SLAB]), root / "meshes" / "slab_mm.glb")
    cube = save_mesh(trimesh.creation.box([1000 * CUBE] * 3), root / "meshes" / "cube_mm.glb")
    only_objects([SceneObject("slab", slab, make_pose(translation=[0, 0, 50.0])),
                  SceneObject("cube", cube, make_pose(translation=[50.0, 0, 150.0]))])(root)


def build(case: Case, root: Path) -> Path:
    """Build the base scene in ``root`` and break it as ``case`` says; return the scene.json path."""
    build_base(root)
    case.break_it(root)
    return scene_path(root)
