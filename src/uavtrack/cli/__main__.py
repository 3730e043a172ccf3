"""python -m uavtrack.cli"""

from . import entry

entry()
