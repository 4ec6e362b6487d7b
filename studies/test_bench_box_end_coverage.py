"""The box-end stand-in benchmark compares an ES-MDA that sees the data with the exact posterior
(studies/bench_box_end_coverage.py): on a few twins both arms' 90 % intervals are a small part of
the box and of comparable width. An ES-MDA handed the variances as standard deviations sees no data and
returns the prior (about 0.9 of the box), which this test fails."""

from studies.bench_box_end_coverage import run


def test_both_arms_learn_from_the_data_and_agree_in_width():
    out = run(twins=4, noise=0.05, transform="logit", seed=3, members=200, steps=8, grid=161)
    for p in ("sigma_t", "E_t"):
        es, ex = out[p]["esmda"]["width_over_box_median"], out[p]["exact"]["width_over_box_median"]
        assert es < 0.3 and ex < 0.3
        assert 0.5 < es / ex < 2.0
