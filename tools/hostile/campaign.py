"""The hostile-user campaign against an installed ``tpnet`` (issue 40 item 6): cases by class (``cases.py``:
output folders, crafted rigs, numeric option bounds, every file-reading door given special or crafted files, a
video with a bad frame),
each run as a black box in its own folder; a table by class, the cases that misbehave, and JSON.

    python tools/hostile/campaign.py [--tpnet "tpnet"] [--quick] [--json out/hostile.json] [--work DIR]

Standard library only: it never imports the project it judges (``--tpnet`` is the command line to run, e.g. "python
-m tpnet_gpu.cli" of another checkout). A case behaves when: it ends within ``--timeout`` s; no traceback or
RuntimeWarning; its exit is the expected one (2 = refused, with exactly one ``tpnet CMD: error:`` line; 1 = a
video's bad frame, named on its own line, the other frames written with ``sequence.json``); no crafted
pickle's payload ran; nothing ``.tmp-*`` / ``.old-*`` is left in its folder. Two writers of one ``--out``: exactly
one exits 0 and the folder holds its whole output. A writer killed by SIGKILL mid-run: the next run into the same
folder exits 0 and leaves nothing of the killed one. tests/tools/test_hostile_campaign.py runs ``--quick`` in CI.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shlex
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from cases import Case, all_cases  # noqa: E402 - this folder's own module, found beside the script

ERROR_LINE = re.compile(r"^tpnet [\w-]+: error: ")


DATA = ["dataset", "--scenes", "2", "--width", "64", "--height", "48", "--supersample", "1", "--rig", "binocular",
        "--mono"]  # the tiny data set the train cases read (``{data}``), made once per campaign


def _argv(case: Case, folder: Path) -> list[str]:
    return [a.replace("{d}", str(folder)).replace("{data}", str(folder.parent / "data")) for a in case.argv]


def _start(tpnet: list[str], argv: list[str]) -> subprocess.Popen:
    return subprocess.Popen([*tpnet, *argv], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            errors="replace", start_new_session=True)


def _finish(proc: subprocess.Popen, timeout: float) -> tuple[int | None, str]:
    try:
        _, err = proc.communicate(timeout=timeout)
        return proc.returncode, err
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        _, err = proc.communicate()
        return None, err


def _problems(code: int | None, err: str, expect: str, names: str | None = None) -> list[str]:
    """What is wrong with one run's exit ``code`` and ``err`` given ``expect`` ("0", "2", "0|2"); a refusal
    must name ``names`` (else it was refused for another reason than the case's)."""
    if code is None:
        return ["hung (killed at the time limit)"]
    found = []
    if "Traceback (most recent call last)" in err:
        found.append("traceback")
    if "RuntimeWarning" in err:  # numpy's warnings are the library's to handle, not the user's to read
        found.append("a RuntimeWarning reached the user")
    if str(code) not in expect.split("|"):
        found.append(f"exit {code}, expected {expect}")
    errors = [line for line in err.splitlines() if ERROR_LINE.match(line)]
    usage = "usage: tpnet" in err  # argparse's own refusal: its usage, then one error line naming the option
    if code == 2 and len(errors) != 1 and not usage:
        found.append(f"{len(errors)} error lines")
    last = errors[-1] if errors else (err.strip().splitlines() or [""])[-1]
    spellings = [] if not names else [names, names.lstrip("-").replace("-", "_")]  # the option, or its field
    if code == 2 and spellings and not any(n in last for n in spellings):
        found.append(f"refused for another reason: {last[:160]}")
    if code == 1 and names and names not in err:  # a video's bad frame: its own line, the video goes on
        found.append(f"exit 1 without a line naming {names!r}")
    return found


def _leftovers(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob(".*")
                  if ".tmp-" in p.name or ".old-" in p.name or p.name.endswith(".lock"))


def run_case(case: Case, tpnet: list[str], folder: Path, timeout: float) -> dict:
    folder.mkdir(parents=True)
    if case.setup is not None:
        case.setup(folder)
    argv = _argv(case, folder)
    start = time.perf_counter()
    problems: list[str] = []
    if case.runs > 1:  # writers of one folder at once
        procs = [_start(tpnet, argv) for _ in range(case.runs)]
        results = [_finish(p, timeout) for p in procs]
        codes = [c for c, _ in results]
        for code, err in results:
            problems += _problems(code, err, "0|2")
        if codes.count(0) != 1:
            problems.append(f"exits {codes}: expected exactly one 0")
        if not (folder / "o" / "disparity.tif").is_file():
            problems.append("the folder does not hold a whole output")
    elif case.kill_after is not None:  # killed mid-run, then the same command again
        proc = _start(tpnet, argv)
        time.sleep(case.kill_after)
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        code, err = _finish(_start(tpnet, argv), timeout)
        problems += _problems(code, err, "0")
    else:
        code, err = _finish(_start(tpnet, argv), timeout)
        problems += _problems(code, err, case.expect, case.names)
        if code == 1 and not (folder / "o" / "sequence.json").is_file():  # a video with a bad frame
            problems.append("a video's bad frame, but no sequence.json for the others")
        elif code not in (0, 1):
            problems += [f"refused, but wrote {made}" for made in ("o", "n.onnx") if (folder / made).exists()]
    if case.marker and (folder / case.marker).exists():
        problems.append("a crafted pickle's payload ran")
    left = _leftovers(folder)
    if left:
        problems.append(f"left {left[:3]}")
    return {"class": case.cls, "case": case.name, "argv": " ".join(shlex.quote(a) for a in argv)[:300],
            "seconds": round(time.perf_counter() - start, 2), "problems": problems}


def table(results: list[dict]) -> list[str]:
    by_class = Counter(r["class"] for r in results)
    bad = Counter(r["class"] for r in results if r["problems"])
    lines = ["| class | cases | behave | misbehave |", "|---|---|---|---|"]
    for cls in by_class:
        lines.append(f"| {cls} | {by_class[cls]} | {by_class[cls] - bad[cls]} | {bad[cls]} |")
    total, wrong = len(results), sum(1 for r in results if r["problems"])
    lines.append(f"| all | {total} | {total - wrong} | {wrong} |")
    lines += ["", "Misbehaving cases:" if wrong else "No case misbehaves."]
    lines += [f"- {r['class']}: {r['case']}: {'; '.join(r['problems'])}" for r in results if r["problems"]]
    return lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tpnet", default="tpnet", help="the command line to judge (default: tpnet)")
    parser.add_argument("--quick", action="store_true", help="a slice of every class (CI)")
    parser.add_argument("--timeout", type=float, default=120.0, help="seconds a case may take")
    parser.add_argument("--json", default="", help="save the results here")
    parser.add_argument("--work", default=None, help="folder for the cases' files (default: a temporary one)")
    parser.add_argument("--only", default=None, help="run only cases whose class or name contains this")
    args = parser.parse_args(argv)
    tpnet = shlex.split(args.tpnet)
    cases = [c for c in all_cases(args.quick) if args.only is None or args.only in f"{c.cls}: {c.name}"]
    results = []
    with tempfile.TemporaryDirectory(prefix="tpnet-hostile-", dir=args.work) as work:
        if any("{data}" in a for c in cases for a in c.argv):
            subprocess.run([*tpnet, DATA[0], str(Path(work) / "data"), *DATA[1:]], capture_output=True,
                           timeout=args.timeout * 5, check=True)
        for i, case in enumerate(cases):
            result = run_case(case, tpnet, Path(work) / f"{i:03d}", args.timeout)
            results.append(result)
            mark = "ok" if not result["problems"] else "MISBEHAVES: " + "; ".join(result["problems"])
            print(f"[{i + 1}/{len(cases)}] {case.cls}: {case.name}: {mark} ({result['seconds']} s)", flush=True)
    lines = table(results)
    print("\n".join(lines))
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps({"tpnet": args.tpnet, "quick": args.quick, "results": results,
                                               "table": lines}, indent=1))
    return 1 if any(r["problems"] for r in results) else 0


if __name__ == "__main__":
    sys.exit(main())
