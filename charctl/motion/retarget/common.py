"""Constants, the result type and the humanoid's rest-pose numbers shared by the retargeting steps (metres,
seconds, y-up)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from charctl.motion.bvh_any import SourceMotion
from charctl.motion.clip import Clip
from charctl.motion.skeleton import load_skeleton

DEFAULT_FPS = 60.0
# planted-flat frames (step 2): the ankle this close to the clip's lowest ankle level and this slow
CONTACT_HEIGHT = 0.025  # m
CONTACT_SPEED = 0.15  # m/s (scaled source): the flat part of a stance, not heel strike / toe-off
CONTACT_MIN_S = 0.05  # s: contact or stance runs and gaps shorter than this are dropped / filled
BLEND_S = 0.1  # s: the offset that planting a foot makes fades out over this after the stance
STANCE_HEIGHT = 0.02  # m: lowest sole corner at most this high ...
STANCE_SPEED = 0.5  # m/s ... and slower than this: a stance frame (the foot is planted)
PLANT_HEIGHT = 0.01  # m: sole corners this low in two consecutive stance frames are held still
REFINE_TOL = 0.005  # m: end-effector residual after two-bone IK that sends a frame to mink
GROUND_TOL = 0.005  # m: a body this far under the ground sends a frame to mink
_Y = np.array([0.0, 1.0, 0.0])
_Z = np.array([0.0, 0.0, 1.0])
SIDES = ("right", "left")


@dataclass
class Retargeted:
    """A retargeted clip and the data behind its quality report (all at the clip's rate, metres, y-up)."""

    clip: Clip
    source: SourceMotion  # at the clip's rate, scaled and turned like the clip (pos in humanoid metres)
    scale: float  # humanoid leg / source leg (metres / metres)
    arm_scale: float  # humanoid arm / scaled source arm
    scaled_source: dict[str, np.ndarray]  # end effector -> (T, 3) where the scaled source puts it
    targets: dict[str, np.ndarray]  # end effector -> (T, 3) the IK targets (contacts held, above ground)
    contacts: np.ndarray  # (T, 2) bool, right/left foot planted (stance frames)
    refined_frames: int  # frames mink refined
    refine_iterations: int
    timings: dict[str, float] = field(default_factory=dict)  # seconds per stage
    notes: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class RetargetHumanoid:
    """The humanoid's rest-pose numbers the retargeting uses."""

    skel: object
    idx: dict[str, int]
    thigh: float
    shin: float
    upper_arm: float
    forearm: float
    foot_corners: np.ndarray  # (8, 3) sole box corners in the foot frame
    sole: float  # ankle height over a flat sole
    hand_radius: float  # the wrist's collision sphere

    @property
    def leg(self) -> float:
        return self.thigh + self.shin

    @property
    def arm(self) -> float:
        return self.upper_arm + self.forearm


def humanoid() -> RetargetHumanoid:
    skel = load_skeleton()
    idx = {n: i for i, n in enumerate(skel.names)}
    off = skel.offsets
    g = skel.geoms[idx["right_ankle"]]
    half, centre = np.array(g.size), np.array(g.pos)
    corners = centre + half * np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
    return RetargetHumanoid(
        skel,
        idx,
        float(np.linalg.norm(off[idx["right_knee"]])),
        float(np.linalg.norm(off[idx["right_ankle"]])),
        float(np.linalg.norm(off[idx["right_elbow"]])),
        float(np.linalg.norm(off[idx["right_wrist"]])),
        corners,
        float(-corners[:, 1].min()),
        float(skel.geoms[idx["right_wrist"]].size[0]),
    )
