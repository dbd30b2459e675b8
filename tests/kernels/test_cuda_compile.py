"""The Warp kernels compile for CUDA (sm_90, 64 threads per block) on a machine without a GPU: Warp's bundled NVRTC
builds the cubins (tpnet_gpu.runtime.cuda_aot). Cold, the project's modules take about a minute of two cores; cached by
Warp's module hash, a rerun takes about a second. Skipped, naming NVRTC, where Warp cannot compile for CUDA."""

import importlib
import shutil

import pytest

from tpnet_gpu.runtime import cuda_aot

GOOD = '''import warp as wp

wp.set_module_options({"enable_backward": False})


@wp.kernel
def probe(a: wp.array(dtype=float)):
    i = wp.tid()
    a[i] = a[i] * 2.0
'''

# Valid C++ for the CPU, rejected by NVRTC only: a CUDA-only compile error.
BROKEN = '''import warp as wp

wp.set_module_options({"enable_backward": False})


@wp.func_native("""
#if defined(__CUDA_ARCH__)
    return x + not_declared_for_cuda;
#else
    return x;
#endif
""")
def shifted(x: float) -> float: ...


@wp.kernel
def probe(a: wp.array(dtype=float)):
    i = wp.tid()
    a[i] = shifted(a[i])
'''


@pytest.fixture
def nvrtc():
    reason = cuda_aot.nvrtc_problem([90])
    if reason:
        pytest.skip(reason)


def test_missing_nvrtc_is_named(monkeypatch, capsys):
    monkeypatch.setattr(cuda_aot.wp, "get_cuda_supported_archs", lambda: [])
    assert "NVRTC" in cuda_aot.nvrtc_problem([90])
    with pytest.raises(RuntimeError, match="NVRTC"):
        cuda_aot.check([90])
    assert cuda_aot.main(["--arch", "90"]) == 2 and "NVRTC" in capsys.readouterr().err
    monkeypatch.setattr(cuda_aot.wp, "get_cuda_supported_archs", lambda: [75, 80])
    assert "cannot target sm_90;" in cuda_aot.nvrtc_problem([80, 90])


def _no_compile(*args):
    raise AssertionError(f"compiled although cached: {args}")


def _probe_module(tmp_path, monkeypatch, name: str, source: str):
    (tmp_path / f"{name}.py").write_text(source)
    monkeypatch.syspath_prepend(str(tmp_path))
    return importlib.import_module(name)


def _rewrite(module, tmp_path, source: str):
    (tmp_path / f"{module.__name__}.py").write_text(source)
    shutil.rmtree(tmp_path / "__pycache__", ignore_errors=True)  # same size and second: a stale .pyc would load
    return importlib.reload(module)


@pytest.mark.usefixtures("nvrtc")
def test_every_kernel_module_compiles_for_sm90(tmp_path, monkeypatch):
    modules = cuda_aot.kernel_modules()
    assert {f"tpnet_gpu.kernels.{m}" for m in ("frames", "convert", "correlate", "fused", "texture")} <= set(modules)
    assert not any(".taichi_" in m for m in modules)
    rows = cuda_aot.check([90])
    assert [r["module"] for r in rows] == modules
    assert all(r["ok"] and r["block_dim"] == 64 for r in rows), cuda_aot.format_table(rows)
    assert all(r["kernels"] and all(k["registers"] > 0 for k in r["kernels"].values()) for r in rows)

    monkeypatch.setattr(cuda_aot, "_run_worker", _no_compile)  # the second run is served from the stamps
    again = cuda_aot.check([90])
    assert all(r["cached"] for r in again)
    assert [r["kernels"] for r in again] == [r["kernels"] for r in rows]
    assert cuda_aot.main(["--arch", "90", "--json", str(tmp_path / "report.json")]) == 0  # the CLI, as CI runs it
    assert (tmp_path / "report.json").read_text().count('"ok": true') == len(modules)


@pytest.mark.usefixtures("nvrtc")
def test_cuda_only_error_is_reported_not_cached(tmp_path, monkeypatch):
    _probe_module(tmp_path, monkeypatch, "aot_probe_broken", BROKEN)
    (row,) = cuda_aot.check([90], modules=["aot_probe_broken"], root=tmp_path / "cache")
    assert not row["ok"] and not row["cached"]
    assert "NVRTC" in row["error"] and "not_declared_for_cuda" in row["error"], row["error"]
    assert not (tmp_path / "cache" / row["key"]).exists()
    monkeypatch.setattr(cuda_aot, "kernel_modules", lambda: ["aot_probe_broken"])
    monkeypatch.setenv("TPNET_CACHE_DIR", str(tmp_path / "cli"))
    assert cuda_aot.main(["--arch", "90"]) == 1


@pytest.mark.usefixtures("nvrtc")
def test_cache_follows_the_kernel_source(tmp_path, monkeypatch):
    root = tmp_path / "cache"
    module = _probe_module(tmp_path, monkeypatch, "aot_probe_edit", GOOD)
    (first,) = cuda_aot.check([90], modules=[module.__name__], root=root)
    assert first["ok"] and not first["cached"], cuda_aot.format_table([first])
    assert (root / first["key"] / "report.json").exists()
    assert first["kernels"]["probe"]["registers"] > 0

    with monkeypatch.context() as m:
        m.setattr(cuda_aot, "_run_worker", _no_compile)
        (again,) = cuda_aot.check([90], modules=[module.__name__], root=root)
    assert again["cached"] and again["key"] == first["key"]

    name = module.__name__
    assert cuda_aot.module_key(name, 80) != first["key"] != cuda_aot.module_key(name, 90, block_dim=256)
    _rewrite(module, tmp_path, GOOD.replace("2.0", "3.0"))
    (edited,) = cuda_aot.check([90], modules=[name], root=root)
    assert edited["ok"] and not edited["cached"] and edited["key"] != first["key"]
    _rewrite(module, tmp_path, GOOD)
    assert cuda_aot.module_key(name, 90) == first["key"]  # the key is the content's, not the edit's time


@pytest.mark.usefixtures("nvrtc")
def test_key_covers_functions_of_other_modules(tmp_path, monkeypatch):
    helper = _probe_module(tmp_path, monkeypatch, "aot_probe_helper",
                           "import warp as wp\n\n\n@wp.func\ndef twice(x: float):\n    return x * 2.0\n")
    user_source = GOOD.replace("a[i] * 2.0", "twice(a[i])").replace(
        "import warp as wp\n", "import warp as wp\n\nfrom aot_probe_helper import twice\n")
    user = _probe_module(tmp_path, monkeypatch, "aot_probe_user", user_source)
    key = cuda_aot.module_key(user.__name__, 90)
    _rewrite(helper, tmp_path, "import warp as wp\n\n\n@wp.func\ndef twice(x: float):\n    return x + x\n")
    user = importlib.reload(user)
    assert cuda_aot.module_key(user.__name__, 90) != key
