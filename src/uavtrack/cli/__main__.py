"""python -m uavtrack.cli"""

import sys

from . import main

sys.exit(main())
