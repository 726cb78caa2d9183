"""Data-parallel plumbing: torchrun's environment -> process group, DDP, agreement.

One process (no WORLD_SIZE, or 1) needs none of it. Under torchrun, gloo on CPU, NCCL
when CUDA is there (one GPU per local rank). Each rank dies with the agent that started it
(``faceclean.workers.die_with_parent``).
"""

from __future__ import annotations

import datetime
import os

import torch
import torch.distributed as dist
from torch import nn

from faceclean import workers


def setup() -> tuple[int, int, torch.device]:
    """(rank, world size, device), initialising the process group under torchrun."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world <= 1 or dist.is_initialized():
        rank = dist.get_rank() if dist.is_initialized() else 0
        return rank, max(world, 1), _device()
    workers.die_with_parent()  # a rank stops when torchrun's agent dies, SIGKILL included
    cuda = torch.cuda.is_available()
    if cuda:
        torch.cuda.set_device(int(os.environ.get("LOCAL_RANK", "0")))
    dist.init_process_group("nccl" if cuda else "gloo", timeout=datetime.timedelta(minutes=30))
    return dist.get_rank(), dist.get_world_size(), _device()


def _device() -> torch.device:
    if torch.cuda.is_available() and int(os.environ.get("WORLD_SIZE", "1")) > 1:
        return torch.device("cuda", int(os.environ.get("LOCAL_RANK", "0")))
    return torch.device("cpu")


def wrap(model: nn.Module, device: torch.device) -> nn.Module:
    """The model under DDP when a process group runs, else itself."""
    if not dist.is_initialized() or dist.get_world_size() == 1:
        return model
    ids = [device.index] if device.type == "cuda" else None
    return nn.parallel.DistributedDataParallel(model, device_ids=ids)


def agree(flag: bool, device: torch.device) -> bool:
    """Rank 0's ``flag`` on every rank (a broadcast; the flag itself when alone)."""
    if not dist.is_initialized():
        return flag
    t = torch.tensor([1.0 if flag else 0.0], device=device)
    dist.broadcast(t, src=0)
    return bool(t.item() > 0)


def teardown() -> None:
    """Destroy the process group if this process made one."""
    if dist.is_initialized():
        dist.destroy_process_group()
