"""`python -m services.perception [--set key=value …]`: the perception service.

`--set perception.segmenter="truth"` feeds the sim's `segmentation_truth` instead of the
network: for ablation and evaluation only, named so in every `Detections`.
"""

import sys

from common.service import run
from services.perception.node import main

sys.exit(run("perception", main))
