"""Suite-wide setup: helper modules under tests/ are importable by name,
torch uses both cores with deterministic defaults, and windows opened by tests
autosave to a temporary folder, never the user's state folder, and neither
refine on idle nor read the user's refined codes."""
import os
import sys
import tempfile
from pathlib import Path

import torch

HERE = Path(__file__).parent
for sub in (HERE, HERE / "training"):
    if str(sub) not in sys.path:
        sys.path.insert(0, str(sub))

torch.set_num_threads(2)

os.environ.setdefault("NBRDF_STATE_DIR", tempfile.mkdtemp(prefix="nbrdf-test-state-"))
# Windows opened by tests show the network's codes: no refinement on idle, no user-cached refined code
# (tests/viewer/test_refine_job.py turns it on where it is tested).
os.environ.setdefault("NBRDF_IDLE_REFINE", "0")
# ... nor a calibrated energy (tests/viewer/test_calibrate_job.py turns it on where it is tested)
os.environ.setdefault("NBRDF_IDLE_CALIBRATE", "0")
