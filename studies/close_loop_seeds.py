"""The full-size closed loop on several noise realisations, and how often each criterion holds (docs/close_loop.md).

The study is ``pyomo_heli.studies.close_loop_seeds``;
``python studies/close_loop_seeds.py --help`` lists its options.
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without installing

from pyomo_heli.studies.close_loop_seeds import main  # noqa: E402
from pyomo_heli.studies.commands import exit_status  # noqa: E402

if __name__ == "__main__":
    sys.exit(exit_status(main, "close_loop_seeds"))
