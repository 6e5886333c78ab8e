"""Flight-test dataset format ``pyomo_heli-flighttest`` v1: writer, loader, validator.

See ``docs/data_format.md`` for the on-disk format.  Loaded data are SI with angles in radians.
"""
from .reader import load_flight_test, validate_flight_test
from .schema import (
    FORMAT_NAME,
    FORMAT_VERSION,
    DatasetError,
    FlightTest,
    Maneuver,
    Problem,
)
from .writer import write_flight_test

__all__ = [
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "DatasetError",
    "FlightTest",
    "Maneuver",
    "Problem",
    "load_flight_test",
    "validate_flight_test",
    "write_flight_test",
]
