"""The hostile-user campaign (tools/hostile/campaign.py, issue 40 item 6): CI runs its quick slice - every class
(output folders with two writers and a killed one, crafted rigs, numeric option bounds, special and crafted files
at every file-reading door) against this checkout's command line as a black box. Oracle: the campaign's own
per-case checks (exit codes, one error line naming the argument, no traceback, no leftovers, no payload run),
which a unit test here shows can fail."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
CAMPAIGN = ROOT / "tools" / "hostile" / "campaign.py"
TPNET = f"{sys.executable} -m tpnet_gpu.cli"


@pytest.mark.slow
def test_the_quick_campaign_finds_nothing(tmp_path):
    done = subprocess.run([sys.executable, str(CAMPAIGN), "--quick", "--tpnet", TPNET, "--work", str(tmp_path),
                           "--json", str(tmp_path / "hostile.json")], capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-2000:]
    assert "No case misbehaves." in done.stdout
    for cls in ("outputs", "crafted rigs", "option bounds", "file doors", "video"):
        assert f"| {cls} |" in done.stdout


def test_the_campaign_sees_a_misbehaving_command(tmp_path):
    # a stand-in "tpnet" that answers every case with a traceback and exit 1: every case must be counted bad
    fake = tmp_path / "fake_tpnet.py"
    fake.write_text("import sys\nprint('Traceback (most recent call last):', file=sys.stderr)\nsys.exit(1)\n")
    done = subprocess.run([sys.executable, str(CAMPAIGN), "--only", "crafted rigs", "--tpnet",
                           f"{sys.executable} {fake}", "--work", str(tmp_path)], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 1
    assert "| crafted rigs | 7 | 0 | 7 |" in done.stdout and "traceback" in done.stdout
