"""An interpolating emulator of a simulator's response curves over a parameter box.

Used where a step needs many more model evaluations than the simulator can afford, e.g. the
re-calibrations of the frozen protocol (:mod:`enkf.diagnosis`) or the emulated analyses
(:mod:`enkf.emulated`): a design of simulator runs, then a radial-basis-function interpolant (SciPy's
``RBFInterpolator``; thin-plate spline plus a linear polynomial by default) of the whole curve, with
inputs scaled to the unit box so that no parameter's units dominate the distances.

The emulator is not the model: its error is measured by leave-one-out cross-validation at the design
points (:meth:`CurveEmulator.loo_residuals`, exact refits, not an approximation) and is carried as a
time-correlated error term of the observations (:func:`enkf.emulated.emulator_error_model`: per-time rms
with AR(1) correlation), so that a calibration on the emulator does not read interpolation error as
signal (Kennedy & O'Hagan's "code uncertainty").
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
from scipy.interpolate import RBFInterpolator

__all__ = ["AnchoredEmulator", "CurveEmulator", "SMOOTHING_GRID", "smoothed_emulator", "design_arrays"]


class CurveEmulator:
    """``(N, n)`` parameters -> ``(N, m)`` curves, interpolating a design of runs.

    X : (n_design, n) design parameters (finite, inside ``[lower, upper]``).
    Y : (n_design, m) the simulator's curves (finite; drop failed runs before).
    lower, upper : the box the emulator is valid in; evaluations outside it raise.
    kernel, degree, smoothing : passed to ``scipy.interpolate.RBFInterpolator``.
    """

    def __init__(self, X, Y, lower, upper, *, names: Sequence[str] | None = None,
                 kernel: str = "thin_plate_spline", degree: int = 1, smoothing: float = 0.0):
        X = np.array(X, dtype=float, ndmin=2)
        Y = np.array(Y, dtype=float, ndmin=2)
        self.lower = np.asarray(lower, dtype=float)
        self.upper = np.asarray(upper, dtype=float)
        n = self.lower.size
        if X.shape[1] != n or self.upper.shape != (n,):
            raise ValueError(f"design has {X.shape[1]} columns, box has {n} / {self.upper.size} bounds")
        if X.shape[0] != Y.shape[0]:
            raise ValueError(f"{X.shape[0]} design points but {Y.shape[0]} curves")
        if not (np.all(np.isfinite(X)) and np.all(np.isfinite(Y))):
            raise ValueError("design and curves must be finite (drop failed runs first)")
        if np.any(self.upper <= self.lower):
            raise ValueError("every upper bound must exceed its lower bound")
        self.names = list(names) if names is not None else [f"x{i}" for i in range(n)]
        self.X, self.Y = X, Y
        self._kw = {"kernel": kernel, "degree": degree, "smoothing": smoothing}
        self._rbf = RBFInterpolator(self._unit(X, check=True), Y, **self._kw)
        self._loo: np.ndarray | None = None

    @property
    def n_params(self) -> int:
        return self.lower.size

    @property
    def m(self) -> int:
        return self.Y.shape[1]

    def _unit(self, P, check: bool = True) -> np.ndarray:
        P = np.array(P, dtype=float, ndmin=2)
        if P.shape[1] != self.n_params:
            raise ValueError(f"expected {self.n_params} parameters per row, got {P.shape[1]}")
        u = (P - self.lower) / (self.upper - self.lower)
        if check and (np.any(u < -1e-9) or np.any(u > 1 + 1e-9)):
            bad = np.argwhere((u < -1e-9) | (u > 1 + 1e-9))[0]
            raise ValueError(f"{self.names[bad[1]]} = {P[bad[0], bad[1]]:g} is outside the emulator's box "
                             f"[{self.lower[bad[1]]:g}, {self.upper[bad[1]]:g}]")
        return u

    def __call__(self, P) -> np.ndarray:
        return self._rbf(self._unit(P))

    def loo_residuals(self) -> np.ndarray:
        """``(n_design, m)``: curve minus its prediction by the emulator refitted without that point."""
        if self._loo is None:
            U = self._unit(self.X)
            out = np.empty_like(self.Y)
            for i in range(self.X.shape[0]):
                keep = np.arange(self.X.shape[0]) != i
                out[i] = self.Y[i] - RBFInterpolator(U[keep], self.Y[keep], **self._kw)(U[i:i + 1])[0]
            self._loo = out
        return self._loo


#: Smoothing values tried by ``smoothing="loo"`` (SciPy's RBF ``smoothing``, inputs in the unit box).
SMOOTHING_GRID = (0.0, 1e-4, 1e-3, 1e-2, 1e-1, 1.0, 10.0, 100.0)


def smoothed_emulator(X, Y, lo, hi, names, latest, smoothing="loo", scale=None) -> tuple[CurveEmulator, dict]:
    """``(emulator, info)`` with the RBF smoothing (the emulator's nugget) given, or with ``"loo"`` the
    value of :data:`SMOOTHING_GRID` with the least leave-one-out error at the ``latest`` runs, each
    output's residual divided by ``scale`` (m,) where given (e.g. the data's error sd per time, so that
    the post-peak scatter of a fracture curve does not outvote the rise where the parameters act).

    A fracture simulator is rugged between its runs (another crack path at a nearby parameter point,
    another mesh realization on every run): an interpolant then threads every run's own departure and
    the likelihood on it is a field of needles. A smoothed one treats that scatter as error, which its
    leave-one-out residuals then carry into the emulator's error term; the leave-one-out choice finds
    how much smoothing the runs' scatter asks for without being told its size."""
    if smoothing != "loo":
        return CurveEmulator(X, Y, lo, hi, names=names, smoothing=float(smoothing)), {"smoothing": float(smoothing)}
    w = 1.0 if scale is None else 1.0 / np.asarray(scale, dtype=float)
    best, scores = None, {}
    for value in SMOOTHING_GRID:
        em = CurveEmulator(X, Y, lo, hi, names=names, smoothing=value)
        scores[value] = float(np.sqrt(np.mean((em.loo_residuals()[latest] * w) ** 2)))
        if best is None or scores[value] < scores[best[0]]:
            best = (value, em)
    return best[1], {"smoothing": best[0], "loo_rms_by_smoothing": {str(k): v for k, v in scores.items()}}


