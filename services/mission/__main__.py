"""`python -m services.mission [--set key=value …]`: the mission service."""

import sys

from common.service import run
from services.mission.node import main

sys.exit(run("mission", main))
