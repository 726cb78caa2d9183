"""Torch views of the numpy training data (faceclean.datasets.dataset): map- and stream-style."""

from __future__ import annotations

from collections.abc import Iterator, Sequence

import numpy as np
import torch
from torch.utils.data import Dataset, IterableDataset, get_worker_info

from faceclean.datasets.dataset import Chunks, Take, batches, epoch_chunks

Batch = dict[str, torch.Tensor]  # noisy, truth (B, T, M) f32; times (B, T) f64; valid, observed


def to_tensors(chunks: Chunks) -> Batch:
    """The arrays of ``chunks`` as tensors (shared memory, no copy)."""
    return {k: torch.from_numpy(np.ascontiguousarray(v)) for k, v in vars(chunks).items()}


class ChunkDataset(Dataset):
    """Fixed chunks (validation, or one epoch), one chunk per item: dict of (T, ...) tensors.

    Works with a ``DataLoader`` and a ``DistributedSampler`` for data-parallel training.
    """

    def __init__(self, chunks: Chunks) -> None:
        self.tensors = to_tensors(chunks)

    def __len__(self) -> int:
        return len(self.tensors["noisy"])

    def __getitem__(self, i: int) -> Batch:
        return {k: v[i] for k, v in self.tensors.items()}


class EpochStream(IterableDataset):
    """Fresh training batches every epoch (call ``set_epoch``), already batched.

    Use with ``DataLoader(stream, batch_size=None)``. Batches are dealt round-robin to
    ``world_size`` ranks (data-parallel) and then to the loader's workers; every rank
    gets the same number, so collective steps stay in step.
    """

    def __init__(
        self,
        takes: Sequence[Take],
        seed: int,
        batch_size: int,
        *,
        rank: int = 0,
        world_size: int = 1,
        **kwargs,
    ) -> None:
        self.takes, self.seed, self.batch_size = list(takes), seed, batch_size
        self.rank, self.world_size, self.kwargs = rank, world_size, kwargs
        self.epoch = 0

    def set_epoch(self, epoch: int) -> None:
        self.epoch = epoch

    def __iter__(self) -> Iterator[Batch]:
        chunks = epoch_chunks(self.takes, self.seed, self.epoch, **self.kwargs)
        rng = np.random.default_rng([self.seed, self.epoch])
        all_batches = list(batches(chunks, self.batch_size, rng))
        per_rank = len(all_batches) // self.world_size  # equal counts on every rank
        mine = all_batches[self.rank : per_rank * self.world_size : self.world_size]
        worker = get_worker_info()
        if worker is not None:
            mine = mine[worker.id :: worker.num_workers]
        for b in mine:
            yield to_tensors(b)
