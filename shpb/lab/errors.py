"""The error a reduction raises when a record cannot be reduced, with the set-up fields that decide it.

A reduction knows the :class:`~shpb.lab.bars.BarSetup` and its own options, not where they came from; a
caller that does (a test sheet, :func:`shpb.lab.lab_reduce.reduce_sheet`) turns ``fields`` into the names
the user wrote, so the message says which line of the sheet to look at.
"""
from __future__ import annotations

__all__ = ["ReductionError"]


class ReductionError(ValueError):
    """A record could not be reduced. ``fields``: the names that set what failed, among the
    :class:`~shpb.lab.bars.BarSetup` attributes (``E``, ``rho``, ``gauge_distance_incident``,
    ``gauge_distance_transmitted``, ``compression_sign``, ``strain_per_volt``) and the reduction's
    ``window_s`` and ``time`` (the record's time axis, i.e. its unit or sampling interval)."""

    def __init__(self, message: str, fields: tuple[str, ...] = ()):
        self.fields = tuple(fields)
        super().__init__(message)
