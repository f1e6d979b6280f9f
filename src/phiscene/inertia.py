"""Rigid-body mass properties of an object at a given uniform scale."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import trimesh

from phiscene.errors import InputError
from phiscene.memo import Memo
from phiscene.tolerances import TOL


@dataclass(frozen=True)
class RigidProps:
    """Mass properties in the object's scaled local frame.

    Attributes
    ----------
    mass : float
        kg.
    com : (3,) float
        Centre of mass, scaled local frame (m).
    principal_moments : (3,) float
        Principal moments of inertia about the COM (kg m^2).
    principal_axes : (3, 3) float
        Rotation whose columns are the principal axes in the local frame.
    source : str
        ``"mesh"`` (closed mesh), ``"proxies"`` (union of convex hulls) or ``"hull"``; with
        ``", declared centre of mass"`` appended when one was given.
    """

    mass: float
    com: np.ndarray
    principal_moments: np.ndarray
    principal_axes: np.ndarray
    source: str


#: Mass properties computed in this process, by :func:`_props_key` (:func:`rigid_props`); least recently used
#: evicted beyond 512 entries, more than the objects of a large scene, each at the scales it is simulated at.
_PROPS: "Memo[RigidProps]" = Memo(512)


def _props_key(mesh: trimesh.Trimesh, hulls: list[np.ndarray] | None, density: float, scale: float,
               com: np.ndarray | None) -> tuple:
    """Every input of :func:`rigid_props`: the mesh and hulls by their content hashes
    (:func:`phiscene.meshes.mesh_hash`, :func:`phiscene.proxies.hulls_hash`), the numbers as given."""
    from phiscene.meshes import mesh_hash
    from phiscene.proxies import hulls_hash

    return (mesh_hash(mesh), hulls_hash(hulls) if hulls else None, float(density), float(scale),
            None if com is None else tuple(np.asarray(com, dtype=float).tolist()))


def rigid_props(mesh: trimesh.Trimesh, hulls: list[np.ndarray] | None, density: float,
                scale: float = 1.0, com: np.ndarray | None = None) -> RigidProps:
    """Mass, centre of mass and inertia of an object (remembered in this process: a grounding asks for the same
    object's at every world it builds).

    A closed (watertight, positive-volume) mesh is integrated exactly; an open
    or multi-shell one falls back to the union of its convex proxies.
    A declared centre of mass (:attr:`phiscene.scene.SceneObject.com`) keeps the mass and moves the centre there;
    the inertia is the uniform solid's about that point (parallel-axis theorem), the inertia of a body whose
    extra mass sits near it.

    Parameters
    ----------
    mesh
        Local-frame mesh (unscaled).
    hulls
        Convex proxies, each ``(v, 3)`` local vertices (unscaled); used when the mesh is not closed.
    density
        kg/m^3.
    scale
        Uniform scale of the pose.
    com : (3,) float, optional
        Declared centre of mass, local frame (unscaled); ``None``: the uniform solid's.
    """
    p = _PROPS.get(_props_key(mesh, hulls, density, scale, com),
                   lambda: _rigid_props(mesh, hulls, density, scale, com))
    return replace(p, com=p.com.copy(), principal_moments=p.principal_moments.copy(),
                   principal_axes=p.principal_axes.copy())


def _rigid_props(mesh: trimesh.Trimesh, hulls: list[np.ndarray] | None, density: float, scale: float,
                 com: np.ndarray | None) -> RigidProps:
    """:func:`rigid_props`, computed."""
    body = None
    source = "mesh"
    if mesh.is_volume and mesh.volume > TOL.min_volume:
        body = mesh
    elif hulls:
        body = trimesh.util.concatenate([trimesh.convex.convex_hull(h) for h in hulls])
        source = "proxies"
    else:
        body = mesh.convex_hull
        source = "hull"
    m = body.copy()
    m.apply_scale(scale)
    m.density = density
    volume = float(m.volume)
    if not np.isfinite(volume) or volume <= TOL.min_volume * scale**3:
        raise InputError(None, None, f"object has no usable volume ({volume:.3g} m^3) for mass properties")
    inertia = np.asarray(m.moment_inertia)
    centre = np.asarray(m.center_mass, dtype=float)
    if com is not None:
        d = np.asarray(com, dtype=float) * scale - centre
        inertia = inertia + float(m.mass) * (float(d @ d) * np.eye(3) - np.outer(d, d))
        centre = centre + d
        source = f"{source}, declared centre of mass"
    moments, axes = np.linalg.eigh(0.5 * (inertia + inertia.T))
    if np.linalg.det(axes) < 0:
        axes[:, 0] *= -1
    moments = np.maximum(moments, 1e-12)
    return RigidProps(mass=float(m.mass), com=centre, principal_moments=moments,
                      principal_axes=axes, source=source)
