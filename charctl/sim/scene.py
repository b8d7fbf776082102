"""The y-up ground scene every charctl MJCF shares: checker floor (the xz plane), sky, sun."""

from __future__ import annotations


def scene_assets(floor_size: float) -> str:
    """<asset> children: floor texture/material and the sky box."""
    return f"""    <texture name="grid" type="2d" builtin="checker" rgb1="0.82 0.84 0.86" rgb2="0.68 0.70 0.74"
             width="512" height="512"/>
    <material name="grid" texture="grid" texrepeat="{floor_size} {floor_size}" reflectance="0.05"/>
    <texture name="sky" type="skybox" builtin="gradient" rgb1="0.55 0.7 0.9" rgb2="0.95 0.95 1.0"
             width="256" height="256"/>"""


def scene_ground(floor_size: float, collides: bool = True) -> str:
    """<worldbody> children: the sun and the floor plane (normal +y); `collides` sets its conaffinity."""
    return f"""    <light name="sun" pos="2 6 3" dir="-0.3 -1 -0.4" directional="true" castshadow="true"/>
    <geom name="floor" type="plane" size="{floor_size} {floor_size} 0.1" quat="0.70710678 -0.70710678 0 0"
          material="grid" contype="0" conaffinity="{1 if collides else 0}"/>"""
