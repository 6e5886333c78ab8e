"""How often the input path finds a signal when nothing is missing (docs/diagnosis.md).

The study is ``pyomo_heli.studies.input_path_level``;
``python studies/input_path_level.py --help`` lists its options.
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without installing

from pyomo_heli.studies.input_path_level import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
