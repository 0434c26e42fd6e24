"""``python -m hri_physio_coach.evaluate`` = ``hri_physio_evaluate``."""

import sys

from hri_physio_coach.evaluate.cli import main

sys.exit(main())
