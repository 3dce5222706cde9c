"""Training the segmenter (`dume train-segmenter`): needs the optional `train` extra (torch).

torch's OpenMP threads spin while they wait by default; on a small shared machine that
makes training several times slower, so they are told to sleep (before torch is imported).
"""

import os

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
