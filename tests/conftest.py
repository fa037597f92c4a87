"""Suite-wide setup: helper modules under tests/ are importable by name, and
torch uses both cores with deterministic defaults."""
import sys
from pathlib import Path

import torch

HERE = Path(__file__).parent
for sub in (HERE, HERE / "training"):
    if str(sub) not in sys.path:
        sys.path.insert(0, str(sub))

torch.set_num_threads(2)
