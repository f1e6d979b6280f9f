"""Reference alignment: does a method's scene still look like the reference image?

The paper scores alignment with the reference image by CLIP image similarity.
No CLIP weights are reachable here, so phiscene uses a stricter and more
interpretable stand-in (docs/DESIGN.md §5): the scene is rendered from the reference
camera with the benchmark renderer (:func:`phiscene.render.render_instance_mask`)
and each object's *visible* mask is compared with its mask in the reference
instance segmentation.

Matching
    An object's reference mask is the set of ``reference/segmentation.png``
    pixels whose colour equals the object's ``color`` (``scene.json``). The
    method scene keeps the ids and colours of the initial scene; an object of
    the method scene without a colour takes the initial scene's. Reference
    pixels of any other non-black colour are counted in
    ``unmatched_reference_pixels`` and otherwise ignored.

Mask IoU
    Per object ``|R ∩ S| / |R ∪ S|`` of its reference mask ``R`` and rendered
    mask ``S`` (both visible masks, so occlusion counts). An object absent from
    both (fewer than ``min_pixels`` pixels in each) is skipped (``mask_iou`` is
    ``None``); an object absent from exactly one scores 0. The scene value is
    the mean over the scored objects (``None`` when none is scored).

Pose change from the initial scene
    Per object, translation (m) of its *anchor* point and rotation angle (deg)
    of the relative rotation between its initial and its final pose (uniform
    scale removed, :func:`phiscene.transforms.decompose`). The anchor is the
    mesh's centre of mass (``anchor="com"``, uniform density, via trimesh's
    ``center_mass``; load_mesh guarantees positive volume) mapped by each pose,
    or the pose origin (``anchor="origin"``), which depends on where the mesh's
    local frame happens to be. ``scale_ratio`` is the final over the initial
    uniform scale. Scene values are means over all objects.

Units: metres, degrees, pixels.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from phiscene.errors import InputError
from phiscene.params import Params
from phiscene.scene import Scene, SceneObject
from phiscene.transforms import decompose, rotation_angle, transform_points

#: Reference sources.
REFERENCES = ("segmentation", "gt_render")
#: Anchor points of the translation change.
ANCHORS = ("com", "origin")


@dataclass(frozen=True)
class AlignmentParams(Params):
    """Parameters of the reference alignment metrics (config ``metrics.alignment``).

    Attributes
    ----------
    reference
        Where the reference masks come from: ``"segmentation"`` (default) reads
        ``reference_dir/segmentation.png``; ``"gt_render"`` re-renders the
        ground-truth scene ``reference_dir/../gt/scene.json`` (the benchmark
        layout) from the reference camera and matches objects by id, a check
        that needs no image decoding.
    anchor
        Point whose displacement is the translation change: ``"com"`` (default,
        the mesh's uniform-density centre of mass) or ``"origin"`` (the pose's
        translation).
    min_pixels
        An object covering fewer pixels than this in a mask is absent from it
        (default 1: absent means no pixel at all).
    """

    _label = "alignment parameters"
    _coerce = {"min_pixels": int}

    reference: str = "segmentation"
    anchor: str = "com"
    min_pixels: int = 1

    def __post_init__(self) -> None:
        if self.reference not in REFERENCES:
            raise ValueError(f"alignment reference must be one of {list(REFERENCES)}, got {self.reference!r}")
        if self.anchor not in ANCHORS:
            raise ValueError(f"alignment anchor must be one of {list(ANCHORS)}, got {self.anchor!r}")
        if int(self.min_pixels) < 1:
            raise ValueError(f"alignment min_pixels must be >= 1, got {self.min_pixels!r}")


def mask_iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two boolean masks.

    Parameters
    ----------
    a, b : (H, W) bool
        Masks of the same shape.

    Returns
    -------
    float
        ``|a ∩ b| / |a ∪ b|`` in [0, 1]; two empty masks are identical and give 1.
    """
    a, b = np.asarray(a, dtype=bool), np.asarray(b, dtype=bool)
    if a.shape != b.shape:
        raise ValueError(f"mask shapes differ: {a.shape} vs {b.shape}")
    union = int(np.count_nonzero(a | b))
    if union == 0:
        return 1.0
    return int(np.count_nonzero(a & b)) / union


