"""Network tests run on one torch CPU thread: their tensors are tiny, and 2 threads on a busy 2-core machine
ran the training tests ~50x slower."""

import pytest
import torch


@pytest.fixture(autouse=True)
def one_thread():
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)
