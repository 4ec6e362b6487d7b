"""Planted closure law (issue 32 item 5): the three closure effects are told apart on real FDEM runs.

Twin data: a fast cylinder member driven by CaMa_SHPB_004's measured incident wave (injected 0.1 m
from the specimen, to keep the runs short), base parameters at the default run's marble calibration
(sigma_t 34.9 MPa, E_t 27.5 kJ/m^2, known here), with the gradual closure switched on (mean gap
135 um spread over 150 um across the face: first touch at 60 um, full contact at 210 um), 0-170 us on
a 1 us grid, plus white noise of 1.5 % of the curve's maximum (0.57 MPa, the records' own noise is
0.6-0.7 MPa). Each closure law is then fitted by least squares with real FDEM runs, inside its
catalogue box, from the fitted hard gap and the middle of its box: the hard gap (``face_gap.gap_m``,
bounded Brent, 8 runs), and the two laws that add a parameter to it, the linear seating
(``seating.compliance_m_per_Pa``, Nelder-Mead, 14 runs) and the gradual closure (``closure.range_m``,
two Gauss-Newton steps, 7 runs). Different optimisers, each the one that finds its law's minimum within
the budget: the seating's misfit is a curved valley along which Gauss-Newton crawls (59.5 -> 45.5 in
five steps, measured), where Nelder-Mead reaches 26.0 at (84 um, 1.78e-12 m/Pa); a 4 x 3 grid over
(50-95 um) x (1.6-2.0e-12 m/Pa) has its minimum at 25.1 (80 um, 2e-12, the top of the box). The
closure's misfit is nearly quadratic in (g, Delta) (correlation +0.14, shpb.effects), so two
Gauss-Newton steps converge. Measured (31 s on one core): chi^2 per observation 69.6 (hard gap,
132 um), 26.0 (gap + seating), 1.04 (gap + closure: g 136 um, Delta 155 um); the truth's own is 0.86.
The planted law fits to the noise level, the other two do not (chi^2 per observation, noise = 1).
"""

from __future__ import annotations

import numpy as np
from scipy import optimize

from shpb.simulate import simulate

RECORD = "freiburg-rae-rock-shpb/Rae2021/SHPBdata/CaMa/CaMa_SHPB_004_Ti25_50b_Al12b_0_001.txt"
# E: the specimen modulus of the measured numbers above (the spreadsheet row's, which the model took for
# this record then; it now takes the rock's 44.8 GPa): twin data and model share it either way
BASE = {"sigma_t": 34.9e6, "E_t": 27.5e3, "E": 33.9e9}
T_END = 170e-6
OBS_T = np.arange(0.0, T_END + 1e-12, 1e-6)
TRUTH = {"face_gap.gap_m": 135e-6, "closure.range_m": 150e-6}
NOISE_FRACTION = 0.015
GAP, SEATING, CLOSURE = "face_gap.gap_m", "seating.compliance_m_per_Pa", "closure.range_m"
BOX = {GAP: (0.0, 400e-6), SEATING: (0.0, 2e-12), CLOSURE: (0.0, 400e-6)}  # the catalogue's (shpb.effects)


def _record():
    from shpb.paths import data_dir, data_file
    return data_file(data_dir() / RECORD)


def run(params: dict) -> np.ndarray:
    out = simulate("cylinder", "fast", params={**BASE, **params}, record=_record(), t_end=T_END,
                   sample_dt=0.5e-6, injection_distance_m=0.1)
    assert out.run["status"] == "ok", out.run["reason"]
    return np.interp(OBS_T, out.curve.time_s.to_numpy(), out.curve.stress_Pa.to_numpy())