def design_arrays(design_params, design_responses, latest, obs):
    """Checked ``(X, Y, latest, d)`` of an emulator design, each simulator parameter set once.

    The simulator is deterministic: a repeated parameter set adds nothing and would make the
    interpolation system singular, so its first run is kept, flagged latest if any copy is."""
    X = np.array(design_params, dtype=float, ndmin=2)
    Y = np.array(design_responses, dtype=float, ndmin=2)
    latest = np.asarray(latest, dtype=bool)
    d = np.asarray(obs, dtype=float)
    if X.shape[0] != Y.shape[0] or latest.shape != (X.shape[0],):
        raise ValueError(f"{X.shape[0]} design points, {Y.shape[0]} curves, {latest.size} latest flags")
    if Y.shape[1] != d.size:
        raise ValueError(f"curves have {Y.shape[1]} values, the observations {d.size}")
    _, first, inverse = np.unique(X, axis=0, return_index=True, return_inverse=True)
    if first.size < X.shape[0]:
        flags = np.bincount(inverse.ravel(), weights=latest.astype(float), minlength=first.size) > 0
        order = np.argsort(first)
        X, Y, latest = X[first[order]], Y[first[order]], flags[order]
    return X, Y, latest, d


def _chords(v, D, x) -> np.ndarray:
    """``(len(x), m)``: the piecewise-linear interpolant of rows ``D`` at sorted values ``v`` (at least
    two), evaluated at ``x``; the end segments extend linearly past the outermost values."""
    i = np.clip(np.searchsorted(v, x), 1, v.size - 1)
    w = (x - v[i - 1]) / (v[i] - v[i - 1])
    return D[i - 1] + w[:, None] * (D[i] - D[i - 1])