def _where(scene: Scene) -> str | Path:
    return scene.source if scene.source is not None else "<scene in memory>"


def _check_ids(scene: Scene, initial: Scene) -> None:
    if sorted(scene.ids) != sorted(initial.ids):
        missing = sorted(set(initial.ids) - set(scene.ids))
        extra = sorted(set(scene.ids) - set(initial.ids))
        raise InputError(_where(scene), "objects", f"ids differ from the initial scene {_where(initial)} "
                         f"(missing {missing}, extra {extra})")


def object_colors(scene: Scene, initial: Scene) -> dict[str, tuple[int, int, int]]:
    """Segmentation colour of every object of ``scene`` (its own ``color``, else the initial scene's).

    Raises
    ------
    InputError
        An object without a colour in both scenes, a colour that differs from the
        initial scene's, or two objects sharing a colour.
    """
    out: dict[str, tuple[int, int, int]] = {}
    for i, o in enumerate(scene.objects):
        init = initial.get(o.id).color
        color = o.color if o.color is not None else init
        if color is None:
            raise InputError(_where(scene), f"objects[{i}].color",
                             "missing here and in the initial scene; needed to match the reference segmentation")
        color = tuple(int(c) for c in color)
        if init is not None and color != tuple(int(c) for c in init):
            raise InputError(_where(scene), f"objects[{i}].color",
                             f"{list(color)} differs from the initial scene's {list(init)}")
        out[o.id] = color
    seen: dict[tuple[int, int, int], str] = {}
    for oid, c in out.items():
        if c in seen:
            raise InputError(_where(scene), "objects", f"{seen[c]} and {oid} share the colour {list(c)}")
        if c == (0, 0, 0):
            raise InputError(_where(scene), "objects", f"{oid} has colour [0, 0, 0], the segmentation background")
        seen[c] = oid
    return out


def reference_masks(reference_dir: Path, colors: dict[str, tuple[int, int, int]], camera: dict,
                    params: AlignmentParams) -> tuple[dict[str, np.ndarray], int]:
    """Reference mask of every object.

    Parameters
    ----------
    reference_dir
        Folder with ``segmentation.png`` (and, for ``gt_render``, the benchmark layout around it).
    colors
        Object id -> segmentation colour.
    camera
        The reference camera (its size must match the segmentation).
    params
        Which reference to use.

    Returns
    -------
    masks
        Object id -> (H, W) bool.
    unmatched
        Number of non-black reference pixels whose colour is no object's (0 for ``gt_render``).
    """
    H, W = int(camera["height"]), int(camera["width"])
    if params.reference == "gt_render":
        from phiscene.render import render_instance_mask
        from phiscene.scene import load_scene

        gt_path = Path(reference_dir).parent / "gt" / "scene.json"
        if not gt_path.is_file():
            raise InputError(gt_path, None, "missing; alignment reference 'gt_render' needs the GT scene")
        gt = load_scene(gt_path)
        labels = render_instance_mask(gt, camera)
        index = {oid: k for k, oid in enumerate(gt.ids)}
        return {oid: labels == index.get(oid, -2) for oid in colors}, 0

    from phiscene.render import load_png

    seg_path = Path(reference_dir) / "segmentation.png"
    if not seg_path.is_file():
        raise InputError(seg_path, None, "reference segmentation not found")
    try:
        seg = load_png(seg_path)
    except Exception as exc:  # PIL raises several types for corrupt files
        raise InputError(seg_path, None, f"cannot read image ({type(exc).__name__}: {str(exc)[:120]})") from None
    if seg.shape[:2] != (H, W):
        raise InputError(seg_path, None, f"size {seg.shape[1]}x{seg.shape[0]} differs from camera.json's {W}x{H}")
    masks = {oid: np.all(seg == np.asarray(c, dtype=np.uint8), axis=2) for oid, c in colors.items()}
    covered = np.zeros((H, W), dtype=bool)
    for m in masks.values():
        covered |= m
    unmatched = int(np.count_nonzero(seg.any(axis=2) & ~covered))
    return masks, unmatched


