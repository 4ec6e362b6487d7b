"""The pieces of studies/center_forms.py and studies/identification_ceiling.py that carry their numbers:
the kink of a curve, residuals aligned on it, and the 1D posterior of a gridded log-likelihood."""
import numpy as np
from scipy import stats

from studies.center_forms import aligned_sd, kinks
from studies.identification_ceiling import FINE, oracle_posterior


def ramp(kink: int, m: int = 100) -> np.ndarray:
    """A rise of slope 1 up to ``kink``, then flat."""
    t = np.arange(m, dtype=float)
    return np.minimum(t, kink)


def test_the_kink_is_where_the_rise_stops_and_the_window_s_end_where_it_never_does():
    curves = np.vstack([ramp(30), ramp(55), np.arange(100.0)])
    assert kinks(curves).tolist() == [31, 56, 99]


def test_residuals_aligned_on_their_kinks_give_back_the_scatter_that_follows_each_kink():
    m = 100
    ks = np.array([30, 40, 50, 60])
    # each run scatters only after its own kink, with amplitude 2; the runs' kinks differ
    r = np.array([np.where(np.arange(m) >= k + 1, 2.0, 0.0) for k in ks])
    sd = aligned_sd(r, kinks(np.vstack([ramp(k) for k in ks])))
    lag = np.arange(2 * m - 1) - (m - 1)
    assert np.allclose(sd[(lag >= 0) & (lag <= 38)], 2.0)
    assert np.all(sd[(lag <= -1) & (lag >= -30)] < 1e-6)


def test_a_gaussian_log_likelihood_on_the_grid_gives_its_quantiles():
    lo, hi, mu, s = 0.0, 10.0, 4.0, 0.8
    centres = lo + (np.arange(400) + 0.5) * (hi - lo) / 400
    out = oracle_posterior(-0.5 * ((centres - mu) / s) ** 2, centres, lo, hi, truth=mu)
    for key, level in (("q05", 0.05), ("q50", 0.5), ("q95", 0.95)):
        # the fine grid's trapezoids: within half of its step of the exact quantile
        assert abs(out[key] - stats.norm.ppf(level, mu, s)) < 0.5 * (hi - lo) / (FINE - 1)
    assert abs(out["pit"] - 0.5) < 1e-3
