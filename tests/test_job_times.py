"""tools/job_times.py on a log in Snakemake 9's format: per-rule durations and the cores' occupancy."""

import pytest

from tools.job_times import job_times

LOG = """Select jobs to execute...
Execute 2 jobs...

[Fri Nov 27 20:47:53 2026]
localrule truth:
    jobid: 6
    reason: Missing output files: results/twin_ref/truth/synthetic/curve.csv
Shell command: None

[Fri Nov 27 20:47:53 2026]
localrule simulate:
    jobid: 42
    wildcards: exp=twin_ref, stage=member, key=iter_0, batch=1
Select jobs to execute...
[Fri Nov 27 20:47:57 2026]
Finished jobid: 42 (Rule: simulate)
1 of 4 steps (25%) done

[Fri Nov 27 20:47:57 2026]
localcheckpoint analysis:
    jobid: 40
[Fri Nov 27 20:47:59 2026]
Finished jobid: 40 (Rule: analysis)
[Fri Nov 27 20:48:03 2026]
Finished jobid: 6 (Rule: truth)
[Fri Nov 27 20:48:03 2026]
rule member:
    jobid: 43
"""


def test_durations_per_rule_and_occupancy():
    out = job_times(LOG.splitlines())
    assert out["jobs"] == 3  # job 43 never finished: left out
    assert out["rules"]["truth"] == {"jobs": 1, "sum_s": 10.0, "mean_s": 10.0, "max_s": 10.0}
    assert out["rules"]["simulate[member]"]["sum_s"] == 4.0 and out["rules"]["analysis"]["sum_s"] == 2.0
    assert out["span_s"] == 10.0
    assert out["mean_occupancy"] == pytest.approx(1.6)
    assert list(out["rules"]) == ["truth", "simulate[member]", "analysis"]
    assert out["experiments"] == {"twin_ref": 4.0}  # the only job whose wildcards name an experiment


def test_not_a_log():
    with pytest.raises(ValueError, match="Snakemake log"):
        job_times(["hello", "world"])
