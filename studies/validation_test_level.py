"""How often the validation rule's paired test fires when no output got worse (docs/close_loop.md).

The study is ``pyomo_heli.studies.validation_test_level``;
``python studies/validation_test_level.py --help`` lists its options.
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without installing

from pyomo_heli.studies.validation_test_level import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
