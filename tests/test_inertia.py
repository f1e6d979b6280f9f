"""Mass properties (phiscene.inertia.rigid_props). Oracle: the solid box's closed-form inertia, m (b^2 + c^2) / 12."""

from __future__ import annotations

import numpy as np
import trimesh

from phiscene import inertia
from phiscene.inertia import rigid_props


def test_box_props_are_closed_form_at_every_scale_and_a_caller_cannot_change_the_remembered_ones():
    box = trimesh.creation.box([0.4, 0.2, 0.1])
    for scale in (1.0, 2.0, 1.0):  # the second 1.0 is answered from memory
        p = rigid_props(box, None, density=500.0, scale=scale)
        a, b, c = 0.4 * scale, 0.2 * scale, 0.1 * scale
        mass = 500.0 * a * b * c
        assert np.isclose(p.mass, mass, rtol=1e-12)
        expected = sorted([mass * (b * b + c * c) / 12, mass * (a * a + c * c) / 12, mass * (a * a + b * b) / 12])
        np.testing.assert_allclose(p.principal_moments, expected, rtol=1e-10)
        np.testing.assert_allclose(p.com, 0.0, atol=1e-12)
        p.com[:] = 9.0  # a caller's change stays in its own copy
        p.principal_moments[:] = -1.0
    assert rigid_props(box, None, 500.0).com.tolist() == [0.0, 0.0, 0.0]


def test_remembered_props_follow_every_input():
    """A different density, centre of mass or mesh is a different entry; the same inputs are one entry."""
    inertia._PROPS.clear()
    box = trimesh.creation.box([0.4, 0.2, 0.1])
    first = rigid_props(box, None, 500.0)
    again = rigid_props(box.copy(), None, 500.0)
    assert again.mass == first.mass and np.array_equal(again.principal_axes, first.principal_axes)
    assert len(inertia._PROPS) == 1
    assert np.isclose(rigid_props(box, None, 1000.0).mass, 2 * first.mass)
    moved = rigid_props(box, None, 500.0, com=np.array([0.1, 0.0, 0.0]))
    np.testing.assert_allclose(moved.com, [0.1, 0.0, 0.0])
    assert moved.source.endswith("declared centre of mass")
    longer = box.copy()
    longer.vertices[longer.vertices[:, 0] > 0, 0] += 0.1  # 0.5 m long
    assert np.isclose(rigid_props(longer, None, 500.0).mass, 500.0 * 0.5 * 0.2 * 0.1)
    assert len(inertia._PROPS) == 4
