"""Identification, not just improvement: which candidates the calibration records tell apart from the one
a selection round chose.

Effects that act alike on the data (in an SHPB series: a face gap, a trigger shift, a gradual closure and
a seating layer all move the onset) can each lower the cross-validated error by about as much. Naming the
one that happened to come out first would claim more than the data say. :func:`identification_group`
puts each other candidate of the round through the same paired comparison the round itself used
(:func:`~.crossval.compare_cv`, here the chosen model's cross-validated predictions against that
candidate's, on the same calibration records and error terms): a candidate the chosen one does not beat
at the level stays in the chosen one's group. The level is Bonferroni-corrected over the candidates
compared, so "told apart" holds for all of them at once; being left in the group is the cautious
outcome, never the bold one. Candidates the round did not try (a score-test ranking left them out) are
listed apart: nothing was measured on them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from statistics import NormalDist

import numpy as np

from .crossval import RecordErrors, compare_cv

__all__ = ["identification_group", "group_text"]


def identification_group(best: Mapping, trials: Sequence[Mapping], obs: Mapping[str, np.ndarray],
                         errors: RecordErrors, *, level: float, not_tried: Sequence[str] = (),
                         spreads: bool = False) -> dict:
    """The chosen candidate's group in one round.

    ``best`` and ``trials``: the round's trials (``candidate`` with a ``name``, ``cv`` a
    :class:`~.crossval.CVResult` over the calibration records); ``obs`` the calibration records'
    observations; ``level`` the one-sided level of "the chosen one predicts better", Bonferroni over the
    other trials; ``spreads``: add each prediction's own calibration spread (as the round did).

    Returns ``{"chosen", "effects"`` (the group, chosen first), ``"level", "z_critical", "evidence"``
    (per other trial: ``delta`` of the squared-error sums, > 0 when the chosen one is better, ``sd``,
    ``z``, ``told_apart``), ``"not_tried"}``."""
    name = best["candidate"].name
    others = [t for t in trials if t["candidate"].name != name]
    z_crit = NormalDist().inv_cdf(1.0 - level / max(len(others), 1))
    records = list(best["cv"].folds)
    chosen = {j: best["cv"].curve(j) for j in records}
    evidence = []
    for t in others:
        kw = ({"spread_current": {j: t["cv"].spread(j) for j in records},
               "spread_candidate": {j: best["cv"].spread(j) for j in records}} if spreads else {})
        cmp = compare_cv(obs, {j: t["cv"].curve(j) for j in records}, chosen, errors, **kw,
                         names_current=t["cv"].spec.names(records), names_candidate=best["cv"].spec.names(records))
        evidence.append({"effect": t["candidate"].name, "delta_sq_error": cmp["delta"], "sd": cmp["sd"],
                         "z": cmp["z"], "told_apart": bool(cmp["z"] > z_crit)})
    group = [name] + [e["effect"] for e in evidence if not e["told_apart"]]
    return {"chosen": name, "effects": group, "level": level, "z_critical": z_crit, "evidence": evidence,
            "not_tried": list(not_tried)}


def group_text(group: Mapping) -> str:
    """One sentence for the report: whether the data name the effect or only its group."""
    name, alike = group["chosen"], [e for e in group["effects"] if e != group["chosen"]]
    z = {e["effect"]: e["z"] for e in group["evidence"]}
    untried = (f"; not tried, so not ruled out: {', '.join(group['not_tried'])}" if group["not_tried"] else "")
    if not alike:
        return (f"{name} is told apart from every other candidate tried (its cross-validated error is lower, "
                f"z above {group['z_critical']:.2f}){untried}")
    told = ", ".join(f"{e} (z = {z[e]:.2f})" for e in alike)
    return (f"the calibration records do not tell {name} apart from {told}: the effect is one of the group "
            f"{', '.join(group['effects'])} (z below {group['z_critical']:.2f}, one-sided, Bonferroni over "
            f"{len(group['evidence'])} candidate(s)){untried}")
