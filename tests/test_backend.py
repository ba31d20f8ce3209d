"""The backend never crashes the process: failing JIT variants fall back to scalar."""

import glob

import pytest

from mirrorsim.formats.cache import cache_root, entry_path
from mirrorsim.rendering import backend


def test_probe_answer_is_cached(monkeypatch):
    calls = []

    def fake_probe(variant):
        calls.append(variant)
        return False, "simulated failure", True

    monkeypatch.setattr(backend, "_run_probe", fake_probe)
    monkeypatch.setenv("DRJIT_LIBLLVM_PATH", "/simulated/cache-test")
    assert backend.probe("llvm_ad_rgb") == (False, "simulated failure")
    assert backend.probe("llvm_ad_rgb") == (False, "simulated failure")
    assert calls == ["llvm_ad_rgb"]
    assert any((cache_root() / "backend").iterdir())


def test_a_probe_killed_from_outside_is_no_verdict(monkeypatch):
    """The OOM killer's SIGKILL says nothing about the variant: the next run probes
    again (a real child process, killed by a real signal)."""
    monkeypatch.setattr(backend, "_PROBE_CODE", "import os, signal; "
                        "os.kill(os.getpid(), signal.SIGKILL)")
    monkeypatch.setenv("DRJIT_LIBLLVM_PATH", "/simulated/killed-probe")
    ok, detail = backend.probe("llvm_ad_rgb")
    assert not ok and "signal 9" in detail and "not a verdict" in detail
    monkeypatch.setattr(backend, "_PROBE_CODE", "print('mirrorsim-probe-ok')")
    assert backend.probe("llvm_ad_rgb") == (True, "")
    # an abort inside LLVM is a verdict, as before
    monkeypatch.setattr(backend, "_PROBE_CODE", "import os; os.abort()")
    monkeypatch.setenv("DRJIT_LIBLLVM_PATH", "/simulated/aborting-probe")
    assert backend.probe("llvm_ad_rgb")[0] is False
    monkeypatch.setattr(backend, "_PROBE_CODE", "print('mirrorsim-probe-ok')")
    assert backend.probe("llvm_ad_rgb")[0] is False  # cached


def test_a_damaged_probe_answer_is_redone_with_a_warning(monkeypatch):
    """An answer edited on disk ("ok" flipped) fails its checksum: probed again."""
    monkeypatch.setenv("DRJIT_LIBLLVM_PATH", "/simulated/damaged-answer")
    monkeypatch.setattr(backend, "_PROBE_CODE", "print('mirrorsim-probe-ok')")
    assert backend.probe("llvm_ad_rgb") == (True, "")
    path = entry_path("backend", f"llvm_ad_rgb|{backend._machine_key('llvm_ad_rgb')}")
    path.write_text(path.read_text().replace('"ok": true', '"ok": false'))
    with pytest.warns(RuntimeWarning, match="checksum"):
        assert backend.probe("llvm_ad_rgb") == (True, "")
    path.write_text("{")  # truncated
    with pytest.warns(RuntimeWarning, match="not trusted"):
        assert backend.probe("llvm_ad_rgb") == (True, "")


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
    # an unknown name is bad input (exit 2), refused before a run claims its folder
    with pytest.raises(backend.BadParameter, match="variant: 'vulkan': use auto"):
        backend.choose_variant("vulkan")
