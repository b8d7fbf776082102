"""Write generated motion on a user's BVH skeleton (the data.bvh_dir database).

The hierarchy, offsets, channel layout and end sites are copied from the first file of the
folder; the root position channels get the generated root position (file units), every
rotation channel the generated local rotation in that joint's own Euler order. Position
channels of non-root joints (rare) are written as the joint's OFFSET.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from charctl.errors import CharctlError
from charctl.motion.bvh import write_bvh_file


def write_user_bvh(template, root_pos: np.ndarray, local_rot: np.ndarray, path: str | Path, fps: float) -> Path:
    """root_pos (T, 3) in the template's file units, local_rot (T, J, 4) xyzw (joint 0 = root world)."""
    J = len(template.names)
    children: dict[int, list[int]] = {j: [] for j in range(J)}
    for j in range(J):
        if template.parents[j] >= 0:
            children[int(template.parents[j])].append(j)
    lines = ["HIERARCHY"]

    def emit(j: int, depth: int) -> None:
        pad = "\t" * depth
        lines.append(f"{pad}{'ROOT' if template.parents[j] < 0 else 'JOINT'} {template.names[j]}")
        lines.append(pad + "{")
        o = template.offsets[j]
        lines.append(f"{pad}\tOFFSET {o[0]:.6f} {o[1]:.6f} {o[2]:.6f}")
        ch = template.channels[j]
        if ch:
            lines.append(f"{pad}\tCHANNELS {len(ch)} {' '.join(ch)}")
        for c in children[j]:
            emit(c, depth + 1)
        if j in template.end_sites:
            e = template.end_sites[j]
            lines.extend(
                [f"{pad}\tEnd Site", pad + "\t{", f"{pad}\t\tOFFSET {e[0]:.6f} {e[1]:.6f} {e[2]:.6f}", pad + "\t}"]
            )
        lines.append(pad + "}")

    for root in [j for j in range(J) if template.parents[j] < 0]:
        emit(root, 0)
    T = root_pos.shape[0]
    columns = []
    for j, ch in enumerate(template.channels):  # one block of columns per joint (file layout)
        pos_src = root_pos if template.parents[j] < 0 else np.broadcast_to(template.offsets[j], (T, 3))
        rot_axes = "".join(c[0].upper() for c in ch if c.endswith("rotation"))
        if rot_axes and len(rot_axes) != 3:
            raise CharctlError(
                f"BVH export: joint {template.names[j]!r} has {len(rot_axes)} rotation channels (only 3 are supported)"
            )
        euler = Rotation.from_quat(local_rot[:, j]).as_euler(rot_axes, degrees=True) if rot_axes else None
        k = 0
        for c in ch:
            if c.endswith("position"):
                columns.append(pos_src[:, "XYZ".index(c[0].upper())])
            else:
                columns.append(euler[:, k])
                k += 1
    data = np.column_stack(columns) if columns else np.zeros((T, 0))
    return write_bvh_file(path, lines, data, 1.0 / fps)
