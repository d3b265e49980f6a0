"""Fleets of one robot model: every unit calibrated on a distributed engine, the fleet prior
(FLEET.json) learned from them, and its summary."""

from kincal.fleet.fleet import calibrate_fleet, learn_prior
from kincal.fleet.folders import commit_units, discard_staged
from kincal.fleet.summary import FleetSummary
from kincal.fleet.unit import UnitJob, UnitOutcome, calibrate_unit

__all__ = ["calibrate_fleet", "learn_prior", "FleetSummary", "UnitJob", "UnitOutcome",
           "calibrate_unit", "commit_units", "discard_staged"]
