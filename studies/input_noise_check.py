"""Anchor A with the truth's model form, with and without the noise on the measured inputs (docs/uncertainty.md).

The study is ``pyomo_heli.studies.input_noise_check``;
``python studies/input_noise_check.py --help`` lists its options.
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without installing

from pyomo_heli.studies.input_noise_check import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
