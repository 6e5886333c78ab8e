"""The trim-only score test's false-alarm rate and power on synthetic trim sets (docs/real_data.md).

The study is ``pyomo_heli.studies.trim_score_level``;
``python studies/trim_score_level.py --help`` lists its options.
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without installing

from pyomo_heli.studies.trim_score_level import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
