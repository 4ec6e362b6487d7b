"""The engine loads without Numba's BLAS probe (fdem.numba_load): a simulation job skips SciPy's linalg
import, and the engine computes the same curves to the bit, because none of its kernels calls BLAS."""
import subprocess
import sys
import textwrap

import numpy as np

from fdem.numba_load import without_blas_probe

RUN = textwrap.dedent("""
    import sys
    import numpy as np
    if {scipy_first}:
        import scipy.linalg  # the probe finds BLAS, as in a process that imported SciPy's linalg itself
    from shpb.simulate import simulate, warm_up
    warm_up()
    import numba.np.arraymath as arraymath
    out = simulate("brazilian_disc", "fast", {{"sigma_t": 38e6, "E_t": 650.0}}, t_end=1.6e-4, mesh_seed=4)
    np.save(sys.argv[1], out.columns["stress_Pa"])
    print(int("scipy.linalg" in sys.modules), int(arraymath._HAVE_BLAS))
""")


def _job(tmp_path, scipy_first: bool):
    path = tmp_path / f"curve_{scipy_first}.npy"
    out = subprocess.run([sys.executable, "-c", RUN.format(scipy_first=scipy_first), str(path)],
                         capture_output=True, text=True, timeout=600, check=True)
    return out.stdout.split()[-2:], np.load(path)


def test_a_job_loads_the_engine_without_scipy_linalg_and_gets_the_same_curve(tmp_path):
    (linalg, blas), curve = _job(tmp_path, scipy_first=False)
    assert (linalg, blas) == ("0", "0")  # the probe was answered "no BLAS"; SciPy's linalg never loaded
    (linalg_ref, blas_ref), ref = _job(tmp_path, scipy_first=True)
    assert (linalg_ref, blas_ref) == ("1", "1")
    assert np.max(np.abs(ref)) > 1e6
    np.testing.assert_array_equal(curve, ref)  # bit for bit: no kernel's code depends on the probe


def test_the_mark_is_removed_and_a_process_that_has_linalg_is_left_alone():
    import scipy.linalg  # noqa: F401  (this test process: the block must change nothing)

    before = sys.modules["scipy.linalg"]
    with without_blas_probe():
        assert sys.modules["scipy.linalg"] is before
    assert sys.modules["scipy.linalg"] is before