def rendered_masks(scene: Scene, camera: dict) -> dict[str, np.ndarray]:
    """Visible mask (H, W) bool of every object of ``scene`` rendered from ``camera``, by id."""
    from phiscene.render import render_instance_mask

    labels = render_instance_mask(scene, camera)
    return {o.id: labels == k for k, o in enumerate(scene.objects)}


def anchor_point(obj: SceneObject, anchor: str) -> np.ndarray:
    """World position (3,) of ``obj``'s anchor: its centre of mass (``"com"``) or pose origin (``"origin"``)."""
    if anchor == "origin":
        return np.asarray(obj.pose, dtype=float)[:3, 3].copy()
    com_local = np.asarray(obj.mesh().center_mass, dtype=float)
    return transform_points(obj.pose, com_local[None])[0]


def pose_change(obj: SceneObject, before: SceneObject, anchor: str) -> dict:
    """Change of ``obj`` relative to ``before`` (the same object in the initial scene).

    Returns
    -------
    dict
        ``trans`` (m, anchor displacement), ``rot`` (deg, relative rotation angle), ``scale_ratio``.
    """
    Ra, _, sa = decompose(before.pose)
    Rb, _, sb = decompose(obj.pose)
    trans = float(np.linalg.norm(anchor_point(obj, anchor) - anchor_point(before, anchor)))
    return {"trans": trans, "rot": math.degrees(rotation_angle(Ra, Rb)), "scale_ratio": float(sb / sa)}


def alignment_metrics(scene: Scene, initial: Scene, reference_dir: Path, params: AlignmentParams) -> dict:
    """Reference alignment of ``scene`` (see the module docstring).

    Parameters
    ----------
    scene
        The method's scene (same ids as ``initial``).
    initial
        The initial scene the method started from.
    reference_dir
        Folder with ``camera.json`` and ``segmentation.png`` (benchmark ``reference/``).
    params
        Metric parameters.

    Returns
    -------
    dict
        ``mask_iou`` (mean over scored objects, or ``None``), ``pose_change_trans`` (m),
        ``pose_change_rot`` (deg), ``n_scored``, ``unmatched_reference_pixels``, ``params`` and
        ``objects``: id -> ``{"mask_iou", "pixels_reference", "pixels_render", "intersection",
        "pose_change_trans", "pose_change_rot", "scale_ratio"}``.

    Raises
    ------
    InputError
        Missing or malformed camera or segmentation, id or colour mismatches between the scenes.
    """
    from phiscene.render import read_camera

    reference_dir = Path(reference_dir)
    _check_ids(scene, initial)
    colors = object_colors(scene, initial)
    camera = read_camera(reference_dir / "camera.json")
    ref, unmatched = reference_masks(reference_dir, colors, camera, params)
    ren = rendered_masks(scene, camera)
    objects: dict[str, dict] = {}
    for o in scene.objects:
        r, s = ref[o.id], ren[o.id]
        n_ref, n_ren = int(np.count_nonzero(r)), int(np.count_nonzero(s))
        absent_ref, absent_ren = n_ref < params.min_pixels, n_ren < params.min_pixels
        if absent_ref and absent_ren:
            iou = None
        elif absent_ref or absent_ren:
            iou = 0.0
        else:
            iou = mask_iou(r, s)
        change = pose_change(o, initial.get(o.id), params.anchor)
        objects[o.id] = {"mask_iou": iou, "pixels_reference": n_ref, "pixels_render": n_ren,
                         "intersection": int(np.count_nonzero(r & s)), "pose_change_trans": change["trans"],
                         "pose_change_rot": change["rot"], "scale_ratio": change["scale_ratio"]}
    scored = [v["mask_iou"] for v in objects.values() if v["mask_iou"] is not None]
    return {
        "mask_iou": float(np.mean(scored)) if scored else None,
        "pose_change_trans": float(np.mean([v["pose_change_trans"] for v in objects.values()])),
        "pose_change_rot": float(np.mean([v["pose_change_rot"] for v in objects.values()])),
        "n_scored": len(scored),
        "unmatched_reference_pixels": unmatched,
        "params": asdict(params),
        "objects": objects,
    }
