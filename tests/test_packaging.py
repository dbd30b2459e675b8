"""Packaging: the wheel holds every module of the four source roots and each imports from it; every third-party
import is a declared dependency; ``tpnet_gpu.net`` reads its weights' recipe without the data-set builder.
Oracles: the source tree (what must be there), pyproject.toml (what is declared)."""

import ast
import json
import re
import shutil
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
ROOTS = {"tpnet_gpu": "tpnet_gpu", "tpnet_gpu.kernels": "kernels", "tpnet_gpu.net": "net", "tpnet_gpu.bench": "bench"}
OPTIONAL = {"cv2"}  # the bench extra (matplotlib is a dependency: the figures)
ALIAS = {"skimage": "scikit-image", "PIL": "pillow", "warp": "warp-lang", "cv2": "opencv-python-headless"}


def source_modules() -> dict[str, Path]:
    """Installed module name -> source file, for every .py under the roots."""
    out = {}
    for name, folder in ROOTS.items():
        for path in sorted((ROOT / folder).rglob("*.py")):
            parts = path.relative_to(ROOT / folder).with_suffix("").parts
            if "__pycache__" in parts:
                continue
            parts = parts[:-1] if parts[-1] == "__init__" else parts
            out[".".join((name, *parts))] = path
    return out


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    # built from a copy of the tracked sources: setuptools keeps a build/ folder whose stale modules would
    # otherwise hide a module the tree no longer ships (and the checkout stays clean)
    out, src = tmp_path_factory.mktemp("wheel"), tmp_path_factory.mktemp("src") / "tpnet-gpu"
    skip = shutil.ignore_patterns(".git", ".venv*", "build", "dist", "out", "__pycache__", "*.egg-info", ".whl*")
    shutil.copytree(ROOT, src, ignore=skip)
    done = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w",
                           str(out), str(src)], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-3000:]
    (found,) = out.glob("tpnet_gpu-*.whl")
    return found


@pytest.mark.slow
def test_wheel_holds_every_module_and_the_weights(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    missing = [str(path.relative_to(ROOT)) for module, path in source_modules().items()
               if module.replace(".", "/") + ".py" not in names and module.replace(".", "/") + "/__init__.py" not in names]
    assert not missing, f"not in the wheel: {missing}"
    assert any(n.startswith("tpnet_gpu/net/weights/") and n.endswith(".pt") for n in names)
    assert {f"tpnet_gpu/rigs/{n}.json" for n in ("quad", "binocular", "two_quads")} <= names  # example rig files


@pytest.mark.slow
def test_every_module_imports_from_the_wheel(wheel, tmp_path):
    site = tmp_path / "site"
    zipfile.ZipFile(wheel).extractall(site)
    script = tmp_path / "import_all.py"
    script.write_text(f"""
import importlib, json, sys
sys.path.insert(0, {str(site)!r})
report = {{}}
for name in {sorted(source_modules())!r}:
    try:
        module = importlib.import_module(name)
        report[name] = "ok" if module.__file__.startswith({str(site)!r}) else "elsewhere: " + module.__file__
    except ModuleNotFoundError as exc:
        report[name] = "missing " + str(exc.name)
print(json.dumps(report))
""")
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads(done.stdout.strip().splitlines()[-1])
    bad = {k: v for k, v in report.items() if v != "ok" and v.replace("missing ", "") not in OPTIONAL}
    assert not bad, bad


def third_party_imports(folder: str, *, top_level_only: bool = False) -> dict[str, str]:
    """Third-party top-level module -> a file importing it, under ``folder``; ``top_level_only``: only the imports
    a module runs when it is imported (not those inside functions, which optional extras use on demand)."""
    out = {}
    for path in (ROOT / folder).rglob("*.py"):
        tree = ast.parse(path.read_text())
        nodes = [n for n in tree.body if not isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef))]
        for node in (n for top in nodes for n in ast.walk(top)) if top_level_only else ast.walk(tree):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names = [node.module]
            else:
                continue
            for name in names:
                top = name.split(".")[0]
                if top not in sys.stdlib_module_names and top not in {"tpnet_gpu", "tests"}:
                    out.setdefault(top, str(path.relative_to(ROOT)))
    return out


def test_every_import_is_declared():
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    declared = {re.split(r"[<>=!~\[; ]", d)[0].lower() for d in meta["dependencies"]}
    extras = {re.split(r"[<>=!~\[; ]", d)[0].lower() for deps in meta["optional-dependencies"].values() for d in deps}
    for folder in ("tpnet_gpu", "kernels", "net"):
        undeclared = {m: f for m, f in third_party_imports(folder, top_level_only=True).items()
                      if ALIAS.get(m, m).lower() not in declared}
        assert not undeclared, f"imported on import but not in [project] dependencies: {undeclared}"
        # inside functions: a dependency or an optional extra (onnx, ray: imported on use with a clear message)
        undeclared = {m: f for m, f in third_party_imports(folder).items()
                      if ALIAS.get(m, m).lower() not in declared | extras}
        assert not undeclared, f"imported but not in [project] dependencies or an extra: {undeclared}"
    bench = {m: f for m, f in third_party_imports("bench").items() if ALIAS.get(m, m).lower() not in declared | extras}
    assert not bench, f"bench imports not declared (dependencies or an extra): {bench}"
    tests = {m: f for m, f in third_party_imports("tests").items()
             if m not in OPTIONAL and ALIAS.get(m, m).lower() not in declared | extras}
    assert not tests, f"test imports not declared: {tests}"


def test_net_does_not_import_the_dataset_builder():
    # reading the weights and their recipe (infer) and the model need no data set; only training loads one
    for path in (ROOT / "net" / "infer.py", ROOT / "net" / "model.py"):
        text = path.read_text()
        assert "tpnet_gpu.training.dataset" not in text and "from tpnet_gpu import dataset" not in text, path
    done = subprocess.run([sys.executable, "-c", "import sys, tpnet_gpu.net.infer as i; i.correlation(); "
                           "print(json.dumps('tpnet_gpu.training.dataset' in sys.modules))".replace("json.dumps", "repr")],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip() == "False"
