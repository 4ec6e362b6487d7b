"""The simulator's file contract, in one light module that the workflow imports without the engine.

``python -m shpb simulate`` writes ``DIR/curve.csv`` with :data:`CURVE_COLUMNS` (SI units) and
``DIR/run.json``; it exits with :data:`EXIT_OK`, :data:`EXIT_BAD_INPUT` or :data:`EXIT_NUMERICAL`
(the run failed numerically; run.json says why). A failed member's ``curve.csv`` is the header alone.
"""

#: Columns of a simulated curve, in file order.
CURVE_COLUMNS = ("time_s", "stress_Pa", "stress_front_Pa", "stress_back_Pa", "force_balance", "centre_sxx_Pa",
                 "centre_syy_Pa", "eps_incident_gauge", "eps_transmitted_gauge")

#: Exit codes of ``python -m shpb simulate``.
EXIT_OK, EXIT_BAD_INPUT, EXIT_NUMERICAL = 0, 2, 3