def fit_pair(chi2, gap0: float, name: str) -> tuple[dict, float]:
    """Nelder-Mead on (gap, name) in units of their boxes, from (gap0, middle of name's box), 14 runs."""
    lo = np.array([BOX[GAP][0], BOX[name][0]])
    width = np.array([BOX[GAP][1], BOX[name][1]]) - lo
    x0 = (np.array([gap0, lo[1] + 0.5 * width[1]]) - lo) / width
    simplex = np.array([x0, x0 + [-0.1, 0.0], x0 + [0.0, -0.25]])

    def f(z):
        v = lo + np.clip(z, 0.0, 1.0) * width
        return chi2({GAP: v[0], name: v[1]})
    r = optimize.minimize(f, x0, method="Nelder-Mead",
                          options={"maxfev": 14, "initial_simplex": simplex, "xatol": 0.01, "fatol": 0.05})
    v = lo + np.clip(r.x, 0.0, 1.0) * width
    return {GAP: float(v[0]), name: float(v[1])}, float(r.fun)


def gauss_newton(resid, x0: np.ndarray, h: np.ndarray, lo: np.ndarray, hi: np.ndarray, iterations: int = 3):
    """Least squares by Gauss-Newton inside the box, forward-difference Jacobian (steps h): each
    iteration costs len(x) + 1 runs; a step that does not lower the misfit is halved once, else the fit
    stops. Returns (x, chi^2 per observation)."""
    x, r = np.array(x0, float), resid(x0)
    for _ in range(iterations):
        J = np.column_stack([(resid(x + h[j] * np.eye(len(x))[j]) - r) / h[j] for j in range(len(x))])
        dx = np.linalg.lstsq(J, -r, rcond=None)[0]
        for step in (1.0, 0.5):
            x1 = np.clip(x + step * dx, lo, hi)
            r1 = resid(x1)
            if r1 @ r1 < r @ r:
                x, r = x1, r1
                break
        else:
            break
    return x, float(r @ r / r.size)


def test_planted_gradual_closure_fits_to_the_noise_where_the_hard_gap_and_linear_seating_do_not():
    truth = run(TRUTH)
    sigma = NOISE_FRACTION * truth.max()
    obs = truth + sigma * np.random.default_rng(5).standard_normal(OBS_T.size)

    def resid(params):  # in units of the noise sd
        return (run(params) - obs) / sigma

    hard = optimize.minimize_scalar(lambda g: float(np.mean(resid({GAP: g}) ** 2)), bounds=(50e-6, 300e-6),
                                    method="bounded", options={"xatol": 3e-6, "maxiter": 8})
    seat, chi_seat = fit_pair(lambda v: float(np.mean(resid(v) ** 2)), hard.x, SEATING)
    lo, hi = np.array([BOX[GAP][0], BOX[CLOSURE][0]]), np.array([BOX[GAP][1], BOX[CLOSURE][1]])
    x, chi_clos = gauss_newton(lambda v: resid({GAP: v[0], CLOSURE: v[1]}), np.array([hard.x, 0.5 * hi[1]]),
                               np.array([4e-6, 8e-6]), lo, hi, iterations=2)
    clos = {GAP: float(x[0]), CLOSURE: float(x[1])}
    print(f"\nplanted closure (g 135 um, Delta 150 um, noise {sigma / 1e6:.2f} MPa), chi^2 per observation: "
          f"hard gap {hard.fun:.1f} (g {hard.x * 1e6:.0f} um); gap + linear seating {chi_seat:.1f} "
          f"(g {seat[GAP] * 1e6:.0f} um, C {seat[SEATING]:.2e} m/Pa); gap + gradual closure {chi_clos:.2f} "
          f"(g {clos[GAP] * 1e6:.0f} um, Delta {clos[CLOSURE] * 1e6:.0f} um)")
    assert chi_clos < 1.5, (chi_clos, clos)                     # the planted law: at the noise level
    assert hard.fun > 20.0 and chi_seat > 10.0, (hard.fun, chi_seat)
    assert chi_clos < 0.2 * min(hard.fun, chi_seat)              # ranked first, by a wide margin
    assert abs(clos[GAP] - TRUTH[GAP]) < 10e-6 and abs(clos[CLOSURE] - TRUTH[CLOSURE]) < 20e-6, clos
