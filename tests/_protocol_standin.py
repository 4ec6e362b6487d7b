"""A vectorised stand-in for the protocol tests (tests/test_protocol_*.py): an analytic SHPB-like surrogate
per record, with the catalogue's face gap, trigger shift, gauge gain, baseline offset and rate-dependent
strength written into the formula (no per-member loop).

Curve of record r (loading slope K_r [Pa/s], its input, like an incident wave): an elastic rise
K_r * FOOT * softplus((t - t0) / FOOT) from the arrival t0 = T0 + gap / V_FACE + dt up to the strength
sigma_p * DIF, DIF = max(1, 1 + k log10(rate_r / 1 s^-1)), rate_r = K_r / E_SPECIMEN; then an
exponential decay with time constant tau_d; the result times the gain g plus the offset.
"""

from __future__ import annotations

from pathlib import Path

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


def _diagnosis_default(key: str):
    """The schema's default of ``diagnosis.<key>`` (config/schema.yaml): the tests walk as the workflow does."""
    from calibration.config_check import load_yaml

    schema = load_yaml(Path(__file__).resolve().parents[1] / "config" / "schema.yaml")
    return schema["properties"]["experiments"]["additionalProperties"]["properties"]["diagnosis"]["properties"][key][
        "default"]


#: the round's proposals after its choice that the workflow's walk tries on the real simulator
ALTERNATIVES = _diagnosis_default("alternatives")


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


def heldout_gap_coverage(seeds, mu=100e-6, tau=25e-6, n_members=80):
    """The measurement quoted in test_protocol_population.py (not run by the tests, ~1.3 s a seed): per
    seed every record's gap drawn from N(mu, tau^2), the protocol on five calibration records, and
    whether the held-out record's true gap lies inside its predictive 90 % interval. Returns
    ``(chosen, covered, rmse_ratios)``."""
    from enkf.diagnosis import heldout_evaluation, select_effects
    K = {"A": 0.6e12, "B": 0.8e12, "C": 1.0e12, "D": 1.2e12, "E": 1.4e12, "H": 0.9e12}
    model, err = StandIn(K), record_errors(list(K))
    chosen, covered, ratios = 0, 0, []
    for seed in seeds:
        rng = np.random.default_rng(100 + seed)
        gaps = {r: float(np.clip(rng.normal(mu, tau), 0.0, 4e-4)) for r in K}
        obs = observe(model, {r: dict(**TRUTH, gap=gaps[r]) for r in K}, seed=200 + seed)
        sel = select_effects(model, base_names=BASE, candidates=[fx.get_effect("face_gap"), fx.get_effect("gauge_gain")],
                             calib_records=list("ABCDE"), heldout_records=["H"], obs={r: obs[r] for r in "ABCDE"},
                             errors=err, seed=seed, n_members=n_members, max_additions=1)
        ev = heldout_evaluation(sel, obs, {r: OBS_T for r in K})["H"]
        if sel.last.spec.effect_names == ["face_gap"]:
            chosen += 1
            lo, hi = ev["after"]["intervals"]["face_gap.gap_m@H"]
            covered += lo <= gaps["H"] <= hi
        ratios.append(ev["after"]["rmse"] / ev["before"]["rmse"])
    return chosen, covered, ratios


RATE_K = {"R14": 0.5e12, "R20": 0.7e12, "R29": 1.0e12, "R40": 1.4e12}  # strain rates K / E = 14-40 /s
RATE_TRUTH = {"sigma_p": 30e6, "tau_d": 45e-6, "k": 0.3}


def rate_series(seed, n_members=80, candidates=("rate_strength", "gauge_gain", "trigger_shift")):
    """The planted shared effect of test_protocol_selection.py: strength x (1 + k log10(rate / 1 s^-1)),
    k = 0.3, four records at four loading rates, the protocol once per record held out
    (:func:`enkf.diagnosis.leave_one_record_out`)."""
    from enkf.diagnosis import leave_one_record_out
    model = StandIn(RATE_K)
    obs = observe(model, {r: RATE_TRUTH for r in RATE_K}, seed=seed)
    return leave_one_record_out(model, list(RATE_K), obs, {r: OBS_T for r in RATE_K}, record_errors(list(RATE_K)),
                                base_names=BASE, candidates=[fx.get_effect(c) for c in candidates], seed=seed,
                                n_members=n_members, esmda_steps=4, max_additions=2)


def rate_series_reliability(seeds, n_members=80):
    """The measurement quoted in test_protocol_selection.py (not run by the tests, ~3.5 s a seed): over
    seeds and folds, how often rate_strength is kept, anything else is kept, the truth of k lies in the
    final calibration's 90 % interval, the base calibration's sigma_p interval misses its truth, and the
    held-out RMSE falls."""
    n = named = extra = covered = base_miss = improved = 0
    for seed in seeds:
        out = rate_series(seed, n_members)
        for h, sel in out["selections"].items():
            row = out["table"].set_index("heldout").loc[h]
            n += 1
            named += "rate_strength" in row["effects"].split(",")
            extra += row["n_effects"] > 1
            if "rate_strength.k_q05" in row and np.isfinite(row["rate_strength.k_q05"]):
                covered += row["rate_strength.k_q05"] <= RATE_TRUTH["k"] <= row["rate_strength.k_q95"]
            b = sel.steps[0].final.posterior()["sigma_p"]
            base_miss += not b["q05"] <= RATE_TRUTH["sigma_p"] <= b["q95"]
            improved += row["rmse_change"] < 0
    return {"folds": n, "named": named, "extra_effect": extra, "k_covered": covered, "base_sigma_p_missed": base_miss,
            "heldout_improved": improved}
