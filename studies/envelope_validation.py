"""A closed loop's first and last models on an independent flight test, hover to 100 kt (docs/close_loop.md).

The study is ``pyomo_heli.studies.envelope_validation``;
``python studies/envelope_validation.py --help`` lists its options.
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without installing

from pyomo_heli.studies.envelope_validation import main  # noqa: E402
from pyomo_heli.studies.commands import exit_status  # noqa: E402

if __name__ == "__main__":
    sys.exit(exit_status(main, "envelope_validation"))
