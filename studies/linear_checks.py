"""The local-linear-model checks of docs/linear.md on bo105_clean.

The study is ``pyomo_heli.studies.linear_checks``;
``python studies/linear_checks.py --help`` lists its options.
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without installing

from pyomo_heli.studies.linear_checks import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
