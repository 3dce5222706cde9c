"""`python -m services.sim [--set key=value …]`: the simulator service."""

import os
import sys

os.environ.setdefault("MUJOCO_GL", "egl")

from common.service import run
from services.sim.node import main

sys.exit(run("sim", main))
