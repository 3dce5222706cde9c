"""`python -m services.localization [--set key=value …]`: the localization service."""

import sys

from common.service import run
from services.localization.node import main

sys.exit(run("localization", main))
