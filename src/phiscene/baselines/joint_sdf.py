"""Joint SDF penetration resolution (CAST-style baseline, paper Tab. 6 "joint SDF").

Every object's translation ``x_i`` is optimised at once with Adam on the same
bidirectional clearance hinge that phi-Scene's sequential stage uses
(:mod:`phiscene.assembly.penetration`), summed over all object pairs and the
ground:

    L(X) = sum_{i != j} sum_n [eps - SDF(p_in + x_i, o_j(x_j))]_+
           + sum_i sum_n [eps - (z_in + x_iz - h)]_+

with ``p_in`` the seeded surface samples of object ``i`` (world frame, initial
pose), ``o_j(x_j)`` object ``j`` translated by ``x_j`` (its grid SDF is queried
at ``p_in + x_i - x_j``), and ``z_in`` the heights of object ``i``'s samples
plus its convex hull vertices for the ground term (the ground is the half-space
``z < h``, analytic SDF ``z - h``). Ordered pairs ``(i, j)`` and ``(j, i)``
make the loss bidirectional. Unlike the sequential method, every object of a
colliding pair receives a gradient, so both move.

What we keep from the sequential stage for a fair comparison (same samples,
grids, ``eps``, Adam settings, stopping rule and the optional backtracking of
the last step; see :class:`~phiscene.assembly.penetration.PenetrationParams`)
and what we leave out: CAST optimises full poses (rotation and scale too) with
further terms; this baseline optimises **translations only**, like the
paper's own SDF stage, so the comparison isolates joint vs. sequential.

Pair pruning is exact and re-evaluated every iteration: a pair whose
translated world AABBs are farther apart than ``eps`` plus both grids'
(scaled) cell diagonals contributes exactly zero loss and gradient (grid
values are lower bounds of the exact SDF up to one cell diagonal), so it is
skipped. The test costs one ``(k, k)`` box-gap matrix per iteration, nothing
next to the SDF lookups.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from phiscene.assembly.penetration import PenetrationParams, SdfBody, minimize_hinge, sdf_body
from phiscene.metrics.physical import box_gaps
from phiscene.params import Params
from phiscene.scene import Scene
from phiscene.sdf_grid import GridParams

#: Format tag of the joint SDF log.
LOG_FORMAT = "phiscene.joint_sdf_log/1"


@dataclass(frozen=True)
class JointSdfParams(Params):
    """Parameters of the joint SDF solve (paper values as defaults, shared with the sequential stage).

    Attributes
    ----------
    n_samples
        Surface samples per object (paper: N = 2048).
    eps
        Safety clearance (m).
    lr
        Adam learning rate (m).
    max_iterations
        Cap on Adam iterations (paper: 300).
    backtrack_steps
        Bisection steps pulling the last (overshooting) joint Adam step back to the zero-loss boundary,
        as the sequential stage does; 0 = plain Adam.
    ground
        Include the ground plane term.
    ground_extreme_points
        Add each object's convex-hull vertices to its samples in the ground term.
    seed
        Seed of the surface samples.
    grid
        SDF grid parameters.
    """

    _label = "joint SDF parameters"

    n_samples: int = 2048
    eps: float = 0.005
    lr: float = 0.005
    max_iterations: int = 300
    backtrack_steps: int = 12
    ground: bool = True
    ground_extreme_points: bool = True
    seed: int = 0
    grid: GridParams = field(default_factory=GridParams)

    def check(self) -> None:
        """Reject ``n_samples < 1``, negative iteration counts or ``eps``, and ``lr <= 0`` (``ValueError``)."""
        if self.n_samples < 1 or self.max_iterations < 0 or self.backtrack_steps < 0:
            raise ValueError(f"joint SDF n_samples must be >= 1 and iteration counts >= 0: {self}")
        if self.eps < 0 or self.lr <= 0:
            raise ValueError(f"joint SDF eps must be >= 0 and lr > 0, got eps={self.eps}, lr={self.lr}")

    def penetration_params(self) -> PenetrationParams:
        """The equivalent sequential-stage parameters (used to build the shared SDF bodies)."""
        return PenetrationParams(n_active=self.n_samples, n_context=self.n_samples, eps=self.eps, lr=self.lr,
                                 max_iterations=self.max_iterations, backtrack_steps=self.backtrack_steps,
                                 ground_extreme_points=self.ground_extreme_points, seed=self.seed, grid=self.grid)


class JointLoss:
    """The joint clearance loss of ``k`` bodies, a function of their translations ``X`` (k, 3).

    Parameters
    ----------
    bodies
        The objects at their initial poses (translations are relative to these).
    ground_height
        Height of the ground plane, or ``None`` for no ground term.
    eps
        Clearance (m).
    extreme_points
        Add convex-hull vertices to the ground-term points.
    prune
        Skip pairs whose AABBs are out of reach (exact; ``False`` evaluates every pair, for checking).
    """

    def __init__(self, bodies: list[SdfBody], ground_height: float | None, eps: float, extreme_points: bool,
                 prune: bool = True):
        import torch

        self.bodies, self.eps, self.prune = bodies, eps, prune
        self.ground_height = ground_height
        self.P = [torch.as_tensor(b.samples()) for b in bodies]
        ground_pts = [np.vstack([b.samples(), b.hull()]) if extreme_points else b.samples() for b in bodies]
        self.G = torch.as_tensor(np.concatenate([g[:, 2] for g in ground_pts]))
        self.owner = torch.as_tensor(np.repeat(np.arange(len(bodies)), [len(g) for g in ground_pts]))
        boxes = np.array([b.aabb() for b in bodies]).reshape(-1, 2, 3)
        self.lo, self.hi = boxes[:, 0], boxes[:, 1]
        cd = np.array([b.cell_diagonal() for b in bodies])
        # grid lookups are >= exact SDF - cell diagonal, and the exact SDF between points of two boxes is
        # >= their gap: beyond this reach every hinge term of the pair is zero
        self.reach = eps + cd[:, None] + cd[None, :]
        self.pairs_seen: set[tuple[int, int]] = set()
        self.pair_counts: list[int] = []

    def neighbours(self, X: np.ndarray) -> list[list[int]]:
        """For each body, the other bodies that can contribute at translations ``X`` (k, 3)."""
        k = len(self.bodies)
        if not self.prune:
            return [[i for i in range(k) if i != j] for j in range(k)]
        near = box_gaps(self.lo + X, self.hi + X) <= self.reach
        np.fill_diagonal(near, False)
        return [np.flatnonzero(near[j]).tolist() for j in range(k)]

    def __call__(self, X):
        """Loss at translations ``X`` ((k, 3) float64 torch tensor), differentiable in ``X``."""
        import torch

        eps = self.eps
        total = X.new_zeros(())
        if self.ground_height is not None:
            total = total + torch.relu(eps - (self.G + X[self.owner, 2] - self.ground_height)).sum()
        nbs = self.neighbours(X.detach().numpy())
        self.pair_counts.append(sum(len(n) for n in nbs) // 2)
        for j, nb in enumerate(nbs):
            if not nb:
                continue
            self.pairs_seen.update((min(i, j), max(i, j)) for i in nb)
            body = self.bodies[j]
            pts = torch.cat([self.P[i] + X[i] for i in nb]) - X[j]
            total = total + torch.relu(eps - body.grid.query(pts, body.pose)).sum()
        return total


def solve_joint(bodies: list[SdfBody], ground_height: float | None, params: JointSdfParams
                ) -> tuple[np.ndarray, dict]:
    """Translations of all bodies that clear every pair and the ground by ``eps`` (Adam, jointly).

    Parameters
    ----------
    bodies
        The objects at their initial poses.
    ground_height
        Height of the ground plane, or ``None`` for no ground.
    params
        Solver parameters (``params.ground`` is not read here: pass ``None`` for no ground).

    Returns
    -------
    translations : (k, 3) float
        World translation to add to each body's pose.
    info : dict
        ``iterations``, ``initial_loss``, ``final_loss``, ``backtracked``, ``pairs`` (index pairs ever
        within reach), ``max_pairs`` (most pairs within reach at one evaluation), ``seconds``.
    """
    t0 = time.perf_counter()
    loss_fn = JointLoss(bodies, ground_height, params.eps, params.ground_extreme_points)
    X, info = minimize_hinge(loss_fn, (len(bodies), 3), params.lr, params.max_iterations, params.backtrack_steps)
    info.update(pairs=sorted(loss_fn.pairs_seen), max_pairs=max(loss_fn.pair_counts, default=0),
                seconds=time.perf_counter() - t0)
    return X, info


def joint_sdf(scene: Scene, params: JointSdfParams, cache_dir: str | Path | None) -> tuple[Scene, dict]:
    """CAST-style joint SDF penetration resolution of a whole scene (translations only).

    Parameters
    ----------
    scene
        The initial scene.
    params
        Solver parameters.
    cache_dir
        Cache root of the SDF grids (``None``: memory only).

    Returns
    -------
    scene
        The scene with every object translated (rotations and scales unchanged).
    record
        JSON-ready log: ``format``, ``params``, ``iterations``, ``initial_loss``, ``final_loss``,
        ``converged`` (final loss exactly zero), ``backtracked``, ``pairs`` (id pairs ever within reach),
        ``max_pairs``, ``objects`` (per id: ``translation`` (3,), ``displacement`` m), ``seconds``.
    """
    t0 = time.perf_counter()
    pp = params.penetration_params()
    bodies = [sdf_body(o.id, o.mesh(), o.pose, params.n_samples, pp, cache_dir) for o in scene.objects]
    t_build = time.perf_counter() - t0
    X, info = solve_joint(bodies, scene.ground_height if params.ground else None, params)
    poses = {}
    objects = {}
    for o, x in zip(scene.objects, X):
        pose = np.array(o.pose, dtype=float)
        pose[:3, 3] += x
        poses[o.id] = pose
        objects[o.id] = {"translation": [float(v) for v in x], "displacement": float(np.linalg.norm(x))}
    ids = scene.ids
    record = {"format": LOG_FORMAT, "params": params.to_dict(), "iterations": info["iterations"],
              "initial_loss": info["initial_loss"], "final_loss": info["final_loss"],
              "converged": info["final_loss"] == 0.0, "backtracked": info["backtracked"],
              "pairs": [[ids[i], ids[j]] for i, j in info["pairs"]], "max_pairs": info["max_pairs"],
              "objects": objects,
              "seconds": {"build": t_build, "solve": info["seconds"], "total": time.perf_counter() - t0}}
    return scene.with_poses(poses), record
