"""`python -m services.wbc [--set key=value …]`: the whole-body controller service."""

import sys

from common.service import run
from services.wbc.node import main

sys.exit(run("wbc", main))
