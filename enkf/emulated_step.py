"""The emulated ES-MDA as a step of :class:`enkf.process.CalibrationProcess`: each analysis an ES-MDA on an
emulator of every successful run so far (:func:`enkf.emulated_esmda_update`).

A module of its own because the emulated analysis runs its inner ES-MDA with the in-process driver
(:func:`enkf.loop.assimilate`), which is a loop over the process: the process cannot import it back.
"""

from __future__ import annotations

from .emulated import EmulatedAnalysis, emulated_esmda_update
from .process import CalibrationProcess, Step, all_runs, register_analysis


def emulated_step(process: CalibrationProcess, step: Step, rng) -> tuple[EmulatedAnalysis, object]:
    """The next ensemble (as many members as this one) from the emulator of iterations ``0..k``'s runs."""
    k = step.iteration
    if len(process.runs) != k:
        raise ValueError(f"{process.label}, iteration {k}: emulated_esmda needs the runs of iterations "
                         f"0..{k - 1}, got {len(process.runs)} of them")
    tr, em = process.transform, process.emulated
    X, Y, latest = all_runs([p for p, _ in process.runs] + [step.params],
                            [y for _, y in process.runs] + [step.responses], step.alive)
    res = emulated_esmda_update(X, Y, latest, process.obs, step.terms.emulated(), lower=tr.lower, upper=tr.upper,
                                n_members=step.params.shape[0], rng=rng, times=em.times, groups=em.groups,
                                inner_members=em.inner_members, inner_steps=em.inner_steps,
                                temper=process.schedule.temper(k, process.criteria.max_iterations),
                                smoothing=em.smoothing, loo_scale=step.terms.loo_scale,
                                transform_kind=tr.kind, names=process.names)
    return res, res.params


register_analysis("emulated_esmda", emulated_step)
