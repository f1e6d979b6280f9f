"""The `phiscene` command: ground a tiny scene end to end outside Snakemake; errors are one line."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import trimesh

from phiscene.meshes import save_mesh
from phiscene.proxies import read_proxies
from phiscene.scene import Scene, SceneObject, load_scene, save_scene
from phiscene.transforms import make_pose


def phiscene(*args, cwd):
    return subprocess.run([sys.executable, "-m", "phiscene.cli", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=300)


def test_ground_command_fixes_penetration_and_floating(tmp_path):
    base = save_mesh(trimesh.creation.box([0.4, 0.4, 0.1]), tmp_path / "meshes/base.glb")
    cube = save_mesh(trimesh.creation.box([0.1, 0.1, 0.1]), tmp_path / "meshes/cube.glb")
    # base sunk 1 cm into the ground, cube sunk 2 cm into the base
    scene = Scene([SceneObject("base", base, make_pose(translation=[0, 0, 0.04])),
                   SceneObject("cube", cube, make_pose(translation=[0.02, 0, 0.12]))])
    save_scene(scene, tmp_path / "in/scene.json")
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text("proxies: {backend: convex}\ncache_dir: " + str(tmp_path / "cache") + "\n")
    res = phiscene("ground", str(tmp_path / "in"), str(tmp_path / "out"), "--config", str(cfg), cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert "[3/3] grounding" in res.stdout
    assert "(1/2) base: 1 hull," in res.stdout and "(2/2) cube: 1 hull," in res.stdout  # proxies, object by object
    assert "no methods.phi_scene" in res.stdout  # this config alone grounds with the paper's loop, and says so
    out = load_scene(tmp_path / "out/scene.json")
    # the closing line: how far each box's centre (its frame's origin) moved from the input, and which moved most
    moved = {o.id: float(np.linalg.norm(o.pose[:3, 3] - scene.get(o.id).pose[:3, 3])) for o in out.objects}
    far = max(moved, key=moved.get)
    assert (f"result: 2 of 2 objects settled; from the input: moved {100 * np.mean(list(moved.values())):.1f} cm on "
            f"average, {100 * moved[far]:.1f} cm at most ({far}), turned 0.0 deg") in res.stdout, res.stdout
    log = json.loads((tmp_path / "out/assembly.json").read_text())
    assert log["order"] == ["base", "cube"]
    # oracle: boxes resting flat -> base centre at 0.05, cube centre at 0.1 + 0.05
    np.testing.assert_allclose(out.get("base").pose[2, 3], 0.05, atol=1e-3)
    np.testing.assert_allclose(out.get("cube").pose[2, 3], 0.15, atol=1e-3)
    metrics = phiscene("metrics", str(tmp_path / "out/scene.json"), "--config", str(cfg), cwd=tmp_path)
    assert metrics.returncode == 0, metrics.stderr
    assert f"proxies the scene was grounded with: {tmp_path / 'out/proxies.npz'}" in metrics.stderr
    m = json.loads(metrics.stdout)
    assert m["pen_depth"] < 1e-3 and m["drift_trans"] < 1e-3
    # the export takes the proxies and the support graph grounding wrote beside the scene (recomputing them took a
    # real scene minutes)
    res = phiscene("export", str(tmp_path / "out/scene.json"), str(tmp_path / "exp"), "--config", str(cfg),
                   "--no-check", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert f"proxies: {tmp_path / 'out/proxies.npz'}" in res.stdout and "topology.json" in res.stdout
    assert not (tmp_path / "exp/proxies.npz").exists()
    # grounding into the input's own folder is refused before anything is written over it
    before = (tmp_path / "in/scene.json").read_bytes()
    res = phiscene("ground", str(tmp_path / "in"), str(tmp_path / "in"), "--config", str(cfg), cwd=tmp_path)
    assert res.returncode == 1 and "output folder is the input scene's folder" in res.stderr.strip().splitlines()[-1]
    assert (tmp_path / "in/scene.json").read_bytes() == before


def test_bad_input_is_one_line(tmp_path):
    (tmp_path / "in").mkdir()
    (tmp_path / "in/scene.json").write_text('{"format": "phiscene.scene/1", "objects": [{"id": "a"}]}')
    res = phiscene("ground", str(tmp_path / "in"), str(tmp_path / "out"), cwd=tmp_path)
    assert res.returncode == 1
    # one line, after the note on the config taken (none in the working folder: the one shipped with phiscene)
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 2 and "default config shipped with phiscene" in lines[0], res.stderr
    assert "scene.json" in lines[1] and "objects[0]" in lines[1]
    assert not (tmp_path / "out/scene.json").exists()


def test_bad_unit_scale_is_one_line(tmp_path):
    """A unit scale that is not a finite number > 0 is refused in one line by both importers, before any reading."""
    for command in ("import-sam3d", "import-placed"):
        for value in ("-1", "0", "nan"):
            res = phiscene(command, str(tmp_path / "in"), str(tmp_path / "out"), "--unit-scale", value, cwd=tmp_path)
            assert res.returncode == 1, res.stderr
            assert res.stderr.strip().count("\n") == 0, res.stderr
            assert "--unit-scale" in res.stderr and "> 0" in res.stderr


def test_ground_command_uses_the_method_settings(tmp_path):
    cube = save_mesh(trimesh.creation.box([0.1, 0.1, 0.1]), tmp_path / "meshes/cube.glb")
    save_scene(Scene([SceneObject("cube", cube, make_pose(translation=[0, 0, 0.08]))]), tmp_path / "in/scene.json")
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text("proxies: {backend: convex}\ncache_dir: " + str(tmp_path / "cache") + "\n"
                   "methods:\n  phi_scene: {kind: phi_scene, assembly: {faithful: {enabled: true}}}\n"
                   "  phi_scene_paper: {kind: phi_scene}\n  initial: {kind: reference, source: initial}\n")
    res = phiscene("ground", str(tmp_path / "in"), str(tmp_path / "out"), "--config", str(cfg), cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    log = json.loads((tmp_path / "out/assembly.json").read_text())
    assert log["params"]["faithful"]["enabled"] is True  # phi_scene by default: faithful grounding ...
    assert log["objects"]["cube"]["certificate"]["settled"]  # ... with its certificate
    np.testing.assert_allclose(load_scene(tmp_path / "out/scene.json").get("cube").pose[2, 3], 0.05, atol=1e-3)
    bad = phiscene("ground", str(tmp_path / "in"), str(tmp_path / "out2"), "--config", str(cfg),
                   "--method", "initial", cwd=tmp_path)
    assert bad.returncode == 1 and bad.stderr.strip().count("\n") == 0, bad.stderr
    assert "'initial'" in bad.stderr and "phi_scene_paper" in bad.stderr


def test_config_given_twice_is_merged_and_a_bad_setting_is_one_line(tmp_path):
    """`--config BASE --config OVERRIDE` merges the override over the base (a suite naming a proxy profile of the
    base: backend convex, route `convex`, where the base's own settings take the box's single hull); an override file
    alone, or a misspelled or out-of-range setting, is refused in one line naming the file and the setting, before
    anything is written."""
    cube = save_mesh(trimesh.creation.box([0.1, 0.1, 0.1]), tmp_path / "meshes/cube.glb")
    save_scene(Scene([SceneObject("cube", cube, make_pose(translation=[0, 0, 0.05]))]), tmp_path / "in/scene.json")
    base, over = tmp_path / "base.yaml", tmp_path / "over.yaml"
    base.write_text(f"cache_dir: {tmp_path / 'cache'}\nproxy_profiles: {{plain: {{backend: convex}}}}\n")
    over.write_text("suites: {mine: {n_scenes: 1, proxy_profile: plain}}\n")
    routes = {}
    for name, extra in (("own", ["--config", str(base)]),
                        ("suite", ["--config", str(base), "--config", str(over), "--suite", "mine"]),
                        ("profile", ["--config", str(base), "--proxy-profile", "plain"])):
        res = phiscene("ground", str(tmp_path / "in"), str(tmp_path / name), *extra, cwd=tmp_path)
        assert res.returncode == 0, res.stderr
        routes[name] = read_proxies(tmp_path / name / "proxies.npz")["cube"].meta["route"]
    assert routes == {"own": "single_hull", "suite": "convex", "profile": "convex"}
    res = phiscene("ground", str(tmp_path / "in"), str(tmp_path / "bad"), "--config", str(base), "--proxy-profile",
                   "plane", cwd=tmp_path)
    assert res.returncode == 1 and res.stderr.strip() == ("phiscene: error: --proxy-profile: no proxy profile "
                                                          "'plane' (known: plain)"), res.stderr

    res = phiscene("ground", str(tmp_path / "in"), str(tmp_path / "bad"), "--config", str(over), "--suite", "mine",
                   cwd=tmp_path)
    assert res.returncode == 1 and "Traceback" not in res.stderr and res.stderr.count("\n") == 1, res.stderr
    assert f"{over}: config: suites.mine.proxy_profile: no proxy profile 'plain'" in res.stderr
    assert "--config config/config.yaml --config FILE" in res.stderr
    bad = tmp_path / "bad.yaml"
    for text, message in (("proxies: {max_hull: 3}", f"{base} + {bad}: config: proxies: unknown key 'max_hull'"),
                          ("assembly: {faithful: {joint_tol: -1}}", f"{base} + {bad}: config: assembly.faithful: "
                                                                    "faithful parameter 'joint_tol' must be >= 0"),
                          ("- proxies", f"{bad}: not a config (a YAML mapping of sections)")):
        bad.write_text(text + "\n")
        for command in (["ground", str(tmp_path / "in"), str(tmp_path / "bad")],
                        ["metrics", str(tmp_path / "in/scene.json")]):
            res = phiscene(*command, "--config", str(base), "--config", str(bad), cwd=tmp_path)
            assert res.returncode == 1 and "Traceback" not in res.stderr, res.stderr
            assert res.stderr.count("\n") == 1 and message in res.stderr, res.stderr
    assert not (tmp_path / "bad").exists()


def test_ground_command_without_a_config_grounds_as_the_workflows_phi_scene(tmp_path):
    """Run where there is no config/config.yaml, `phiscene ground` reads the workflow's own config as shipped with
    the package (the faithful `phi_scene` method, not the paper's loop of the parameter defaults), says so, and
    keeps its cache beside its outputs, not in the workflow's results/cache of the working folder."""
    import yaml

    from phiscene.config import method_assembly, packaged_config_path

    repo = yaml.safe_load((Path(__file__).resolve().parents[1] / "config/config.yaml").read_text())
    assert yaml.safe_load(packaged_config_path().read_text()) == repo
    cube = save_mesh(trimesh.creation.box([0.1, 0.1, 0.1]), tmp_path / "meshes/cube.glb")
    save_scene(Scene([SceneObject("cube", cube, make_pose(translation=[0, 0, 0.08]))]), tmp_path / "in/scene.json")
    res = phiscene("ground", str(tmp_path / "in"), str(tmp_path / "out"), cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert "default config shipped with phiscene" in res.stderr
    log = json.loads((tmp_path / "out/assembly.json").read_text())
    want = method_assembly(repo, "phi_scene")
    assert log["params"]["faithful"]["enabled"] is want["faithful"]["enabled"] is True
    assert log["params"]["penetration_params"]["optimizer"] == want["penetration_params"]["optimizer"]
    np.testing.assert_allclose(load_scene(tmp_path / "out/scene.json").get("cube").pose[2, 3], 0.05, atol=1e-3)
    assert (tmp_path / "out/cache").is_dir() and not (tmp_path / "results").exists()


def test_ground_command_takes_a_suites_proxy_settings(tmp_path):
    cube = save_mesh(trimesh.creation.box([0.1, 0.1, 0.1]), tmp_path / "meshes/cube.glb")
    save_scene(Scene([SceneObject("cube", cube, make_pose(translation=[0, 0, 0.05]))]), tmp_path / "in/scene.json")
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text("proxies: {backend: coacd}\ncache_dir: " + str(tmp_path / "cache") + "\n"
                   "suites:\n  scans: {proxies: {backend: convex}}\n")
    routes = {}
    for name, extra in (("global", []), ("suite", ["--suite", "scans"])):
        res = phiscene("ground", str(tmp_path / "in"), str(tmp_path / name), "--config", str(cfg), *extra,
                       cwd=tmp_path)
        assert res.returncode == 0, res.stderr
        routes[name] = read_proxies(tmp_path / name / "proxies.npz")["cube"].meta["route"]
    # a box is convex: the global coacd backend takes its single hull, the suite's backend the plain hull
    assert routes == {"global": "single_hull", "suite": "convex"}
    bad = phiscene("ground", str(tmp_path / "in"), str(tmp_path / "bad"), "--config", str(cfg), "--suite", "nope",
                   cwd=tmp_path)
    assert bad.returncode == 1 and bad.stderr.strip().count("\n") == 0, bad.stderr
    assert "'nope'" in bad.stderr and "scans" in bad.stderr


def test_bench_command_deep_merges_a_suites_benchmark_override():
    from phiscene.cli import _bench_settings
    from phiscene.errors import PhisceneError

    cfg = {"benchmark": {"seed": 3, "degrade": {"rotation_sigma_deg": 9.0, "kind": "clean"}},
           "sim": {"dt": 0.01}, "proxies": {"backend": "convex"},
           "suites": {"corners": {"benchmark": {"degrade": {"kind": "foundation"}}}}}
    params = _bench_settings(cfg, "corners")
    # the suite's degrade kind overrides, the global magnitude it does not name survives (a shallow merge lost it)
    assert params["degrade"] == {"rotation_sigma_deg": 9.0, "kind": "foundation"}
    assert params["seed"] == 3 and params["sim"] == {"dt": 0.01} and params["proxies"] == {"backend": "convex"}
    try:
        _bench_settings(cfg, "nope")
    except PhisceneError as exc:
        assert "'nope'" in str(exc) and "corners" in str(exc)
    else:
        raise AssertionError("an unknown suite was accepted")


def test_import_rest3d_estimates_walls_unless_told_not_to(tmp_path):
    # the REST3D-layout fixture has a poster on its back wall: one wall, none with --no-walls
    from rest3d_fixture import write_scene

    write_scene(tmp_path / "data", "scene_a")
    for flags, walls in (((), 1), (("--no-walls",), 0)):
        out = tmp_path / f"out{walls}"
        res = phiscene("import-rest3d", str(tmp_path / "data"), "scene_a", str(out), *flags, cwd=tmp_path)
        assert res.returncode == 0, res.stderr
        assert f"{walls} walls estimated" in res.stdout
        assert len(load_scene(out / "initial" / "scene.json").structure) == walls


def test_interrupt_and_a_list_of_placements_are_one_line(tmp_path, monkeypatch, capsys):
    """Ctrl-C ends a command with status 130 and one line (not a KeyboardInterrupt traceback); a placements file
    that is not a mapping is refused naming it."""
    import pytest

    from phiscene import cli
    from phiscene.errors import InputError
    from phiscene.io.placed import read_placed_dir

    def interrupted(args):
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "cmd_failures", interrupted)
    assert cli.main(["failures", str(tmp_path)]) == 130
    assert capsys.readouterr().err.strip() == "phiscene: interrupted (failures)"
    save_mesh(trimesh.creation.box([0.1, 0.1, 0.1]), tmp_path / "meshes/box.glb")
    (tmp_path / "placements.json").write_text("[1, 2, 3]")
    with pytest.raises(InputError, match=r"placements.json: expected a mapping of object ids .* got a list"):
        read_placed_dir(tmp_path / "meshes", tmp_path / "placements.json")


def test_threads_do_not_change_the_result(tmp_path):
    # a table (top and four legs: CoACD decomposes it) with a cube on it, grounded with 1 and with 2 threads from
    # empty caches: the same proxies and the same grounded scene, to the bit
    parts = [trimesh.creation.box([0.8, 0.5, 0.04], transform=trimesh.transformations.translation_matrix([0, 0, 0.38]))]
    for x in (-0.36, 0.36):
        for y in (-0.21, 0.21):
            parts.append(trimesh.creation.box([0.05, 0.05, 0.36],
                                              transform=trimesh.transformations.translation_matrix([x, y, 0.18])))
    table = save_mesh(trimesh.util.concatenate(parts), tmp_path / "meshes/table.glb")
    cube = save_mesh(trimesh.creation.box([0.1, 0.1, 0.1]), tmp_path / "meshes/cube.glb")
    scene = Scene([SceneObject("table", table, make_pose(translation=[0, 0, 0.01])),
                   SceneObject("cube", cube, make_pose(translation=[0.05, 0, 0.46]))])
    save_scene(scene, tmp_path / "in/scene.json")
    outs = []
    for threads in (1, 2):
        cfg = tmp_path / f"cfg{threads}.yaml"
        cfg.write_text(f"proxies: {{mcts_iterations: 10, mcts_nodes: 8, resolution: 300}}\n"
                       f"cache_dir: {tmp_path / f'cache{threads}'}\n")
        res = phiscene("--threads", str(threads), "ground", str(tmp_path / "in"), str(tmp_path / f"out{threads}"),
                       "--config", str(cfg), cwd=tmp_path)
        assert res.returncode == 0, res.stderr
        outs.append(tmp_path / f"out{threads}")
    a, b = (read_proxies(o / "proxies.npz")["table"] for o in outs)
    assert a.meta["route"] == "decomposed" and len(a.hulls) > 1
    assert [h.tobytes() for h in a.hulls] == [h.tobytes() for h in b.hulls]
    assert (outs[0] / "scene.json").read_bytes() == (outs[1] / "scene.json").read_bytes()
    res = phiscene("--threads", "0", "ground", str(tmp_path / "in"), str(tmp_path / "out0"), cwd=tmp_path)
    assert res.returncode == 2 and "--threads: must be at least 1" in res.stderr


def test_bench_command_refuses_a_suite_no_generator_builds(tmp_path):
    """`phiscene bench --suite real` (a real-data suite) and a suite of an unknown name: one line, no traceback."""
    cfg = tmp_path / "c.yaml"
    cfg.write_text("suites:\n  foo: {n_scenes: 1}\n  real: {source: {kind: rest3d, root: data/REST3D}}\n")
    for suite in ("foo", "real"):
        res = phiscene("bench", str(tmp_path / "out"), "--suite", suite, "--config", str(cfg), cwd=tmp_path)
        assert res.returncode != 0 and "Traceback" not in res.stderr, res.stderr
        assert f"--suite {suite!r}: not built by an embedded benchmark generator (known: clutter, contact, rooms" \
            in res.stderr, res.stderr
    assert not (tmp_path / "out").exists()


def test_ground_names_the_reconstruction_suite_for_reconstructed_meshes(tmp_path):
    """Without --suite, a scene whose median mesh has over 10,000 faces (a reconstruction) gets a note naming the
    config's real-data suite with its own proxy settings (the shipped config: `real`); clean meshes, or a config
    without such a suite, get none."""
    import yaml

    from phiscene.cli import RECONSTRUCTION_FACES, _reconstruction_hint
    from phiscene.config import packaged_config_path

    cfg = yaml.safe_load(packaged_config_path().read_text())
    fine = trimesh.creation.icosphere(subdivisions=5, radius=0.05)  # 20,480 faces
    assert len(fine.faces) > RECONSTRUCTION_FACES
    scan, box = (save_mesh(m, tmp_path / f"meshes/{n}.glb") for n, m in
                 (("scan", fine), ("box", trimesh.creation.box([0.1, 0.1, 0.1]))))
    for name, meshes in (("scanned", [scan, scan, box]), ("clean", [box, box, scan])):
        save_scene(Scene([SceneObject(f"o{k}", m, make_pose(translation=[0.3 * k, 0, 0.05]))
                          for k, m in enumerate(meshes)]), tmp_path / f"{name}/scene.json")
    hint = _reconstruction_hint(cfg, tmp_path / "scanned/scene.json")
    assert hint is not None and "--proxy-profile reconstruction (or --suite real)" in hint and "20,480 faces" in hint
    assert _reconstruction_hint(cfg, tmp_path / "clean/scene.json") is None
    assert _reconstruction_hint({"proxies": {}}, tmp_path / "scanned/scene.json") is None


def test_bench_command_refuses_a_bad_benchmark_setting_in_one_line(tmp_path):
    """A misspelled benchmark key, global or in the suite's override: one line naming the file and the setting's
    path, no traceback, nothing built."""
    cfg = tmp_path / "c.yaml"
    for text, path in (("suites: {contact: {n_scenes: 1}}\nbenchmark: {n_objectz: [3, 4]}",
                        "config: benchmark: unknown key 'n_objectz'"),
                       ("suites: {contact: {n_scenes: 1, benchmark: {gt: {settle_second: 1}}}}",
                        "config: suites.contact.benchmark.gt: unknown key 'settle_second'")):
        cfg.write_text(text + "\n")
        res = phiscene("bench", str(tmp_path / "out"), "--suite", "contact", "--config", str(cfg), cwd=tmp_path)
        assert res.returncode == 1 and "Traceback" not in res.stderr and res.stderr.count("\n") == 1, res.stderr
        assert f"{cfg}: {path}" in res.stderr, res.stderr
    assert not (tmp_path / "out").exists()
