"""Whiteness of the exact model's residuals with and without the input noise taken out (docs/close_loop.md).

The study is ``pyomo_heli.studies.innovation_check``;
``python studies/innovation_check.py --help`` lists its options.
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without installing

from pyomo_heli.studies.innovation_check import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
