"""A vectorised stand-in for the protocol tests (tests/test_protocol_*.py): the analytic SHPB-like surrogate
of tests/test_diagnosis_loop.py per record, with the catalogue's face gap, trigger shift, gauge gain,
baseline offset and rate-dependent strength written into the formula (no per-member loop).

Curve of record r (loading slope K_r [Pa/s], its input, like an incident wave): an elastic rise
K_r * FOOT * softplus((t - t0) / FOOT) from the arrival t0 = T0 + gap / V_FACE + dt up to the strength
sigma_p * DIF, DIF = max(1, 1 + k log10(rate_r / 1 s^-1)), rate_r = K_r / E_SPECIMEN; then an
exponential decay with time constant tau_d; the result times the gain g plus the offset.
"""

from __future__ import annotations

import numpy as np

from enkf import AR1Error
from enkf.diagnosis import RecordErrors, split_name
from enkf.emulated import emulator_error_model
from shpb import effects as fx

OBS_T = np.arange(0.0, 280e-6 + 1e-12, 2e-6)
T0, FOOT, V_FACE = 30e-6, 2e-6, 10.0
E_SPECIMEN = 35e9
BASE = ["sigma_p", "tau_d"]
BASE_BOX = {"sigma_p": (20e6, 60e6), "tau_d": (10e-6, 100e-6)}
TRUTH = {"sigma_p": 40e6, "tau_d": 45e-6}
SIGMA = 0.3e6          # instrument noise sd [Pa]
NOISE_TAU = 3e-6       # its correlation time [s]
EFFECT_PARAMS = ("face_gap.gap_m", "trigger_shift.dt_s", "gauge_gain.g", "baseline.offset_Pa", "rate_strength.k")


def curves(t, K, sigma_p, tau_d, gap=0.0, dt=0.0, g=1.0, offset=0.0, k=0.0):
    """Rows of stress curves [Pa] (every argument but ``t`` and ``K`` a scalar or an (N,) array)."""
    sigma_p, tau_d, gap, dt, g, offset, k = (np.atleast_1d(np.asarray(v, float))[:, None]
                                             for v in (sigma_p, tau_d, gap, dt, g, offset, k))
    dif = np.maximum(1.0, 1.0 + k * np.log10(K / E_SPECIMEN / fx.RATE0_PER_S))
    s = sigma_p * dif
    t0 = T0 + gap / V_FACE + dt
    rise = K * FOOT * np.logaddexp(0.0, (t - t0) / FOOT)
    x = s / (K * FOOT)
    t_p = t0 + FOOT * (x + np.log(-np.expm1(-x)))
    return g * np.where(t < t_p, rise, s * np.exp(-(t - t_p) / tau_d)) + offset


class StandIn:
    """The :class:`enkf.diagnosis.ForwardModel` of the tests: ``K[record]`` is each record's loading slope."""

    def __init__(self, K):
        self.K = dict(K)

    def box(self, names):
        lo, hi = [], []
        for n in names:
            p = split_name(n)[0]
            a, b = BASE_BOX[p] if p in BASE_BOX else (v[0] for v in fx.bounds([p]))
            lo.append(a), hi.append(b)
        return np.array(lo, float), np.array(hi, float)

    def forward(self, names, records):
        names, records = list(names), list(records)
        for n in names:
            if split_name(n)[0] not in BASE + list(EFFECT_PARAMS):
                raise KeyError(n)

        def f(P):
            P = np.array(P, dtype=float, ndmin=2)
            out = []
            for r in records:
                def val(p, default):
                    for n in (f"{p}@{r}", p):
                        if n in names:
                            return P[:, names.index(n)]
                    return np.full(P.shape[0], default)
                out.append(curves(OBS_T, self.K[r], val("sigma_p", np.nan), val("tau_d", np.nan),
                                  val("face_gap.gap_m", 0.0), val("trigger_shift.dt_s", 0.0), val("gauge_gain.g", 1.0),
                                  val("baseline.offset_Pa", 0.0), val("rate_strength.k", 0.0)))
            return np.hstack(out)
        return f


def noise_model():
    return AR1Error(SIGMA, OBS_T, NOISE_TAU)


def model_error_model(seed=0, rms=0.1e6, corr=8e-6, n=40):
    """A time-correlated model-error term as the workflow builds it (:func:`enkf.emulated.emulator_error_model`
    of leave-one-out residuals), here of synthetic AR(1) residuals: the stand-in is exact, the term only
    makes the error model the protocol is run with the one the workflow uses."""
    res = AR1Error(rms, OBS_T, corr).sample(np.random.default_rng(seed), n)
    return emulator_error_model(res, OBS_T)[0]


def record_errors(records, *, model_error=True):
    noise = noise_model()
    emu = model_error_model() if model_error else None
    return RecordErrors({r: noise for r in records}, {r: emu for r in records} if model_error else {})


def observe(model: StandIn, truth_by_record, seed):
    """Noisy observations per record: ``truth_by_record[r]`` maps the names of :func:`curves`' keywords."""
    rng = np.random.default_rng(seed)
    noise = noise_model()
    out = {}
    for r in model.K:
        clean = curves(OBS_T, model.K[r], **truth_by_record[r])[0]
        out[r] = clean + noise.sample(rng, 1)[0]
    return out
