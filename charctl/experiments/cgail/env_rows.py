"""The cgail env's row subsets and skill tables (`env.CgailEnv`, `env_arrays`).

A data-dependent subset of the envs (the envs a reset writes, the envs scored against their clip's closest
frame) in one of two forms with one interface (`pick` the rows values are computed for, `put` them back):
`MaskRows`, an (N,) bool mask and `torch.where` (no host round trip: the form on a GPU), or `IndexRows`, the
subset's integer ids, numpy or torch (on the CPU, where reading the mask costs nothing: only those rows are
computed). `pad_clip_arrays` / `pad_skill_tables` stack per-skill clip arrays into one padded array / tensor.
"""

from __future__ import annotations

import numpy as np
import torch


class MaskRows:
    """A data-dependent subset of the envs (the envs a reset writes, the envs scored against their closest clip
    frame) as its (N,) bool mask: values computed for every env and written where the mask is set
    (`torch.where`), so nothing is read back to the host (the form on a GPU)."""

    def __init__(self, mask: torch.Tensor):
        self.mask = self.ids = mask

    def pick(self, x: torch.Tensor) -> torch.Tensor:
        """The rows of per-env `x` the values are computed for: all of them."""
        return x

    def put(self, old: torch.Tensor, new: torch.Tensor | float | bool) -> torch.Tensor:
        """`old` with `new` written in the subset's rows (`new` per env, or one value for all)."""
        if not isinstance(new, torch.Tensor):
            return torch.where(self.mask, torch.full_like(old, new), old)
        return torch.where(self.mask.view(-1, *[1] * (new.dim() - 1)), new, old)


class IndexRows:
    """The same subset as its integer ids, a numpy array or a tensor (on the CPU, where reading the mask costs
    nothing): values computed for those rows only and written into a copy (arrays handed out earlier, e.g. the
    last step's state, do not change). Every quantity is a row-wise function of its
    env, so the written values are `MaskRows`' (up to the last bit of a transcendental function, whose
    vectorised and scalar kernels may round differently: ~1e-16 rad on a heading)."""

    def __init__(self, ids):
        self.ids = ids  # (n,) integer ids

    def pick(self, x: torch.Tensor) -> torch.Tensor:
        """The subset's rows of per-env `x`."""
        return x[self.ids]

    def put(self, old: torch.Tensor, new: torch.Tensor | float | bool) -> torch.Tensor:
        """A copy of `old` with `new` (per subset row, or one value) written in the subset's rows, in the result
        dtype `torch.where` (`np.where`) would give."""
        if isinstance(old, np.ndarray):
            out = old.astype(np.result_type(new, old)) if isinstance(new, np.ndarray) else old.copy()
            out[self.ids] = new
            return out
        if not isinstance(new, torch.Tensor):
            return old.clone().index_fill_(0, self.ids, new)
        out = old.to(torch.result_type(new, old), copy=True)
        out[self.ids] = new
        return out


def pad_clip_arrays(arrays: list[np.ndarray]) -> np.ndarray:
    """(K, max_len, ...) array of per-skill arrays, each padded with its last row."""
    longest = max(len(a) for a in arrays)
    return np.stack([np.concatenate([a, np.repeat(a[-1:], longest - len(a), axis=0)]) for a in arrays])


def pad_skill_tables(arrays: list[np.ndarray], device: torch.device, dtype=torch.float32) -> torch.Tensor:
    """`pad_clip_arrays` as a tensor on `device`."""
    return torch.as_tensor(pad_clip_arrays(arrays), dtype=dtype, device=device)
