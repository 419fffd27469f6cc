"""Splat tests use one torch thread: the tensors are tiny, and on a shared 2-core machine torch's
OpenMP barriers cost far more than they save (the numba kernels keep their own pool)."""

import pytest


@pytest.fixture(autouse=True)
def _one_torch_thread():
    import torch

    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)
