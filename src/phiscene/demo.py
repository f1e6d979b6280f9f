"""Perturbation demo: a ball thrown into an exported scene, simulated and rendered as an animated GIF.

The paper's supplement shows settled reconstructions "imported into a
physics simulator and perturbed by an external object". Here the scene is
the exported URDF scene (:mod:`phiscene.io.export`), loaded into a fresh
pybullet DIRECT client with :func:`~phiscene.io.export.load_urdf_scene`, so
the demo also exercises the export. A solid ball is launched on a ballistic
arc that reaches the target (by default the centre of mass of the object
whose top is highest) at a given horizontal speed, the world runs
``seconds``, and every ``1 / fps`` seconds a frame is rendered on the CPU by
pybullet's TinyRenderer from the same kind of oblique camera as the
benchmark's reference image (:mod:`phiscene.render`: its camera
conventions, ``fit_distance`` and ``look_at_camera``), framing the scene and
the launch point. Frames are written as a looping GIF with Pillow.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from phiscene.errors import InputError
from phiscene.params import Params
from phiscene.tolerances import GRAVITY

#: Colour of the ball (RGB 0-255).
BALL_RGB = (230, 40, 40)


@dataclass(frozen=True)
class DemoParams(Params):
    """Settings of the perturbation demo (config ``export.demo``).

    Attributes
    ----------
    seconds
        Simulated time from the launch (s).
    fps
        GIF frame rate; a frame is rendered every ``round(1 / (fps * time_step))`` physics steps.
    ball_radius
        Ball radius (m); 0 = ``ball_radius_frac`` times the target's size.
    ball_radius_frac
        Ball radius as a fraction of the target object's size (the median edge of its bounding box).
    ball_density
        kg/m^3 (the objects have ``sim.density``).
    speed
        Horizontal speed of the ball (m/s); the flight to the target takes ``distance / speed``.
    launch_distance
        Horizontal distance of the launch point from the target, in scene sizes (the horizontal
        diagonal of all objects' bounding box).
    launch_height
        Height of the launch point above the target, in scene sizes.
    launch_azimuth_deg
        Direction from the target to the launch point, counter-clockwise from +x seen from above (deg).
    target
        ``"top"``: the object whose top is highest; otherwise an object id.
    width, height
        GIF size in pixels (the camera angles and light come from the render settings).
    """

    _label = "demo parameters"

    seconds: float = 2.5
    fps: float = 15.0
    ball_radius: float = 0.0
    ball_radius_frac: float = 0.25
    ball_density: float = 1500.0
    speed: float = 3.0
    launch_distance: float = 0.5
    launch_height: float = 0.05
    launch_azimuth_deg: float = 30.0
    target: str = "top"
    width: int = 480
    height: int = 360

    def __post_init__(self):
        for name in ("seconds", "fps", "ball_density", "speed"):
            v = float(getattr(self, name))
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"demo {name} must be > 0, got {v}")
        for name in ("ball_radius", "ball_radius_frac", "launch_distance", "launch_height"):
            v = float(getattr(self, name))
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"demo {name} must be >= 0, got {v}")
        if int(self.width) < 16 or int(self.height) < 16:
            raise ValueError(f"demo width and height must be >= 16, got {self.width} x {self.height}")
        if self.ball_radius == 0 and self.ball_radius_frac == 0:
            raise ValueError("demo ball_radius and ball_radius_frac are both 0")


@dataclass
class DemoResult:
    """A simulated and rendered throw.

    Attributes
    ----------
    frames : (n, H, W, 3) uint8
        Rendered frames, the first at the launch.
    times : (n,) float
        Simulated time of each frame (s).
    ball : (n, 3) float
        Ball centre at each frame (world, m).
    objects : dict of str to (n, 3) float
        Centre of mass of each object at each frame.
    camera : dict
        The camera (``phiscene.camera/1`` dict, see :mod:`phiscene.render`).
    ball_radius : float
    launch_velocity : (3,) float
    target : str
        Id of the object aimed at.
    """

    frames: np.ndarray
    times: np.ndarray
    ball: np.ndarray
    objects: dict[str, np.ndarray]
    camera: dict
    ball_radius: float
    launch_velocity: np.ndarray
    target: str

    def summary(self) -> dict:
        """JSON-ready summary: frame count, ball travel, per-object displacement at the end (m)."""
        return {"frames": int(len(self.frames)), "seconds": float(self.times[-1]), "target": self.target,
                "ball_radius": self.ball_radius, "launch_velocity": self.launch_velocity.tolist(),
                "ball_start": self.ball[0].tolist(), "ball_end": self.ball[-1].tolist(),
                "ball_travel": float(np.linalg.norm(np.diff(self.ball, axis=0), axis=1).sum()),
                "object_displacement": {k: float(np.linalg.norm(v[-1] - v[0])) for k, v in self.objects.items()}}


def launch_velocity(start: np.ndarray, target: np.ndarray, flight_time: float) -> np.ndarray:
    """Initial velocity (3,) of a ballistic arc from ``start`` to ``target`` in ``flight_time`` under gravity -z.

    Solves ``target = start + v T + g T^2 / 2`` with ``g = (0, 0, -GRAVITY)``.
    """
    g = np.array([0.0, 0.0, -GRAVITY])
    T = float(flight_time)
    return (np.asarray(target, float) - np.asarray(start, float) - 0.5 * g * T * T) / T


def throw_ball(index_path: str | Path, params: DemoParams, render=None) -> DemoResult:
    """Throw a ball into an exported URDF scene, simulate it in pybullet and render frames.

    Parameters
    ----------
    index_path
        The export's ``scene_urdf.json``.
    params
        Ball, launch and timing settings.
    render
        :class:`phiscene.render.RenderParams` (image size, camera angles, light); defaults if ``None``.

    Returns
    -------
    The frames and trajectories.

    Raises
    ------
    InputError
        The index is unreadable, or ``params.target`` names no object of it.
    """
    from dataclasses import replace

    from phiscene.io.export import load_urdf_scene, read_urdf_index
    from phiscene.render import RenderParams, fit_distance, look_at_camera

    render = replace(render or RenderParams(), width=int(params.width), height=int(params.height))
    index = read_urdf_index(index_path)
    contact = index.get("contact", {})
    time_step = float(index["physics"]["time_step"])
    from phiscene.sim.bullet import open_client

    client = open_client()
    try:
        uids = load_urdf_scene(index_path, client)
        bodies = {k: v for k, v in uids.items() if k != "ground"}
        boxes = {k: np.asarray(client.getAABB(uid), dtype=float) for k, uid in bodies.items()}

        def com(uid: int) -> np.ndarray:
            return np.asarray(client.getBasePositionAndOrientation(uid)[0], dtype=float)

        if params.target == "top":
            target_id = max(boxes, key=lambda k: boxes[k][1, 2])
        elif params.target in bodies:
            target_id = params.target
        else:
            raise InputError(index_path, "objects", f"demo target {params.target!r} is not an object "
                             f"(objects: {', '.join(bodies)})")
        lo = np.min([b[0] for b in boxes.values()], axis=0)
        hi = np.max([b[1] for b in boxes.values()], axis=0)
        size = max(float(np.linalg.norm(hi[:2] - lo[:2])), 0.05)
        radius = params.ball_radius or params.ball_radius_frac * float(np.median(np.diff(boxes[target_id], axis=0)))
        target = com(bodies[target_id])
        az = math.radians(params.launch_azimuth_deg)
        distance = max(params.launch_distance * size, 4.0 * radius)
        start = target + np.array([math.cos(az), math.sin(az), 0.0]) * distance
        start[2] = max(start[2] + params.launch_height * size, index["ground"]["position"][2] + radius)
        v0 = launch_velocity(start, target, distance / params.speed)

        mass = params.ball_density * 4.0 / 3.0 * math.pi * radius**3
        col = client.createCollisionShape(client.GEOM_SPHERE, radius=radius)
        vis = client.createVisualShape(client.GEOM_SPHERE, radius=radius, rgbaColor=[c / 255 for c in BALL_RGB] + [1.0])
        ball = client.createMultiBody(mass, col, vis, basePosition=start.tolist())
        client.changeDynamics(ball, -1, lateralFriction=contact.get("lateral_friction", 0.8),
                              rollingFriction=contact.get("rolling_friction", 0.0),
                              spinningFriction=contact.get("spinning_friction", 0.0),
                              restitution=contact.get("restitution", 0.0))
        client.resetBaseVelocity(ball, v0.tolist(), [0, 0, 0])

        # camera: the benchmark's oblique view, framing the objects and the ball's launch point
        view_lo = np.minimum(lo, start - radius)
        view_hi = np.maximum(hi, start + radius)
        bounds = np.array([view_lo, view_hi])
        centre = bounds.mean(axis=0)
        aspect = render.width / render.height
        el, azc = math.radians(render.elevation_deg), math.radians(render.azimuth_deg)
        back = np.array([math.cos(el) * math.cos(azc), math.cos(el) * math.sin(azc), math.sin(el)])
        dist = render.margin * fit_distance(bounds, centre, back, math.radians(render.fov_y_deg) / 2, aspect)
        camera = look_at_camera(centre + dist * back, centre, render.width, render.height, render.fov_y_deg,
                                render.near, max(render.far, 4 * dist))

        stride = max(1, int(round(1.0 / (params.fps * time_step))))
        n_frames = int(round(params.seconds / (stride * time_step))) + 1
        frames, times, ball_path = [], [], []
        paths: dict[str, list] = {k: [] for k in bodies}
        for k in range(n_frames):
            if k:
                for _ in range(stride):
                    client.stepSimulation()
            _, _, px, _, _ = client.getCameraImage(
                render.width, render.height, viewMatrix=camera["pybullet"]["view_matrix"],
                projectionMatrix=camera["pybullet"]["projection_matrix"], renderer=client.ER_TINY_RENDERER,
                shadow=int(render.shadow), lightDirection=list(render.light_direction))
            frames.append(np.asarray(px, dtype=np.uint8).reshape(render.height, render.width, 4)[:, :, :3])
            times.append(k * stride * time_step)
            ball_path.append(com(ball))
            for oid, uid in bodies.items():
                paths[oid].append(com(uid))
    finally:
        client.disconnect()
    return DemoResult(frames=np.stack(frames), times=np.asarray(times), ball=np.asarray(ball_path),
                      objects={k: np.asarray(v) for k, v in paths.items()}, camera=camera, ball_radius=float(radius),
                      launch_velocity=v0, target=target_id)


def save_gif(frames: np.ndarray, path: str | Path, fps: float) -> Path:
    """Write frames (n, H, W, 3) uint8 as a looping animated GIF atomically (Pillow, no dithering).

    Each frame gets its own adaptive 256-colour palette (median cut), so
    colours stay close to the rendered ones; the output is deterministic.
    """
    from PIL import Image

    from phiscene.atomic import atomic_path

    frames = np.asarray(frames)
    if frames.ndim != 4 or frames.shape[-1] != 3 or len(frames) == 0:
        raise ValueError(f"frames must be (n, H, W, 3) with n >= 1, got {frames.shape}")
    images = [Image.fromarray(np.ascontiguousarray(f, dtype=np.uint8)).quantize(
        colors=256, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE) for f in frames]
    path = Path(path)
    with atomic_path(path) as tmp:
        images[0].save(tmp, format="GIF", save_all=True, append_images=images[1:],
                       duration=int(round(1000.0 / fps)), loop=0, optimize=False, disposal=1)
    return path


def run_demo(index_path: str | Path, out_gif: str | Path, out_json: str | Path | None, params: dict,
             render: dict | None = None) -> dict:
    """File-level demo: exported ``scene_urdf.json`` in, animated GIF (and a JSON summary) out.

    Parameters
    ----------
    index_path
        The export's ``scene_urdf.json``.
    out_gif, out_json
        Output GIF, and optionally the summary JSON (:meth:`DemoResult.summary`).
    params
        :class:`DemoParams` mapping.
    render
        :class:`phiscene.render.RenderParams` mapping (image size, camera angles).

    Returns
    -------
    The summary.
    """
    import logging

    from phiscene.atomic import write_json
    from phiscene.render import RenderParams

    dp = DemoParams.from_dict(params)
    result = throw_ball(index_path, dp, RenderParams.from_dict(render))
    save_gif(result.frames, out_gif, dp.fps)
    summary = {**result.summary(), "params": dp.to_dict()}
    if out_json is not None:
        write_json(out_json, summary)
    moved = max(summary["object_displacement"].values())
    logging.getLogger(__name__).info("demo: %d frames, ball travelled %.3f m, largest object displacement %.3f m",
                                     summary["frames"], summary["ball_travel"], moved)
    return summary
