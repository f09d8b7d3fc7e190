"""Stored sessions in other tools' formats: MCAP for Foxglove and PlotJuggler (:mod:`aerobat.export.mcap`)."""

from aerobat.export.mcap import McapSummary, write_session_mcap

__all__ = ["McapSummary", "write_session_mcap"]
