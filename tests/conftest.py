"""Suite-wide setup: helper modules under tests/ are importable by name,
torch uses both cores with deterministic defaults, and windows opened by tests
autosave to a temporary folder, never the user's state folder."""
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
