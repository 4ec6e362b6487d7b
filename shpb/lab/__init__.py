"""Measured SHPB records: the bars and measurement chain (:mod:`.bars`), readers of the shipped lab
formats (:mod:`.records`), the reduction to specimen stress, strain rate and force balance
(:mod:`.reduction`), and the reduction check against the authors' values (:mod:`.reduction_table`).
Knows no inference."""
