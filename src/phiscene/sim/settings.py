"""Simulation settings shared by every engine and stage (one dataclass, filled from config)."""

from __future__ import annotations

from dataclasses import dataclass

from phiscene.params import Params


@dataclass(frozen=True)
class SimSettings(Params):
    """Physical and numerical settings of a rigid-body world.

    Attributes
    ----------
    frame_dt
        Seconds per frame (the paper's frame: 1/60 s).
    substeps
        Physics steps per frame.
    friction
        Lateral (Coulomb) friction coefficient of every body and the ground.
    rolling_friction, spinning_friction
        Rolling and torsional friction coefficients. A little of each (0.003,
        0.01) stops irregular meshes resting on a few contact points from
        rocking or spinning slowly forever, which otherwise keeps them from
        ever meeting the settling criterion (1e-4 rad per 15 frames).
    restitution
        Coefficient of restitution.
    linear_damping, angular_damping
        Velocity damping per body.
    density
        Mass density of every object, kg/m^3.
    solver_iterations
        Constraint solver iterations per step.
    collision_margin
        Collision margin of convex hulls in metres. Bullet's mesh default
        (1 mm) makes resting bodies float by the sum of both margins, so we
        use 0 and let the solver handle penetration recovery.
    """

    _label = "simulation settings"

    frame_dt: float = 1.0 / 60.0
    substeps: int = 8
    friction: float = 0.8
    rolling_friction: float = 0.003
    spinning_friction: float = 0.01
    restitution: float = 0.0
    linear_damping: float = 0.04
    angular_damping: float = 0.04
    density: float = 500.0
    solver_iterations: int = 50
    collision_margin: float = 0.0
