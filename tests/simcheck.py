"""Independent re-simulation of a scene, shared by the benchmark tests (an oracle outside phiscene.bench)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from phiscene.inertia import rigid_props
from phiscene.proxies import ProxyParams, proxy_for_mesh
from phiscene.scene import Scene
from phiscene.sim.bullet import BulletWorld
from phiscene.sim.settings import SimSettings
from phiscene.transforms import decompose, rotation_angle


def resimulate(scene: Scene, cache: Path, proxies: ProxyParams, seconds: float = 2.0) -> tuple[float, float]:
    """Every object dynamic on the ground for ``seconds``; max drift of any object (m, deg)."""
    s = SimSettings()
    with BulletWorld(s, cache) as world:
        world.add_ground(scene.ground_height)
        for o in scene.objects:
            hulls = proxy_for_mesh(o.mesh_path, proxies, cache).hulls
            world.add_body(o.id, hulls, o.pose, rigid_props(o.mesh(), hulls, s.density, com=o.com))
        world.step_frames(int(round(seconds / s.frame_dt)))
        dt, dr = 0.0, 0.0
        for o in scene.objects:
            (R0, t0, _), (R1, t1, _) = decompose(o.pose), decompose(world.pose(o.id))
            dt, dr = max(dt, float(np.linalg.norm(t1 - t0))), max(dr, np.degrees(rotation_angle(R0, R1)))
    return dt, dr


def saved_and_released(scene: Scene, path: Path, proxies: dict, field: str, sim: SimSettings) -> tuple[dict, dict]:
    """``scene`` saved to ``path`` and read back (``field`` of each object, ``com`` or ``base``, must survive the
    file), then released in MuJoCo's drift protocol as written and again with ``field`` cleared on every object.

    Returns
    -------
    The two :func:`~phiscene.metrics.drift.drift_mujoco` results: as written, and without ``field``.
    """
    from phiscene.metrics.drift import drift_mujoco
    from phiscene.metrics.physical import PhysicalParams
    from phiscene.scene import load_scene, save_scene

    saved = load_scene(save_scene(scene, path))
    for o in scene.objects:
        mine = getattr(saved.get(o.id), field)
        assert (mine is None) == (getattr(o, field) is None)
        if mine is not None:
            np.testing.assert_allclose(mine, getattr(o, field), atol=1e-9)
    written = drift_mujoco(saved, proxies, PhysicalParams(), sim)
    for o in saved.objects:
        setattr(o, field, None)
    return written, drift_mujoco(saved, proxies, PhysicalParams(), sim)
