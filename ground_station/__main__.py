"""python -m ground_station: the ground-station console script."""
import sys

from .cli import main

sys.exit(main())