class AnchoredEmulator:
    """``(N, n)`` parameters -> ``(N, m)`` curves: a first-order anchored surrogate (cut-HDMR),

        f(x) = f(a) + sum_j [ f(a + (x_j - a_j) e_j) - f(a) ],

    each term interpolated piecewise-linearly along its own axis from runs that move that one parameter
    away from the anchor ``a`` (linearly extrapolated past the outermost runs of the axis). It is exact
    at every run it is built from and for any response additive in its parameters. Why it exists beside
    :class:`CurveEmulator`: one effect's response to its own parameter can be strongly nonlinear (an
    onset that moves with a gap), and a handful of runs along its axis resolve it where a space-filling
    design of the same size spread over every dimension cannot.

    ``pairs`` adds second-order terms where two parameters do not add: an end friction's confinement
    scales with the strength, so the friction's runs made at the base model's ``sigma_t`` overstate its
    increment at a lower one. For a pair ``(i, j)`` with runs at ``x_i = u`` and ``x_j = v_k`` the term
    ``g_k = f(u, v_k) - f(u, a_j) - f(a_i, v_k) + f(a)`` (the first-order parts read off the axes'
    chords) is interpolated along ``j`` as the axes are and scaled linearly in ``x_i``:
    ``g(x_i, x_j) = chord(x_j) (x_i - a_i) / (u - a_i)``, zero on both axes through the anchor.

    anchor : (n,) the anchor ``a``; anchor_curve : (m,) ``f(a)``.
    axes : ``{j: (values, curves)}``, per parameter index ``j`` the values it was moved to (``(k,)``,
        none equal to ``a_j``) and those runs' curves (``(k, m)``). A parameter without runs contributes
        nothing (held at the anchor).
    lower, upper : the box (bounds of the inputs, not checked: the terms extrapolate linearly).
    pairs : ``{(i, j): (u, values, curves)}``: runs with parameter ``i`` at ``u`` and ``j`` at each of
        ``values`` (``(k,)``, none equal to ``a_j``), the others at the anchor; both axes need runs.
    """

    # an emulator pickled before pairs existed (a selection.pkl of an earlier run) has none
    _pairs: dict = {}

    def __init__(self, anchor, anchor_curve, axes, lower, upper, *, names: Sequence[str] | None = None,
                 pairs=None):
        self.anchor = np.asarray(anchor, dtype=float)
        self.f0 = np.asarray(anchor_curve, dtype=float)
        self.lower = np.asarray(lower, dtype=float)
        self.upper = np.asarray(upper, dtype=float)
        n = self.anchor.size
        if self.lower.shape != (n,) or self.upper.shape != (n,):
            raise ValueError(f"anchor has {n} parameters, box {self.lower.size} / {self.upper.size} bounds")
        if self.f0.ndim != 1 or not np.all(np.isfinite(self.f0)):
            raise ValueError("the anchor's curve must be one finite curve")
        self.names = list(names) if names is not None else [f"x{i}" for i in range(n)]
        self._axes = {}
        for j, (values, curves) in axes.items():
            v = np.asarray(values, dtype=float).ravel()
            Y = np.array(curves, dtype=float, ndmin=2)
            if not 0 <= int(j) < n or Y.shape != (v.size, self.f0.size) or not np.all(np.isfinite(Y)):
                raise ValueError(f"axis {j}: {v.size} values and curves of shape {Y.shape} (need finite "
                                 f"({v.size}, {self.f0.size}), parameter index below {n})")
            if v.size == 0:
                continue
            # relative to the box: a parameter's units may be 1e-12 (a compliance in m/Pa)
            if np.any(np.abs(v - self.anchor[j]) <= 1e-9 * (self.upper[j] - self.lower[j])):
                raise ValueError(f"axis {j} has a run at the anchor's own value {self.anchor[j]:g}")
            order = np.argsort(np.concatenate([[self.anchor[j]], v]))
            self._axes[int(j)] = (np.concatenate([[self.anchor[j]], v])[order],
                                  np.vstack([np.zeros_like(self.f0), Y - self.f0])[order])
        self._pairs = {}
        for (i, j), (u, values, curves) in (pairs or {}).items():
            self._pairs[(int(i), int(j))] = self._pair_term(int(i), int(j), float(u), values, curves)

    def _pair_term(self, i: int, j: int, u: float, values, curves):
        """``(u, values along j with the anchor's, second-order terms)`` of one pair (class docstring)."""
        v = np.asarray(values, dtype=float).ravel()
        Y = np.array(curves, dtype=float, ndmin=2)
        if i == j or i not in self._axes or j not in self._axes:
            raise ValueError(f"pair ({i}, {j}): two different parameters, each with axis runs, are needed")
        if Y.shape != (v.size, self.f0.size) or not np.all(np.isfinite(Y)) or v.size == 0:
            raise ValueError(f"pair ({i}, {j}): {v.size} values and curves of shape {Y.shape} (need finite "
                             f"({v.size}, {self.f0.size}))")
        if abs(u - self.anchor[i]) <= 1e-9 * (self.upper[i] - self.lower[i]):
            raise ValueError(f"pair ({i}, {j}): its runs must move parameter {i} off the anchor")
        if np.any(np.abs(v - self.anchor[j]) <= 1e-9 * (self.upper[j] - self.lower[j])):
            raise ValueError(f"pair ({i}, {j}) has a run at the anchor's own value of parameter {j}")
        vi, Di = self._axes[i]
        vj, Dj = self._axes[j]
        G = Y - self.f0 - _chords(vi, Di, np.array([u]))[0] - _chords(vj, Dj, v)
        order = np.argsort(np.concatenate([[self.anchor[j]], v]))
        return u, np.concatenate([[self.anchor[j]], v])[order], np.vstack([np.zeros_like(self.f0), G])[order]

    @property
    def n_params(self) -> int:
        return self.anchor.size

    @property
    def m(self) -> int:
        return self.f0.size

    def __call__(self, P) -> np.ndarray:
        P = np.array(P, dtype=float, ndmin=2)
        if P.shape[1] != self.n_params:
            raise ValueError(f"expected {self.n_params} parameters per row, got {P.shape[1]}")
        Y = np.broadcast_to(self.f0, (P.shape[0], self.m)).copy()
        for j, (v, D) in self._axes.items():
            Y += _chords(v, D, P[:, j])
        for (i, j), (u, v, G) in self._pairs.items():
            Y += _chords(v, G, P[:, j]) * ((P[:, i] - self.anchor[i]) / (u - self.anchor[i]))[:, None]
        return Y

    def loo_residuals(self) -> np.ndarray:
        """``(n_runs, m)``: each axis run's curve minus its prediction from the anchor and the other runs
        of its axis (the same piecewise-linear rule, so an end run is extrapolated from its neighbours),
        axis by axis in increasing parameter value (:meth:`loo_residuals_by_axis`, stacked). The anchor's
        own run is not left out: every term is built from it. This measures the error of interpolating
        along an axis, at twice the spacing of the runs (so it over-states the error between them); the
        first-order form's error away from the axes (interactions) it does not see."""
        return np.vstack([np.empty((0, self.m)), *self.loo_residuals_by_axis().values()])

    def loo_residuals_by_axis(self) -> dict[str, np.ndarray]:
        """``{parameter name: (k, m)}``: :meth:`loo_residuals` of each axis with runs."""
        out = {}
        for j, (v, D) in self._axes.items():
            rows = []
            for i in range(v.size):
                if v[i] == self.anchor[j]:
                    continue
                keep = np.arange(v.size) != i
                # the anchor alone (an axis of one run) predicts no change
                rows.append(D[i] - (_chords(v[keep], D[keep], v[i:i + 1])[0] if keep.sum() > 1 else 0.0))
            out[self.names[j]] = np.array(rows, dtype=float).reshape(-1, self.m)
        return out
