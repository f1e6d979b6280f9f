"""Rigid-body simulation back ends: pybullet (settling, drift) and MuJoCo (cross-simulator check)."""
