"""`python -m services.semantic_map`: the semantic map service (see `node`)."""

from __future__ import annotations

import sys

from common.service import run
from services.semantic_map.node import NAME, main

if __name__ == "__main__":
    sys.exit(run(NAME, main))
