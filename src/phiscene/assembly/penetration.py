"""SDF-based penetration resolution (paper §3.1.2): a translation-only solve for the active object.

The loss is the paper's bidirectional clearance hinge

    L(x) = sum_k ( sum_n [eps - SDF(p_n + x, o_k)]_+ + sum_n [eps - SDF(q_kn - x, o_active)]_+ )

over every settled context object ``o_k``, with ``p_n`` seeded surface samples
of the active object and ``q_kn`` of ``o_k`` (world frame), plus the ground.
``SDF(., o)`` is the grid SDF of :mod:`phiscene.sdf_grid` (exact values on a
grid, trilinear lookup). It is minimised over ``x`` with Adam (paper: lr
0.005, at most 300 iterations; torch's own update, see :class:`AdamState`) and stops as soon as the loss is exactly zero
(Adam's momentum would otherwise keep moving the object).

Choices the paper leaves open, and what we do:

* The ground is the half-space ``z < h`` with the analytic SDF ``z - h``. It
  has no samples of its own: a half-space overlaps a mesh exactly when a mesh
  point lies below it, and the lowest mesh point is a vertex of its convex
  hull, so the ground term uses the active samples plus the active's convex
  hull vertices (``ground_extreme_points``; the reverse term would add nothing).
* Pruning is exact and re-evaluated every iteration: a context object whose
  world AABB is farther than ``eps`` plus the two grids' (scaled) cell
  diagonals from the translated active AABB contributes exactly zero loss and
  gradient (grid values are lower bounds up to one cell diagonal), so it is
  skipped. No bound on the step length is needed.
* Adam normalises each coordinate on its own, so with a gradient that is
  mostly vertical it still moves the object as far sideways as up (a
  diagonal push of equal x, y, z steps; measured on the clutter suite:
  sideways pushes of 4-8 cm that carried objects off their supporters).
  ``optimizer: steepest`` takes steps of length ``lr`` along the loss's
  steepest descent direction instead, the smallest motion that clears the
  overlap to first order; the paper's Adam stays the default.
* The last Adam step usually overshoots the zero-loss boundary by up to one
  step (~lr per axis). With ``backtrack_steps > 0`` that step is bisected
  back to the zero-loss point closest to the previous iterate (the loss
  stays exactly zero), which keeps the clearance close to ``eps`` and the
  disturbance of the arrangement minimal, as the paper intends. Set it to 0
  for plain Adam.
* ``planar=True`` (faithful grounding, an object standing on the floor alone) moves the object
  horizontally out of its context objects and the walls: their terms are evaluated at the whole
  translation but their gradient's vertical part is dropped; only the ground pushes vertically (an
  object sunk into the floor still rises out of it). The height of such an object is the floor's: a
  vertical push out of a neighbour (a chair tucked under a table top lowered onto the floor) lifts it
  off the floor, to fall back into the same overlap, or presses it into the floor. The walls too: an
  estimated wall is a degree or two off vertical, and its push along its normal, each time a
  neighbour pushes the object back into it, would ratchet the object upwards (measured on clutter:
  a plate 17 cm off the floor).
* Gradient steps stop in a local minimum with a positive loss where the object is wedged between
  neighbours (a chair's back inside a table top and the chair's seat under it): the pushes of the two
  cancel. With ``search_directions > 0`` such a solve falls back to a direction search
  (:func:`min_translation_search`): ``search_directions`` unit directions (horizontal only when
  ``planar``) are marched out together in steps of ``search_step``, up to ``search_reach``; the first
  translation with a zero loss is bisected back to the zero-loss boundary. That is the smallest
  translation that clears the overlap, to the step's resolution, wherever the gradient stalls. None within
  ``search_reach`` (a reconstruction that put a chair through a table, a bed through the wardrobe): the
  march goes on to :data:`SEARCH_DOUBLINGS` doublings of the reach with a doubled step each; an object left
  inside its neighbours is thrown metres when the scene is released together (and by the drift metric). The
  paper's loop keeps it off (0). The same search also checks a gradient solve that cleared the overlap by a
  long way (longer than ``rotate_over``): the gradient of a sum of hinge terms need not point along the
  shortest way out (a plate sunk 3 cm into the box it lies on, its rim over the box's edge, was pushed 18
  cm sideways), so the shorter of the two is taken. An object supported from below is never searched
  downwards (into or under its supporter).
* Rotation where translation alone cannot do it (``rotate_over > 0``): a plank jammed across a gap,
  each end inside a neighbour from opposite sides, clears by a small turn while a translation must slide
  it out lengthwise. When the translation found is longer than ``rotate_over`` (or none clears), the same
  loss is minimised over a translation ``x`` and a rotation vector ``w`` about the centroid ``c`` of the
  active samples (``p -> R(w)(p - c) + c + x``; the context samples are moved by the inverse into the
  active's frame), by normalised steps on ``(x, r w)`` with ``r`` the samples' RMS radius, so a step moves
  the object's points by about ``lr`` either way. The smaller motion, ``|x| + r |w|``, wins. An object
  standing on the floor alone turns about the vertical only.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from phiscene.params import Params
from phiscene.sdf_grid import GridParams, SdfGrid, sdf_grid
from phiscene.transforms import decompose, transform_points


@dataclass(frozen=True)
class PenetrationParams(Params):
    """Parameters of the SDF penetration solve (paper values as defaults).

    Attributes
    ----------
    n_active, n_context
        Surface samples of the active object (N_a) and of each context object (N_k).
    eps
        Safety clearance (m).
    lr
        Adam learning rate (m); with ``optimizer: steepest`` the length of each step (m).
    max_iterations
        Cap on iterations.
    optimizer
        ``adam`` (the paper's) or ``steepest`` (normalised gradient descent: steps of length ``lr`` along
        the steepest descent direction, per object).
    search_directions
        A solve that ends with a positive loss falls back to :func:`min_translation_search` over this many
        directions (0 = off, the paper's loop).
    search_step, search_reach
        That search's step (m) and farthest translation (m).
    rotate_over
        When the translation that clears the overlap is longer than this (m), or none was found, a solve over
        translation and rotation (about the active samples' centroid, :func:`resolve_penetration`) is tried too,
        and the smaller motion wins (translation plus the arc the rotation sweeps at the samples' radius);
        0 = translation only (the paper's loop).
    max_rotation
        Largest rotation (deg) that solve may apply.
    backtrack_steps
        Bisection steps that pull the last (overshooting) Adam step back to the
        zero-loss boundary; 0 = plain Adam.
    ground_extreme_points
        Add the active's convex-hull vertices to its samples in the ground term.
    seed
        Seed of the surface samples.
    grid
        SDF grid parameters.
    """

    _label = "penetration parameters"

    n_active: int = 2048
    n_context: int = 2048
    eps: float = 0.005
    lr: float = 0.005
    max_iterations: int = 300
    backtrack_steps: int = 12
    optimizer: str = "adam"
    search_directions: int = 0
    search_step: float = 0.01
    search_reach: float = 0.6
    rotate_over: float = 0.0
    max_rotation: float = 15.0
    ground_extreme_points: bool = True
    seed: int = 0
    grid: GridParams = field(default_factory=GridParams)

    def check(self) -> None:
        """Reject sample counts < 1, negative iteration counts or ``eps``, and ``lr <= 0`` (``ValueError``)."""
        if self.n_active < 1 or self.n_context < 1 or self.max_iterations < 0 or self.backtrack_steps < 0:
            raise ValueError(f"penetration sample counts must be >= 1 and iteration counts >= 0: {self}")
        if self.eps < 0 or self.lr <= 0:
            raise ValueError(f"penetration eps must be >= 0 and lr > 0, got eps={self.eps}, lr={self.lr}")
        if self.rotate_over < 0 or not 0 < self.max_rotation <= 90:
            raise ValueError(f"penetration rotate_over must be >= 0 and max_rotation in (0, 90]: {self.rotate_over}, "
                             f"{self.max_rotation}")
        if self.search_directions < 0 or self.search_step <= 0 or self.search_reach <= 0:
            raise ValueError("penetration search_directions must be >= 0, search_step and search_reach > 0: "
                             f"{self.search_directions}, {self.search_step}, {self.search_reach}")
        if self.optimizer not in OPTIMIZERS:
            raise ValueError(f"penetration optimizer must be one of {sorted(OPTIMIZERS)}, got {self.optimizer!r}")


@dataclass
class SdfBody:
    """An object as the penetration solve sees it.

    Attributes
    ----------
    id
        Object id.
    pose : (4, 4) float
        Local-to-world pose (uniform scale allowed).
    grid
        SDF grid of the local mesh.
    samples_local : (n, 3) float
        Seeded surface samples, unscaled local frame.
    hull_local : (m, 3) float
        Convex hull vertices of the local mesh (its extreme points).
    """

    id: str
    pose: np.ndarray
    grid: SdfGrid
    samples_local: np.ndarray
    hull_local: np.ndarray

    @property
    def scale(self) -> float:
        return decompose(self.pose)[2]

    def samples(self) -> np.ndarray:
        """World surface samples (n, 3)."""
        return transform_points(self.pose, self.samples_local)

    def hull(self) -> np.ndarray:
        """World convex hull vertices (m, 3)."""
        return transform_points(self.pose, self.hull_local)

    def aabb(self) -> np.ndarray:
        """World axis-aligned bounding box (2, 3): exact, from the hull vertices."""
        h = self.hull()
        return np.stack([h.min(axis=0), h.max(axis=0)])

    def cell_diagonal(self) -> float:
        """World length of one grid cell diagonal (the grid's interpolation error bound)."""
        return self.scale * self.grid.cell_diagonal

    def moved(self, pose: np.ndarray) -> "SdfBody":
        """The same body at another pose."""
        return SdfBody(self.id, np.asarray(pose, dtype=float), self.grid, self.samples_local, self.hull_local)


_SAMPLES: dict[tuple[str, int, int], np.ndarray] = {}


def sdf_body(object_id: str, mesh, pose: np.ndarray, n_samples: int, params: PenetrationParams,
             cache_dir: str | Path | None) -> SdfBody:
    """Build the :class:`SdfBody` of a local mesh at ``pose`` (grid and samples cached).

    Parameters
    ----------
    object_id
        Object id.
    mesh : trimesh.Trimesh
        Local-frame mesh.
    pose : (4, 4) float
    n_samples
        Surface samples to draw (seeded by ``params.seed``).
    params
        Penetration parameters (grid settings, seed).
    cache_dir
        Cache root for the SDF grids (``None``: memory only).
    """
    from phiscene.meshes import sample_surface

    grid = sdf_grid(mesh, params.grid, cache_dir, clearance=params.eps / decompose(pose)[2])
    key = (grid.mesh_hash, n_samples, params.seed)
    if key not in _SAMPLES:
        _SAMPLES[key] = sample_surface(mesh, n_samples, params.seed)
    hull = np.asarray(mesh.convex_hull.vertices, dtype=float)
    return SdfBody(object_id, np.asarray(pose, dtype=float), grid, _SAMPLES[key], hull)


def aabb_gap(a: np.ndarray, b: np.ndarray) -> float:
    """Euclidean distance between two axis-aligned boxes, each (2, 3) (0 when they overlap)."""
    d = np.maximum(0.0, np.maximum(a[0] - b[1], b[0] - a[1]))
    return float(np.linalg.norm(d))


class _Loss:
    """The clearance loss of one active body against a fixed context and the ground."""

    def __init__(self, active: SdfBody, context: list[SdfBody], ground_height: float | None, eps: float,
                 extreme_points: bool, planes=(), planar: bool = False, yaw_only: bool = False):
        import torch

        self.active, self.context, self.eps = active, context, eps
        # planar: the context and wall terms are evaluated at the whole translation but push only horizontally
        self.mask = torch.tensor([1.0, 1.0, 0.0 if planar else 1.0], dtype=torch.float64)
        self.ground_height = ground_height
        self.P = torch.as_tensor(active.samples())
        ground_pts = np.vstack([active.samples(), active.hull()]) if extreme_points else active.samples()
        self.G = torch.as_tensor(ground_pts[:, 2])
        # walls and ceiling: half-spaces like the ground, analytic SDF n . p + d on the same points
        # (distances of the ground points, normal, offset) per plane
        self.planes = [(torch.as_tensor(ground_pts @ np.asarray(p.normal, dtype=float) + p.offset),
                        torch.as_tensor(np.asarray(p.normal, dtype=float)), float(p.offset)) for p in planes]
        self.Q = [torch.as_tensor(k.samples()) for k in context]
        #: pivot of the rotation (the active samples' centroid) and the ground/plane points and hull, world frame
        self.pivot = torch.as_tensor(active.samples().mean(axis=0))
        self.ground_points = torch.as_tensor(ground_pts)
        self.hull_world = active.hull()
        #: the rotation solve turns about the vertical only (a floor-standing or supported object stays flush)
        self.yaw_only = planar or yaw_only
        self.aabb_active = active.aabb()
        self.aabbs = [k.aabb() for k in context]
        # grid lookups are >= exact SDF - cell diagonal, and the exact SDF between points of two boxes is
        # >= their gap: beyond this reach every hinge term of the pair is zero
        self.reach = [eps + k.cell_diagonal() + active.cell_diagonal() for k in context]
        self.used: set[str] = set()

    def near(self, box: np.ndarray) -> list[int]:
        """Indices of the context bodies that can contribute with the active body inside ``box`` (2, 3)."""
        return [i for i, (b, r) in enumerate(zip(self.aabbs, self.reach)) if aabb_gap(box, b) <= r]

    def _context_terms(self, total, idx: list[int], moved, to_active):
        """``total`` plus the hinge terms against the context bodies ``idx``: the active samples at ``moved``
        (n, 3) in each context grid, and the context samples, taken into the active's unmoved frame by
        ``to_active``, in the active grid."""
        import torch

        self.used.update(self.context[i].id for i in idx)
        for i in idx:
            k = self.context[i]
            total = total + torch.relu(self.eps - k.grid.query(moved, k.pose)).sum()
        Q = to_active(torch.cat([self.Q[i] for i in idx]))
        return total + torch.relu(self.eps - self.active.grid.query(Q, self.active.pose)).sum()

    def __call__(self, x, w=None):
        """The loss at translation ``x`` (3,) and, when given, rotation vector ``w`` (3,) about :attr:`pivot`."""
        import torch

        if w is None:
            return self._translated(x)
        eps = self.eps
        if self.yaw_only:  # an object on the floor or on a supporter turns about the vertical only
            w = w * torch.tensor([0.0, 0.0, 1.0], dtype=w.dtype)
        R = torch.linalg.matrix_exp(_skew(w))
        c = self.pivot
        total = x.new_zeros(())
        turned = (self.ground_points - c) @ R.T + c
        if self.ground_height is not None:
            total = total + torch.relu(eps - (turned[:, 2] + x[2] - self.ground_height)).sum()
        x = x * self.mask + (x * (1.0 - self.mask)).detach()  # planar: only the ground pushes vertically
        for _, normal, offset in self.planes:
            total = total + torch.relu(eps - ((turned + x) @ normal + offset)).sum()
        Rn = R.detach().numpy()
        hull = (self.hull_world - c.numpy()) @ Rn.T + c.numpy() + x.detach().numpy()
        idx = self.near(np.stack([hull.min(axis=0), hull.max(axis=0)]))
        if idx:  # the context samples go back by the inverse motion, into the active's unmoved frame
            total = self._context_terms(total, idx, (self.P - c) @ R.T + c + x, lambda Q: (Q - c - x) @ R + c)
        return total

    def _translated(self, x):
        import torch

        eps = self.eps
        total = x.new_zeros(())
        if self.ground_height is not None:
            total = total + torch.relu(eps - (self.G + x[2] - self.ground_height)).sum()
        x = x * self.mask + (x * (1.0 - self.mask)).detach()  # planar: only the ground pushes vertically
        for dist, normal, _ in self.planes:
            total = total + torch.relu(eps - (dist + x @ normal)).sum()
        idx = self.near(self.aabb_active + x.detach().numpy())
        if idx:
            total = self._context_terms(total, idx, self.P + x, lambda Q: Q - x)
        return total


def _skew(w):
    """The cross-product matrix (3, 3) of a torch vector ``w`` (3,), differentiable."""
    import torch

    z = w.new_zeros(())
    return torch.stack([torch.stack([z, -w[2], w[1]]), torch.stack([w[2], z, -w[0]]),
                        torch.stack([-w[1], w[0], z])])


class AdamState:
    """Adam on one tensor through torch's functional update :func:`torch.optim.adam.adam`.

    The arithmetic is exactly ``torch.optim.Adam`` (default betas and eps); the
    functional form skips the optimizer class, whose construction imports
    ``torch._dynamo`` (1-2 s per process, more than a whole scene's solve).

    Parameters
    ----------
    param
        The leaf tensor to optimise (updated in place).
    lr
        Learning rate.
    """

    def __init__(self, param, lr: float):
        import torch

        self.param, self.lr = param, lr
        self.exp_avg = torch.zeros_like(param)
        self.exp_avg_sq = torch.zeros_like(param)
        self.step_count = torch.zeros((), dtype=torch.float32)

    def step(self) -> None:
        """One Adam step from ``param.grad`` (then cleared)."""
        import torch
        from torch.optim.adam import adam

        with torch.no_grad():
            adam([self.param], [self.param.grad], [self.exp_avg], [self.exp_avg_sq], [], [self.step_count],
                 foreach=False, amsgrad=False, beta1=0.9, beta2=0.999, lr=self.lr, weight_decay=0.0, eps=1e-8,
                 maximize=False)
        self.param.grad = None


class SteepestState:
    """Normalised gradient descent: each row of ``param`` moves by ``lr`` along its own steepest descent direction.

    Parameters are those of :class:`AdamState`.
    """

    def __init__(self, param, lr: float):
        self.param, self.lr = param, lr

    def step(self) -> None:
        """One step from ``param.grad`` (then cleared); rows with a zero gradient stay."""
        import torch

        with torch.no_grad():
            g = self.param.grad.reshape(-1, 3)
            norm = torch.linalg.vector_norm(g, dim=1, keepdim=True)
            step = torch.where(norm > 0, g / torch.clamp(norm, min=1e-300), torch.zeros_like(g))
            self.param -= self.lr * step.reshape(self.param.shape)
        self.param.grad = None


class SteepestJointState:
    """Normalised gradient descent on the whole of ``param``: it moves by ``lr`` along its steepest descent
    direction (the translation-and-rotation solve, where per-row normalisation would always turn and slide).

    Parameters are those of :class:`AdamState`.
    """

    def __init__(self, param, lr: float):
        self.param, self.lr = param, lr

    def step(self) -> None:
        """One step from ``param.grad`` (then cleared); a zero gradient stays."""
        import torch

        with torch.no_grad():
            g = self.param.grad
            norm = torch.linalg.vector_norm(g)
            if float(norm) > 0:
                self.param -= self.lr * g / norm
        self.param.grad = None


#: Optimizers of the penetration solve, by ``PenetrationParams.optimizer``.
OPTIMIZERS = {"adam": AdamState, "steepest": SteepestState}
#: Optimizers :func:`minimize_hinge` knows besides the configurable ones (the translation-and-rotation solve's).
_SOLVERS = {**OPTIMIZERS, "steepest_joint": SteepestJointState}


#: :func:`resolve_penetration`: when no direction clears the overlap within ``search_reach``, the search goes on
#: out to this many doublings of it (0.6 m -> 4.8 m), each with a doubled step (as many probes per doubling).
SEARCH_DOUBLINGS = 3


def resolve_penetration(active: SdfBody, context: list[SdfBody], ground_height: float | None,
                        params: PenetrationParams, planes=(), planar: bool = False,
                        yaw_only: bool = False) -> tuple[np.ndarray, dict]:
    """Translation of ``active`` that clears its settled context, the ground and the walls by ``eps``.

    Parameters
    ----------
    active
        The object to move (its pose is not changed here).
    context
        The fixed, already settled objects.
    ground_height
        Height of the ground plane, or ``None`` for no ground.
    params
        Solver parameters.
    planes
        Walls and ceiling (:class:`phiscene.scene.Plane`, ``Scene.structure``): half-spaces with the
        analytic SDF ``n . p + d``, on the same points as the ground term.
    planar
        Clear the context objects and the walls by horizontal motion only (the translation's vertical part
        moves the object out of the ground only); see the module notes. Implies ``yaw_only``.
    yaw_only
        The object rests on a supporter: the rotation solve (``params.rotate_over``) turns it about the vertical
        only (made flush with its supporter, it stays flush), and the direction search never moves it down.

    Returns
    -------
    translation : (3,) float
        World translation to add to the active pose.
    info : dict
        ``iterations`` (Adam steps taken), ``initial_loss``, ``final_loss``, ``backtracked`` (bisection
        steps used), ``context`` (ids that were ever within reach), ``searched`` (whether the direction
        search replaced a stalled solve), ``rotation`` (3,) rotation vector (rad) applied about ``pivot`` (3,)
        before the translation (zero unless the rotation solve won), ``seconds``.
    """
    t0 = time.perf_counter()
    loss_fn = _Loss(active, context, ground_height, params.eps, params.ground_extreme_points, planes, planar,
                    yaw_only)
    x, info = minimize_hinge(loss_fn, (3,), params.lr, params.max_iterations, params.backtrack_steps,
                             params.optimizer)
    info["searched"] = False

    def search(reach: float, start: float = 0.0, step: float = params.search_step) -> np.ndarray | None:
        base = np.zeros(3)
        if planar and ground_height is not None:  # only the ground moves a floor-standing object vertically
            base[2] = max(0.0, params.eps - (float(loss_fn.G.min()) - ground_height))
        return min_translation_search(loss_fn, base, _directions(params.search_directions, planar, yaw_only),
                                      step, reach, params.backtrack_steps, start)

    length = float(np.linalg.norm(x))
    if info["final_loss"] > 0.0 and params.search_directions > 0:
        found = search(params.search_reach)
        # none within reach: farther out, each doubling of the reach marched with a doubled step, before the
        # object is left inside its neighbours (released with them, it would fling them across the room)
        reach = params.search_reach
        for k in range(1, SEARCH_DOUBLINGS + 1):
            if found is not None:
                break
            found = search(2 * reach, start=reach, step=params.search_step * 2 ** k)
            reach *= 2
        if found is not None:
            x = found
            info.update(searched=True, final_loss=0.0)
    elif params.search_directions > 0 and length > max(params.rotate_over, params.search_step):
        found = search(length)  # a shorter way out than the gradient's
        if found is not None and float(np.linalg.norm(found)) < length:
            x = found
            info["searched"] = True
    info["rotation"] = [0.0, 0.0, 0.0]
    info["pivot"] = [float(v) for v in loss_fn.pivot]
    if params.rotate_over > 0 and (info["final_loss"] > 0.0 or float(np.linalg.norm(x)) > params.rotate_over):
        xr, wr, rinfo = _rigid_solve(loss_fn, params)
        radius = rinfo["radius"]
        cost_t = float(np.linalg.norm(x)) if info["final_loss"] == 0.0 else np.inf
        cost_r = float(np.linalg.norm(xr) + radius * np.linalg.norm(wr))
        if rinfo["final_loss"] == 0.0 and cost_r < cost_t \
                and np.degrees(np.linalg.norm(wr)) <= params.max_rotation:
            x = xr
            info.update(rotation=[float(v) for v in wr], final_loss=0.0, iterations=info["iterations"]
                        + rinfo["iterations"])
    info.update(context=sorted(loss_fn.used), seconds=time.perf_counter() - t0)
    return x, info


def _rigid_solve(loss_fn: "_Loss", params: PenetrationParams) -> tuple[np.ndarray, np.ndarray, dict]:
    """Minimise the clearance loss over a translation and a rotation about ``loss_fn.pivot`` (module notes).

    Returns
    -------
    x : (3,) float, w : (3,) float rotation vector (rad), info : ``iterations``, ``final_loss``, ``radius`` (m)
    """
    import torch

    radius = float(torch.sqrt(((loss_fn.P - loss_fn.pivot) ** 2).sum(dim=1).mean()))
    radius = max(radius, 1e-3)

    def loss6(v):
        return loss_fn(v[:3], v[3:] / radius)

    v, info = minimize_hinge(loss6, (6,), params.lr, params.max_iterations, params.backtrack_steps, "steepest_joint")
    info["radius"] = radius
    w = v[3:] / radius
    if loss_fn.yaw_only:
        w = w * np.array([0.0, 0.0, 1.0])
    return v[:3], w, info


def _directions(n: int, planar: bool, supported: bool) -> np.ndarray:
    """The search's directions: :func:`search_directions`, without the downward ones for an object supported
    from below (clearing an overlap downwards would put it into or under its supporter)."""
    d = search_directions(n, planar)
    return d[d[:, 2] >= 0.0] if supported and not planar else d


def search_directions(n: int, planar: bool = False) -> np.ndarray:
    """``n`` unit directions (n, 3) spread evenly: over the sphere (a Fibonacci lattice), or over the horizontal
    circle when ``planar``."""
    k = np.arange(n, dtype=float)
    if planar:
        a = 2.0 * np.pi * k / max(n, 1)
        return np.stack([np.cos(a), np.sin(a), np.zeros(n)], axis=1)
    z = 1.0 - 2.0 * (k + 0.5) / n
    r = np.sqrt(np.clip(1.0 - z * z, 0.0, None))
    a = np.pi * (3.0 - np.sqrt(5.0)) * k
    return np.stack([r * np.cos(a), r * np.sin(a), z], axis=1)


def directions_toward(axis, min_dot: float, n: int) -> np.ndarray:
    """``axis`` (3,) made unit, then those of the ``n`` :func:`search_directions` over the sphere whose component
    along it is at least ``min_dot``: (k, 3), the axis first (the searches that may only go one way: up, out from a
    wall)."""
    a = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    d = search_directions(n)
    return np.vstack([a, d[d @ a >= min_dot]])


def min_translation_search(loss_fn: Callable, base: np.ndarray, directions: np.ndarray, step: float, reach: float,
                           bisect_steps: int, start: float = 0.0) -> np.ndarray | None:
    """The smallest translation ``base + t d`` (over the unit ``directions`` (k, 3), ``t`` in steps of ``step`` up
    to ``reach``, beyond ``start``) at which ``loss_fn`` is exactly zero, bisected back to the zero-loss boundary.

    Every direction is marched out together, so the first zero found is the nearest one (to within ``step``);
    the march never stops inside a local minimum of the loss, where gradient steps stall.

    Parameters
    ----------
    loss_fn
        ``loss_fn(x) -> scalar tensor`` for a float64 tensor ``x`` (3,).
    base : (3,) float
        Where the rays start (e.g. the lift out of the ground).
    directions : (k, 3) float
    step, reach
        March step and farthest ``t`` (m).
    bisect_steps
        Bisection steps between the last positive and the first zero ``t``.
    start
        ``t`` already marched (m, a search resumed farther out with a coarser step): the march starts one step
        beyond it, and ``base`` itself is not tested again.

    Returns
    -------
    (3,) float translation, or ``None`` when no ray clears within ``reach``.
    """
    import torch

    def loss(v: np.ndarray) -> float:
        with torch.no_grad():
            return float(loss_fn(torch.as_tensor(v, dtype=torch.float64)))

    base = np.asarray(base, dtype=float)
    if start <= 0.0 and loss(base) == 0.0:
        return base
    n_steps = int(np.ceil((reach - start) / step))
    for i in range(1, n_steps + 1):
        t = min(start + i * step, reach)
        for d in directions:
            if loss(base + t * d) == 0.0:
                lo, hi = max(t - step, start), t
                for _ in range(bisect_steps):
                    mid = 0.5 * (lo + hi)
                    if loss(base + mid * d) == 0.0:
                        hi = mid
                    else:
                        lo = mid
                return base + hi * d
    return None


#: :func:`upward_clearance`: the least upward component of the directions it tries besides straight up (sin 15 deg).
UPWARD_MIN_Z = 0.26


def upward_clearance(active: SdfBody, context: list[SdfBody], ground_height: float | None,
                     params: PenetrationParams, planes=(), reach: float = 0.6) -> np.ndarray | None:
    """The shortest move up and out of an overlap, then straight down to where the object rests: (3,) m or ``None``.

    Straight up first, then the upward ones of ``2 params.search_directions`` directions over the sphere (at
    least :data:`UPWARD_MIN_Z` up), are marched out together (:func:`min_translation_search`, to within
    ``search_step``, bisected, at most ``reach``); from the first clear point the object is lowered straight down
    while the loss stays exactly zero (to ``search_step``, then bisected), so it ends on whatever lies under it
    there, clear by ``params.eps``: a box standing in a crate, read as on the floor (the input had the crate
    floating), overlaps the crate once the crate is lowered; it goes 3 cm up and sideways to rest on the crate's
    floor instead of 15 cm sideways along the floor. ``None`` when no direction clears within ``reach``.
    """
    loss_fn = _Loss(active, context, ground_height, params.eps, params.ground_extreme_points, planes)
    up = directions_toward((0.0, 0.0, 1.0), UPWARD_MIN_Z, 2 * max(params.search_directions, 1))
    found = min_translation_search(loss_fn, np.zeros(3), up, params.search_step, reach, params.backtrack_steps)
    if found is None:
        return None
    drop = max_clear_drop(loss_fn, found, params.search_step, max(float(found[2]), 0.0), params.backtrack_steps)
    return found - np.array([0.0, 0.0, drop])


def overlaps_deeper(active: SdfBody, context: list[SdfBody], tol: float, extreme_points: bool = True) -> bool:
    """Whether a surface sample of ``active`` lies deeper than ``tol`` (m) inside one of ``context``, or one of
    theirs inside it (the clearance hinge of :class:`_Loss` at ``eps = -tol``, at the current poses)."""
    import torch

    with torch.no_grad():
        return float(_Loss(active, context, None, -tol, extreme_points)(torch.zeros(3, dtype=torch.float64))) > 0.0


def fixture_clearance(active: SdfBody, context: list[SdfBody], ground_height: float | None,
                      params: PenetrationParams, outward: np.ndarray | None = None) -> np.ndarray | None:
    """The shortest translation (3,) m that takes a fixed object clear of other fixed ones, never against
    ``outward``.

    Objects fixed to a wall or the ceiling are kept where the input put them, and inputs put them through each
    other: a curtain through the window it hangs in front of, two posters through each other. The move is the
    smallest clearing one (by ``params.eps``; :func:`min_translation_search` over ``outward`` first, then the
    ``2 params.search_directions`` directions over the sphere, to within ``search_step``, bisected, at most
    ``search_reach``) among the directions with no component against ``outward`` (the holder's normal, into the
    room): out in front of the other object, or sideways along the wall. The ground term keeps it out of the floor
    (a floor-length curtain moved down through it is no nearer to the photo).

    Parameters
    ----------
    active
        The fixed object to move.
    context
        The fixed objects placed before it.
    ground_height
        Height of the ground plane, or ``None`` for no ground.
    params
        Search settings (``eps``, ``search_directions``, ``search_step``, ``search_reach``, ``backtrack_steps``).
    outward : (3,) float, optional
        Unit direction the object may not move against (``None``: any direction).

    Returns
    -------
    (3,) float translation (zero when already clear by ``eps``), or ``None`` when no direction clears within
    ``search_reach``.
    """
    n = 2 * max(params.search_directions, 1)
    directions = search_directions(n) if outward is None else directions_toward(outward, 0.0, n)
    loss_fn = _Loss(active, context, ground_height, params.eps, params.ground_extreme_points)
    return min_translation_search(loss_fn, np.zeros(3), directions, params.search_step, params.search_reach,
                                  params.backtrack_steps)


def max_clear_drop(loss_fn: Callable, start: np.ndarray, step: float, reach: float, bisect_steps: int) -> float:
    """How far (m) a clear translation ``start`` (3,) can be lowered straight down with ``loss_fn`` still exactly
    zero: marched in steps of ``step`` up to ``reach``, then bisected between the last clear and the first
    overlapping height."""
    import torch

    def clear(t: float) -> bool:
        with torch.no_grad():
            return float(loss_fn(torch.as_tensor(start - np.array([0.0, 0.0, t]), dtype=torch.float64))) == 0.0

    lo, t = 0.0, 0.0
    while t < reach:
        t = min(t + step, reach)
        if not clear(t):
            hi = t
            for _ in range(bisect_steps):
                mid = 0.5 * (lo + hi)
                if clear(mid):
                    lo = mid
                else:
                    hi = mid
            return lo
        lo = t
    return lo


def minimize_hinge(loss_fn: Callable, shape: tuple[int, ...], lr: float, max_iterations: int,
                   backtrack_steps: int, optimizer: str = "adam") -> tuple[np.ndarray, dict]:
    """Adam on a translation (or several) from zero until a hinge loss is exactly zero, then back to its boundary.

    Adam stops at the first iterate with zero loss (its momentum would otherwise carry the
    objects further away); with ``backtrack_steps`` > 0 the last step is then bisected back
    towards the last iterate with a positive loss, so the result ends at the clearance instead of
    overshooting it.

    Parameters
    ----------
    loss_fn
        ``loss_fn(x) -> scalar tensor`` for a float64 tensor ``x`` of ``shape``; zero when clear.
    shape
        Shape of the translation tensor: ``(3,)`` for one object, ``(k, 3)`` for ``k`` objects.
    lr, max_iterations, backtrack_steps
        Learning rate (step length for ``steepest``), iteration cap and bisection steps.
    optimizer
        A key of :data:`OPTIMIZERS`, or ``steepest_joint`` (:class:`SteepestJointState`).

    Returns
    -------
    x : float array of ``shape``
        The translation(s).
    info : dict
        ``iterations``, ``initial_loss``, ``final_loss``, ``backtracked``.
    """
    import torch

    x = torch.zeros(shape, dtype=torch.float64, requires_grad=True)
    opt = _SOLVERS[optimizer](x, lr)
    loss = loss_fn(x)
    initial = float(loss.detach())
    iterations = 0
    x_prev = x.detach().clone()
    while float(loss.detach()) > 0.0 and iterations < max_iterations:
        loss.backward()
        x_prev = x.detach().clone()
        opt.step()
        iterations += 1
        loss = loss_fn(x)
    final_x = x.detach().clone()
    backtracked = 0
    if iterations and float(loss.detach()) == 0.0 and backtrack_steps:
        lo, hi = x_prev, final_x  # loss(lo) > 0, loss(hi) == 0
        with torch.no_grad():
            for _ in range(backtrack_steps):
                mid = 0.5 * (lo + hi)
                if float(loss_fn(mid)) == 0.0:
                    hi = mid
                else:
                    lo = mid
                backtracked += 1
        final_x = hi
    with torch.no_grad():
        final = float(loss_fn(final_x))
    info = {"iterations": iterations, "initial_loss": initial, "final_loss": final, "backtracked": backtracked}
    return final_x.numpy().astype(float), info
