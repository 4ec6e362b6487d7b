"""Where a Snakemake run's time went, per rule, from its log (``.snakemake/log/*.snakemake.log`` or the
captured console output of ``snakemake --cores N``).

    python tools/job_times.py .snakemake/log/2026-11-27T204751.snakemake.log

Snakemake stamps each job's start (``[date]`` then ``rule``/``checkpoint`` and its ``jobid``) and end
(``[date]`` then ``Finished jobid: N``) to the second. Per rule: the number of jobs, the sum and mean of
their durations (the one simulating rule split by its ``stage`` wildcard, ``simulate[design]``: what
each stage of a calibration or a leave-one-record-out series costs); per experiment (the ``exp``
wildcard: each fold of a series), the summed job time; and the run's span, the summed job time over the span (the cores' mean occupancy: on 2
cores a value near 2 means the jobs themselves, not the scheduling, set the run's length). Durations
are whole seconds: a mean over many jobs is good to a few tenths of a second. Prints one JSON object.
"""

from __future__ import annotations

import json
import re
import sys
from collections import defaultdict
from datetime import datetime

_STAMP = re.compile(r"^\[(\w{3} \w{3} +\d+ \d\d:\d\d:\d\d \d{4})\]$")
_RULE = re.compile(r"^(?:local)?(?:rule|checkpoint) (\w+):")
_JOBID = re.compile(r"^\s+jobid: (\d+)")
_WILDCARDS = re.compile(r"^\s+wildcards: (.*)$")
_DONE = re.compile(r"^Finished jobid: (\d+) \(Rule: (\w+)\)")


def job_times(lines) -> dict:
    """Per-rule job counts and durations [s] and the run's span from a Snakemake log's lines."""
    stamp, rule = None, None
    start, rule_of, end, exp_of, job = {}, {}, {}, {}, None
    for line in lines:
        line = line.rstrip("\n")
        if m := _STAMP.match(line):
            stamp, rule = datetime.strptime(m.group(1), "%a %b %d %H:%M:%S %Y"), None
        elif m := _RULE.match(line):
            rule = m.group(1)
        elif (m := _JOBID.match(line)) and rule and stamp:
            job = int(m.group(1))
            start[job], rule_of[job] = stamp, rule
        elif (m := _WILDCARDS.match(line)) and job is not None and rule_of.get(job) == rule:
            wildcards = dict(w.split("=", 1) for w in m.group(1).split(", ") if "=" in w)
            if "stage" in wildcards:
                rule_of[job] = f"{rule}[{wildcards['stage']}]"
            if "exp" in wildcards:
                exp_of[job] = wildcards["exp"]
        elif (m := _DONE.match(line)) and stamp:
            end[int(m.group(1))] = stamp
    done = [j for j in start if j in end]
    if not done:
        raise ValueError("no job with both a start and a 'Finished jobid' line: is this a Snakemake log?")
    per_rule: dict[str, list[float]] = defaultdict(list)
    for j in done:
        per_rule[rule_of[j]].append((end[j] - start[j]).total_seconds())
    span = (max(end[j] for j in done) - min(start[j] for j in done)).total_seconds()
    total = sum(sum(v) for v in per_rule.values())
    per_exp: dict[str, float] = defaultdict(float)
    for j in done:
        if j in exp_of:
            per_exp[exp_of[j]] += (end[j] - start[j]).total_seconds()
    rules = {r: {"jobs": len(v), "sum_s": sum(v), "mean_s": round(sum(v) / len(v), 2), "max_s": max(v)}
             for r, v in sorted(per_rule.items(), key=lambda kv: -sum(kv[1]))}
    return {"span_s": span, "jobs": len(done), "job_time_sum_s": total,
            "mean_occupancy": round(total / span, 3) if span > 0 else None, "rules": rules,
            "experiments": dict(sorted(per_exp.items()))}


def main(argv=None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 1:
        raise SystemExit("usage: python tools/job_times.py <snakemake log>")
    with open(argv[0], encoding="utf-8") as fh:
        print(json.dumps(job_times(fh), indent=1))


if __name__ == "__main__":
    main()
