"""One code path for numpy arrays and torch tensors: the array-API namespace of an array and the
rotation module of its library.

Rules that both cgail backends apply (features, rewards, episode ends) are written once against the
Python array API standard (`array_api_compat` gives numpy and torch that namespace), so the CPU
backend runs them on numpy arrays and the on-device backend on torch tensors, where they stay on
the simulation's device. Quaternion helpers stay one module per array library
(`rotations` for numpy, `rotations_torch` for torch); `rotations_for` picks the one for an array.
"""

from __future__ import annotations

from types import ModuleType
from typing import Any, TypeAlias

import numpy as np
from array_api_compat import array_namespace
from array_api_compat import device as device_of  # noqa: F401  the device an array lives on ('cpu' for numpy)

Array: TypeAlias = Any  # a numpy ndarray or a torch Tensor (all arrays of one call of one kind)


def namespace(*arrays: Array) -> ModuleType:
    """The array-API namespace of `arrays` (numpy's or torch's, via array_api_compat)."""
    return array_namespace(*arrays)


def is_numpy(x: Array) -> bool:
    return isinstance(x, np.ndarray)


def rotations_for(x: Array) -> ModuleType:
    """`charctl.motion.rotations` for numpy arrays, `charctl.motion.rotations_torch` for torch tensors."""
    if is_numpy(x):
        from charctl.motion import rotations

        return rotations
    from charctl.motion import rotations_torch

    return rotations_torch
