"""The backend never crashes the process: failing JIT variants fall back to scalar."""

import glob

import pytest

from mirrorsim.rendering import backend


def test_probe_answer_is_cached(monkeypatch):
    calls = []

    def fake_probe(variant):
        calls.append(variant)
        return False, "simulated failure"

    monkeypatch.setattr(backend, "_run_probe", fake_probe)
    monkeypatch.setenv("DRJIT_LIBLLVM_PATH", "/simulated/cache-test")
    assert backend.probe("llvm_ad_rgb") == (False, "simulated failure")
    assert backend.probe("llvm_ad_rgb") == (False, "simulated failure")
    assert calls == ["llvm_ad_rgb"]
    assert backend.cache_path().exists()


def test_failing_llvm_falls_back_to_scalar_with_one_warning(monkeypatch):
    # a libLLVM that cannot be loaded: the probe fails in its child process
    monkeypatch.setenv("DRJIT_LIBLLVM_PATH", "/nonexistent/libLLVM-99.so")
    monkeypatch.setattr(backend, "_maybe_gpu", lambda: False)
    ok, detail = backend.probe("llvm_ad_rgb")
    assert not ok and detail
    with pytest.warns(RuntimeWarning, match="libllvm19") as rec:
        assert backend.choose_variant("auto") == "scalar_rgb"
    assert len(rec) == 1
    with pytest.raises(backend.BackendError, match="does not work here"):
        backend.choose_variant("llvm")


@pytest.mark.skipif(not glob.glob("/usr/lib/*/libLLVM-15.so*"), reason="no libLLVM 15 here")
def test_llvm15_abort_is_contained(monkeypatch):
    """libLLVM 15 really aborts drjit's LLVM backend; the probe survives it."""
    lib = sorted(glob.glob("/usr/lib/*/libLLVM-15.so*"))[0]
    monkeypatch.setenv("DRJIT_LIBLLVM_PATH", lib)
    ok, detail = backend.probe("llvm_ad_rgb", use_cache=False)
    assert not ok
    assert "signal" in detail or "ERROR" in detail


def test_scalar_always_available():
    assert backend.choose_variant("scalar") == "scalar_rgb"
    with pytest.raises(backend.BackendError, match="unknown variant"):
        backend.choose_variant("vulkan")
