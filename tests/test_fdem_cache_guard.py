"""The engine's Numba cache is dropped when any of its sources changes (fdem/cache_guard.py): Numba
itself checks only the cached function's own file, and run_loop inlines the kernels of other files."""
from pathlib import Path

from fdem.cache_guard import STAMP, clear_if_stale, sources_hash


def _package(tmp_path: Path) -> Path:
    pkg = tmp_path / "pkg"
    (pkg / "__pycache__").mkdir(parents=True)
    (pkg / "integrator.py").write_text("def run_loop(): pass\n")
    (pkg / "kernels.py").write_text("K = 1\n")
    return pkg


def test_an_edited_kernel_file_clears_the_cache_of_every_function(tmp_path, monkeypatch):
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    pkg = _package(tmp_path)
    cache = pkg / "__pycache__"
    assert clear_if_stale(pkg) is False  # nothing cached yet; the stamp is written
    assert (cache / STAMP).read_text().strip() == sources_hash(pkg)
    (cache / "integrator.run_loop-1.py311.nbi").write_text("index")
    (cache / "integrator.run_loop-1.py311.1.nbc").write_text("code")
    (cache / "integrator.cpython-311.pyc").write_text("bytecode")
    assert clear_if_stale(pkg) is False  # sources unchanged: the cache is kept
    assert len(list(cache.glob("*.nb?"))) == 2
    (pkg / "kernels.py").write_text("K = 2\n")  # only the kernel's file changes
    assert clear_if_stale(pkg) is True
    assert list(cache.glob("*.nb?")) == []
    assert (cache / "integrator.cpython-311.pyc").exists()  # Python's own cache is not Numba's
    assert (cache / STAMP).read_text().strip() == sources_hash(pkg)


def test_numba_cache_dir_is_guarded_too(tmp_path, monkeypatch):
    pkg = _package(tmp_path)
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "nc"))
    clear_if_stale(pkg)
    from numba.core.caching import UserProvidedCacheLocator  # where Numba itself puts it
    mirror = tmp_path / "nc" / UserProvidedCacheLocator.get_suitable_cache_subpath(str(pkg / "integrator.py"))
    (mirror / "integrator.run_loop-1.py311.nbi").write_text("index")
    (pkg / "integrator.py").write_text("def run_loop(): return 1\n")
    assert clear_if_stale(pkg) is True
    assert not (mirror / "integrator.run_loop-1.py311.nbi").exists()
