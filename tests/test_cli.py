"""The ``tpnet`` command line. Oracle for the demo: the disparity the scene was generated at."""

import re
import subprocess
import sys

from tpnet_gpu.cli import main


def test_demo_recovers_the_generated_disparity(capsys):
    assert main(["demo"]) == 0
    out = capsys.readouterr().out
    errors = [float(m) for m in re.findall(r"median \|error\| ([0-9.]+) px", out)]
    assert errors and errors[-1] < 0.1  # generated at 2.37 px; every tile within 0.1 px after refinement


def test_help_lists_subcommands():
    done = subprocess.run([sys.executable, "-m", "tpnet_gpu.cli", "--help"], capture_output=True, text=True)
    assert done.returncode == 0 and "demo" in done.stdout
