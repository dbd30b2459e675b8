"""The throughput bench's network split (bench/throughput/bench_throughput.py). Oracle: ``TPNet.forward_frame`` (itself
tested against the cluster form in tests/net/test_model.py); atol 1e-6."""

import torch

from tpnet_gpu.bench.throughput.bench_throughput import network_stage1, network_stage2
from tpnet_gpu.net.model import TPNet


def test_stage1_then_stage2_is_the_whole_network():
    torch.manual_seed(0)
    net = TPNet()
    layers, target = torch.randn(7, 9, 4, 9, 9), torch.randn(7, 9)
    with torch.no_grad():
        split = network_stage2(net, network_stage1(net, layers, target), target)
        torch.testing.assert_close(split, net.forward_frame(layers, target), atol=1e-6, rtol=0)
        assert split.std() > 0.01
