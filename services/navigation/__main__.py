"""`python -m services.navigation [--set key=value …]`: the navigation service."""

import sys

from common.service import run
from services.navigation.node import main

sys.exit(run("navigation", main))
